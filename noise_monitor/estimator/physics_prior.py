"""The analytic noise model applied to patches: per-source sigma from the 5x5-smoothed intensity map.

A patch's clean intensity is estimated by a 5x5 box filter of the noisy patch (cv2.blur), shrunk
towards the patch mean by the noise it still holds and corrected for the clipping bias near 0 and 255;
the model's tables E[n|v], E[n^2|v] (one set per metadata, cached by the NoiseModel) are then
integrated over the patch's intensity histogram with linear weights, which equals
``NoiseModel.predict`` on that map but runs one ``bincount`` per metadata group instead of per-pixel
interpolation.
"""
from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from ..physics import CameraMetadata, NoiseModel
from ..physics.constants import PAPER_EFFECTS as SOURCES
from ..physics.constants import SMOOTH_KERNEL
from ..physics.grid import grid_position, histogram
from ..physics.model import TABLE_STEP_DN

#: Name of the optional 4th table row: every noise effect of the model beyond the paper's sources.
EXTRA = "extra"
#: Floor of the per-pixel sigma map used to normalise residuals (DN).
SIGMA_MAP_FLOOR = 0.25


def box_smooth(patches: np.ndarray, k: int = SMOOTH_KERNEL) -> np.ndarray:
    """k x k box filter of every patch of an (N, H, W) float32 batch (cv2.blur, reflect-101 border)."""
    out = np.empty_like(patches, dtype=np.float32)
    for i, p in enumerate(patches):
        out[i] = cv2.blur(np.asarray(p, dtype=np.float32), (k, k))
    return out


def group_by_meta(metas: Sequence[CameraMetadata]) -> dict[CameraMetadata, np.ndarray]:
    """Indices of the patches sharing each distinct metadata (tables are built once per group)."""
    groups: dict[CameraMetadata, list[int]] = {}
    for i, m in enumerate(metas):
        groups.setdefault(m, []).append(i)
    return {m: np.asarray(idx) for m, idx in groups.items()}


class PhysicsPrior:
    """Per-source sigma (DN) predicted by the analytic model for patches, in sequential mode."""

    def __init__(self, model: NoiseModel | None = None, mode: str = "sequential") -> None:
        self.model = model or NoiseModel()
        self.mode = mode

    @property
    def extra_effects(self) -> list[str]:
        """Noise effects of the model beyond the paper's sources (summed into the ``extra`` row)."""
        return [n for n in (e.name for e in self.model.noise_effects) if n not in SOURCES]

    def tables(self, meta: CameraMetadata) -> np.ndarray:
        """float64 (2, S, G): E[n|v] and E[n^2|v] of the paper's sources on the model's intensity grid.

        With effects beyond the paper's sources, a 4th row (S = 4) holds their sum as independent
        noises: means add, variances add.
        """
        t = self.model.tables(meta, self.mode)
        m1 = [t[s][0] for s in SOURCES]
        m2 = [t[s][1] for s in SOURCES]
        extra = self.extra_effects
        if extra:
            mean = np.sum([t[n][0] for n in extra], axis=0)
            m1.append(mean)
            m2.append(np.sum([t[n][1] - t[n][0] ** 2 for n in extra], axis=0) + mean**2)
        return np.stack([np.stack(m1), np.stack(m2)])

    def predict(self, smooth: np.ndarray, metas: Sequence[CameraMetadata], with_map: bool = False,
                debias: bool = True) -> dict[str, np.ndarray]:
        """Sigma per source and ``total`` for each smoothed patch (N, H, W); see :func:`predict_from_tables`."""
        groups = group_by_meta(metas)
        tables = np.stack([self.tables(m) for m in groups])
        group_of = np.empty(len(metas), dtype=np.int64)
        for g, idx in enumerate(groups.values()):
            group_of[idx] = g
        return predict_from_tables(smooth, tables, group_of, with_map, debias)


def _nearest(table: np.ndarray, level: np.ndarray) -> np.ndarray:
    """``table`` (on the intensity grid) at the grid point nearest each level (a gather in the table's type)."""
    return np.take(table, (level * np.float32(1.0 / TABLE_STEP_DN) + np.float32(0.5)).astype(np.intp))


