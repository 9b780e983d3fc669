"""Patch selection: K patches spread over the frame, avoiding the estimator's failure cases.

Rejected: underexposed ("black": mean below ``min_patch_mean_dn`` or too many pixels at 0 DN),
overexposed ("saturated": mean above ``max_patch_mean_dn`` or too many pixels at 255 DN) and
"flat" patches (a large share of equal neighbour pixels: clipped plateaus below 255 or noise-free
regions). Among the usable patches the least-textured fraction is kept (edges inflate noise
estimates) and K are picked by farthest-point sampling so they spread over the frame.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from .config import MonitorConfig

REJECT_REASONS = ("black", "saturated", "flat")
_LOW, _HIGH = 0.5, 254.5


@dataclass(frozen=True)
class PatchSelection:
    """Top-left corners (y, x) of the chosen patches and what was rejected."""

    size: int
    corners: list[tuple[int, int]]
    candidates: int
    rejected: dict[str, int] = field(default_factory=dict)

    def extract(self, image: np.ndarray) -> np.ndarray:
        """The chosen patches as a float32 (N, size, size) batch."""
        s = self.size
        out = np.empty((len(self.corners), s, s), dtype=np.float32)
        for i, (y, x) in enumerate(self.corners):
            out[i] = image[y : y + s, x : x + s]
        return out

    def describe_rejections(self) -> str:
        parts = [f"{n} {r}" for r, n in self.rejected.items() if n]
        return f"{', '.join(parts) or 'none'} of {self.candidates} candidate patches rejected"


def _grid(length: int, size: int, stride: int) -> np.ndarray:
    n = (length - size) // stride + 1
    offset = ((length - size) - (n - 1) * stride) // 2
    return offset + stride * np.arange(n)


def candidate_corners(height: int, width: int, size: int, k: int) -> list[tuple[int, int]]:
    """A centred grid of non-overlapping patch positions (half-overlapping when that gives fewer than k)."""
    if height < size or width < size:
        return []
    stride = size
    if ((height - size) // size + 1) * ((width - size) // size + 1) < k:
        stride = max(size // 2, 1)
    return [(int(y), int(x)) for y in _grid(height, size, stride) for x in _grid(width, size, stride)]


class _BoxSums:
    """Per-candidate sums of pixel statistics via integral images (O(image) for all candidates)."""

    def __init__(self, image: np.ndarray, size: int) -> None:
        self.size = size
        img = np.ascontiguousarray(image, dtype=np.float32)
        self.value = cv2.integral(img, sdepth=cv2.CV_64F)
        self.low = cv2.integral((img <= _LOW).astype(np.uint8))
        self.high = cv2.integral((img >= _HIGH).astype(np.uint8))
        self.eq_x = cv2.integral((img[:, 1:] == img[:, :-1]).astype(np.uint8))
        self.eq_y = cv2.integral((img[1:] == img[:-1]).astype(np.uint8))
        # texture: gradients of the 4x area-downsampled image (noise averages out, structure stays)
        h4, w4 = img.shape[0] // 4, img.shape[1] // 4
        small = cv2.resize(img[: 4 * h4, : 4 * w4], (w4, h4), interpolation=cv2.INTER_AREA)
        grad = np.zeros_like(small)
        grad[:, 1:] += np.abs(np.diff(small, axis=1))
        grad[1:] += np.abs(np.diff(small, axis=0))
        self.grad = cv2.integral(grad, sdepth=cv2.CV_64F)

    @staticmethod
    def _sum(table: np.ndarray, y: int, x: int, h: int, w: int) -> float:
        return float(table[y + h, x + w] - table[y, x + w] - table[y + h, x] + table[y, x])

    def stats(self, y: int, x: int) -> tuple[float, float, float, float, float]:
        """(mean, fraction at 0 DN, fraction at 255 DN, fraction of equal neighbours, texture)."""
        s = self.size
        n = float(s * s)
        equal = (self._sum(self.eq_x, y, x, s, s - 1) + self._sum(self.eq_y, y, x, s - 1, s)) / (2.0 * s * (s - 1))
        s4 = max(s // 4, 1)
        texture = self._sum(self.grad, y // 4, x // 4, s4, s4) / (s4 * s4)
        return (self._sum(self.value, y, x, s, s) / n, self._sum(self.low, y, x, s, s) / n,
                self._sum(self.high, y, x, s, s) / n, equal, texture)


def _reject_reason(mean: float, low: float, high: float, equal: float, cfg: MonitorConfig) -> str | None:
    if mean < cfg.min_patch_mean_dn or low > cfg.max_clipped_fraction:
        return "black"
    if mean > cfg.max_patch_mean_dn or high > cfg.max_clipped_fraction:
        return "saturated"
    if equal > cfg.max_flat_fraction:
        return "flat"
    return None


def _spread(points: np.ndarray, k: int) -> list[int]:
    """Farthest-point sampling of k indices, starting from index 0."""
    chosen = [0]
    dist = np.linalg.norm(points - points[0], axis=1)
    while len(chosen) < k:
        nxt = int(np.argmax(dist))
        chosen.append(nxt)
        dist = np.minimum(dist, np.linalg.norm(points - points[nxt], axis=1))
    return chosen


def select_patches(image: np.ndarray, size: int, cfg: MonitorConfig) -> PatchSelection:
    """Choose up to ``cfg.patches_per_frame`` usable patches of ``size`` pixels from a gray DN image."""
    k = cfg.patches_per_frame
    corners = candidate_corners(image.shape[0], image.shape[1], size, k)
    rejected = dict.fromkeys(REJECT_REASONS, 0)
    usable: list[tuple[int, int]] = []
    texture: list[float] = []
    sums = _BoxSums(image, size) if corners else None
    for y, x in corners:
        mean, low, high, equal, tex = sums.stats(y, x)
        reason = _reject_reason(mean, low, high, equal, cfg)
        if reason:
            rejected[reason] += 1
        else:
            usable.append((y, x))
            texture.append(tex)
    if len(usable) > k:
        order = np.argsort(texture, kind="stable")
        keep = order[: max(k, int(np.ceil(cfg.smooth_fraction * len(usable))))]
        pts = np.array([usable[i] for i in keep], dtype=float)
        usable = sorted(usable[keep[i]] for i in _spread(pts, k))
    return PatchSelection(size=size, corners=usable, candidates=len(corners), rejected=rejected)
