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
    for stride in (size, max(size // 2, 1)):
        ys, xs = _grid(height, size, stride), _grid(width, size, stride)
        if len(ys) * len(xs) >= k or stride == max(size // 2, 1):
            return [(int(y), int(x)) for y in ys for x in xs]
    return []


def _texture(patch: np.ndarray) -> float:
    """Mean gradient of the 4x area-downsampled patch (noise is averaged away, structure stays)."""
    s = max(patch.shape[0] // 4, 2)
    small = cv2.resize(patch, (s, s), interpolation=cv2.INTER_AREA)
    return float(np.abs(np.diff(small, axis=0)).mean() + np.abs(np.diff(small, axis=1)).mean())


def _reject_reason(patch: np.ndarray, cfg: MonitorConfig) -> str | None:
    mean = float(patch.mean())
    n = patch.size
    if mean < cfg.min_patch_mean_dn or np.count_nonzero(patch <= _LOW) > cfg.max_clipped_fraction * n:
        return "black"
    if mean > cfg.max_patch_mean_dn or np.count_nonzero(patch >= _HIGH) > cfg.max_clipped_fraction * n:
        return "saturated"
    flat = (np.count_nonzero(patch[:, 1:] == patch[:, :-1]) + np.count_nonzero(patch[1:] == patch[:-1])) / (
        2.0 * patch.shape[0] * (patch.shape[1] - 1)
    )
    if flat > cfg.max_flat_fraction:
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
    for y, x in corners:
        patch = image[y : y + size, x : x + size]
        reason = _reject_reason(patch, cfg)
        if reason:
            rejected[reason] += 1
        else:
            usable.append((y, x))
            texture.append(_texture(patch))
    if len(usable) > k:
        order = np.argsort(texture, kind="stable")
        keep = order[: max(k, int(np.ceil(cfg.smooth_fraction * len(usable))))]
        pts = np.array([usable[i] for i in keep], dtype=float)
        usable = sorted(usable[keep[i]] for i in _spread(pts, k))
    return PatchSelection(size=size, corners=usable, candidates=len(corners), rejected=rejected)
