"""The analytic noise model applied to patches: per-source sigma from the 5x5-smoothed intensity map.

A patch's clean intensity is estimated by a 5x5 box filter of the noisy patch (cv2.blur), corrected
for the clipping bias near 0 and 255; the model's tables E[n|v], E[n^2|v] (one set per metadata,
cached by the NoiseModel) are then integrated over the patch's intensity histogram with linear
weights, which equals ``NoiseModel.predict`` on that map but runs one ``bincount`` per metadata group
instead of per-pixel interpolation.
"""
from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np

from ..physics import CameraMetadata, NoiseModel
from ..physics.model import TABLE_STEP_DN

SOURCES = ("pn", "dcsn", "rn")
#: Name of the optional 4th table row: every noise effect of the model beyond the paper's sources.
EXTRA = "extra"
SMOOTH_KERNEL = 5
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
            mean = sum(t[n][0] for n in extra)
            m1.append(mean)
            m2.append(sum(t[n][1] - t[n][0] ** 2 for n in extra) + mean**2)
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


def clean_level(smooth: np.ndarray, m1: np.ndarray) -> np.ndarray:
    """Clean intensity (DN, float64) whose expected noisy value equals the smoothed value.

    Clipping at 0 and 255 biases the noisy mean by E[n | v] (the sum of the sources' tabulated means),
    so a smoothed flat patch at 0 DN reads a few DN; inverting v -> v + sum E[n | v] removes that bias
    (elsewhere E[n | v] is ~0 and the map is unchanged). The inverse is tabulated on the intensity grid
    and read with linear interpolation (no per-pixel search).
    """
    grid = np.arange(m1.shape[-1]) * TABLE_STEP_DN
    inverse = np.interp(grid, np.maximum.accumulate(grid + m1.sum(axis=0)), grid)
    pos = np.clip(smooth, 0.0, 255.0).astype(np.float64) / TABLE_STEP_DN
    i0 = np.minimum(pos.astype(np.int64), len(grid) - 2)
    frac = pos - i0
    return inverse[i0] * (1.0 - frac) + inverse[i0 + 1] * frac


def predict_from_tables(smooth: np.ndarray, tables: np.ndarray, group_of: np.ndarray,
                        with_map: bool = False, debias: bool = True) -> dict[str, np.ndarray]:
    """Per-source sigma and ``total`` (sqrt of the sum of squares) from tables (K, 2, S, G).

    S = 3 (the paper's sources) or 4 (plus ``extra``, see :meth:`PhysicsPrior.tables`).

    Patch i uses ``tables[group_of[i]]``. The smoothed map is first mapped to clean levels
    (:func:`clean_level`, unless ``debias`` is False); integrating the tables over the resulting
    intensity histogram (linear weights) equals ``NoiseModel.predict`` on that map. With ``with_map`` also
    ``sigma_map`` (N, H, W): the model's total sigma at each pixel's level.
    """
    n, h, w = smooth.shape
    names = (SOURCES + (EXTRA,))[: tables.shape[2]]
    sig = np.empty((n, len(names)))
    sigma_map = np.empty(smooth.shape, dtype=np.float32) if with_map else None
    g = tables.shape[-1]
    for k in np.unique(group_of):
        idx = np.flatnonzero(group_of == k)
        m1, m2 = tables[k]
        level = clean_level(smooth[idx], m1) if debias else np.clip(smooth[idx], 0.0, 255.0).astype(np.float64)
        pos = level / TABLE_STEP_DN
        i0 = np.minimum(pos.astype(np.int64), g - 2)
        frac = pos - i0
        rows = (np.arange(len(idx)) * g)[:, None, None]
        hist = np.bincount((i0 + rows).ravel(), (1.0 - frac).ravel(), len(idx) * g)
        hist += np.bincount((i0 + 1 + rows).ravel(), frac.ravel(), len(idx) * g)
        hist = hist.reshape(len(idx), g) / (h * w)
        sig[idx] = np.sqrt(np.maximum(hist @ m2.T - (hist @ m1.T) ** 2, 0.0))
        if sigma_map is not None:
            level = np.sqrt(np.maximum(m2 - m1**2, 0.0).sum(axis=0))
            sigma_map[idx] = (level[i0] * (1.0 - frac) + level[i0 + 1] * frac).astype(np.float32)
    out = {s: sig[:, j] for j, s in enumerate(names)}
    out["total"] = np.sqrt((sig**2).sum(axis=1))
    if sigma_map is not None:
        out["sigma_map"] = sigma_map
    return out
