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


@dataclass(frozen=True)
class _Layout:
    """Candidate grid: corners at (y0 + i*stride, x0 + j*stride) of patches of ``size`` pixels."""

    y0: int
    x0: int
    stride: int
    ny: int
    nx: int
    size: int = 0

    def corners(self) -> list[tuple[int, int]]:
        return [(self.y0 + i * self.stride, self.x0 + j * self.stride) for i in range(self.ny) for j in range(self.nx)]


def _layout(height: int, width: int, size: int, k: int) -> _Layout:
    """A centred grid of non-overlapping patches, half-overlapping (even sizes) when that gives fewer than k."""
    if height < size or width < size:
        return _Layout(0, 0, 0, 0, 0, size)
    stride = size
    if ((height - size) // size + 1) * ((width - size) // size + 1) < k and size % 2 == 0:
        stride = size // 2
    ny, nx = (height - size) // stride + 1, (width - size) // stride + 1
    y0 = ((height - size) - (ny - 1) * stride) // 2
    x0 = ((width - size) - (nx - 1) * stride) // 2
    return _Layout(y0, x0, stride, ny, nx, size)


def _patch_sums(a: np.ndarray, lay: _Layout, scale: int = 1) -> np.ndarray:
    """(ny, nx) sums of ``a`` over every candidate patch (integral image; ``a`` downsampled by ``scale``)."""
    table = cv2.integral(a) if a.dtype == np.uint8 else cv2.integral(a, sdepth=cv2.CV_64F)
    ys = (lay.y0 + lay.stride * np.arange(lay.ny)) // scale
    xs = (lay.x0 + lay.stride * np.arange(lay.nx)) // scale
    y1, x1, d = ys[:, None], xs[None, :], lay.size // scale
    return (table[y1 + d, x1 + d] - table[y1, x1 + d] - table[y1 + d, x1] + table[y1, x1]).astype(np.float64)


def _candidate_stats(image: np.ndarray, lay: _Layout, black_level: float = 0.0) -> dict[str, np.ndarray]:
    """Per candidate: mean, fractions at the ADC's 0 / 255 DN (``-black_level`` / ``255 - black_level`` in an image
    with the camera's black level taken off), fraction of equal right/lower neighbours (pairs leaving the patch
    count at their inner pixel) and texture (mean gradient of the image averaged over f x f blocks, f = 4 when the
    grid allows: noise averages out, structure stays)."""
    img = np.ascontiguousarray(image, dtype=np.float32)
    n = float(lay.size * lay.size)
    equal = np.zeros(img.shape, dtype=np.uint8)
    equal[:, :-1] += img[:, 1:] == img[:, :-1]
    equal[:-1] += img[1:] == img[:-1]
    f = next(d for d in (4, 2, 1) if lay.stride % d == 0 and lay.y0 % d == 0 and lay.x0 % d == 0)
    h, w = img.shape[0] // f, img.shape[1] // f
    small = cv2.resize(img[: h * f, : w * f], (w, h), interpolation=cv2.INTER_AREA)
    grad = np.zeros_like(small)
    grad[:, :-1] += np.abs(np.diff(small, axis=1))
    grad[:-1] += np.abs(np.diff(small, axis=0))
    return {
        "mean": _patch_sums(img, lay) / n,
        "low": _patch_sums((img <= _LOW - black_level).view(np.uint8), lay) / n,
        "high": _patch_sums((img >= _HIGH - black_level).view(np.uint8), lay) / n,
        "equal": _patch_sums(equal, lay) / (2.0 * n),
        "texture": _patch_sums(grad, lay, f) / (n / (f * f)),
    }


def _reject_reasons(st: dict[str, np.ndarray], cfg: MonitorConfig, black_level: float = 0.0) -> np.ndarray:
    """Per candidate: index into REJECT_REASONS, or -1 when usable (means: the signal above the black level, the
    saturation limit the ADC's)."""
    black = (st["mean"] < cfg.min_patch_mean_dn) | (st["low"] > cfg.max_clipped_fraction)
    saturated = (st["mean"] > cfg.max_patch_mean_dn - black_level) | (st["high"] > cfg.max_clipped_fraction)
    flat = st["equal"] > cfg.max_flat_fraction
    return np.select([black, saturated, flat], [0, 1, 2], default=-1)


def _spread(points: np.ndarray, k: int) -> list[int]:
    """Farthest-point sampling of k indices, starting from index 0."""
    chosen = [0]
    dist = np.linalg.norm(points - points[0], axis=1)
    while len(chosen) < k:
        nxt = int(np.argmax(dist))
        chosen.append(nxt)
        dist = np.minimum(dist, np.linalg.norm(points - points[nxt], axis=1))
    return chosen


def select_patches(image: np.ndarray, size: int, cfg: MonitorConfig, black_level: float = 0.0) -> PatchSelection:
    """Choose up to ``cfg.patches_per_frame`` usable patches of ``size`` pixels from a gray DN image (the camera's
    ``black_level`` taken off: :attr:`..monitor.frame.Frame.black_level_dn`)."""
    k = cfg.patches_per_frame
    lay = _layout(image.shape[0], image.shape[1], size, k)
    corners = lay.corners()
    if not corners:
        return PatchSelection(size=size, corners=[], candidates=0, rejected=dict.fromkeys(REJECT_REASONS, 0))
    stats = _candidate_stats(image, lay, black_level)
    reasons = _reject_reasons(stats, cfg, black_level).ravel()
    rejected = {r: int(np.count_nonzero(reasons == i)) for i, r in enumerate(REJECT_REASONS)}
    ok = np.flatnonzero(reasons < 0)
    usable = [corners[i] for i in ok]
    if len(usable) > k:
        texture = stats["texture"].ravel()[ok]
        keep = np.argsort(texture, kind="stable")[: max(k, int(np.ceil(cfg.smooth_fraction * len(usable))))]
        pts = np.array([usable[i] for i in keep], dtype=float)
        usable = sorted(usable[keep[i]] for i in _spread(pts, k))
    return PatchSelection(size=size, corners=usable, candidates=len(corners), rejected=rejected)