def shrink_noise(smooth: np.ndarray, sigma: np.ndarray, k: int = SMOOTH_KERNEL) -> np.ndarray:
    """Shrink each smoothed patch (N, H, W) towards its mean by the share of its variance that is noise.

    A k x k box filter leaves noise of variance sigma^2 / k^2 in the smoothed map; on a flat patch that
    spread alone widens the intensity histogram, which biases the prediction where sigma depends
    strongly on the level (clipping, a small full well). The Wiener factor
    ``max(0, 1 - mean(sigma^2) / k^2 / var(smooth))`` removes it and leaves textured patches unchanged.
    """
    mean = smooth.mean(axis=(1, 2), keepdims=True)
    var = smooth.var(axis=(1, 2), keepdims=True)
    noise = (sigma**2).mean(axis=(1, 2), keepdims=True) / k**2
    factor = np.clip(1.0 - noise / np.maximum(var, 1e-12), 0.0, 1.0)
    return mean + factor * (smooth - mean)


def clean_level(smooth: np.ndarray, m1: np.ndarray) -> np.ndarray:
    """Clean intensity (DN, float32) whose expected noisy value equals the smoothed value.

    Clipping at 0 and 255 biases the noisy mean by E[n | v] (the sum of the sources' tabulated means),
    so a smoothed flat patch at 0 DN reads a few DN; inverting v -> v + sum E[n | v] removes that bias
    (elsewhere E[n | v] is ~0 and the map is unchanged). The inverse's offset from the identity is
    tabulated on the intensity grid (0.5 DN) and read at the nearest grid point: it varies slowly, so
    this costs one gather per pixel and no per-pixel search.
    """
    grid = np.arange(m1.shape[-1]) * TABLE_STEP_DN
    offset = np.interp(grid, np.maximum.accumulate(grid + m1.sum(axis=0)), grid) - grid
    level = np.clip(smooth, 0.0, 255.0).astype(np.float32)
    return np.clip(level + _nearest(offset.astype(np.float32), level), 0.0, 255.0)


def predict_from_tables(smooth: np.ndarray, tables: np.ndarray, group_of: np.ndarray,
                        with_map: bool = False, debias: bool = True) -> dict[str, np.ndarray]:
    """Per-source sigma and ``total`` (sqrt of the sum of squares) from tables (K, 2, S, G).

    S = 3 (the paper's sources) or 4 (plus ``extra``, see :meth:`PhysicsPrior.tables`).

    Patch i uses ``tables[group_of[i]]``. Unless ``debias`` is False, the smoothed map is first rid of
    the noise it still holds (:func:`shrink_noise`) and mapped to clean levels (:func:`clean_level`);
    integrating the tables over the resulting intensity histogram (linear weights) equals
    ``NoiseModel.predict`` on that map. With ``with_map`` also ``sigma_map`` (N, H, W): the model's
    total sigma at each pixel's level.
    """
    n = smooth.shape[0]
    names = (SOURCES + (EXTRA,))[: tables.shape[2]]
    sig = np.empty((n, len(names)))
    sigma_map: np.ndarray | None = np.empty(smooth.shape, dtype=np.float32) if with_map else None
    g = tables.shape[-1]
    for k in np.unique(group_of):
        idx = np.flatnonzero(group_of == k)
        m1, m2 = tables[k]
        sigma_level = np.sqrt(np.maximum(m2 - m1**2, 0.0).sum(axis=0)).astype(np.float32)
        level = np.clip(smooth[idx], 0.0, 255.0).astype(np.float32)
        if debias:
            level = clean_level(shrink_noise(level, _nearest(sigma_level, level)), m1)
        i0, frac = grid_position(level, g)
        hist = histogram(i0, frac, g)
        sig[idx] = np.sqrt(np.maximum(hist @ m2.T - (hist @ m1.T) ** 2, 0.0))
        if sigma_map is not None:
            sigma_map[idx] = np.take(sigma_level, i0) + np.take(np.diff(sigma_level, append=sigma_level[-1]), i0) * frac
    out = {s: sig[:, j] for j, s in enumerate(names)}
    out["total"] = np.sqrt((sig**2).sum(axis=1))
    if sigma_map is not None:
        out["sigma_map"] = sigma_map
    return out
