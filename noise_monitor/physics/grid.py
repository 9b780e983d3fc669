"""Intensity maps on the model's table grid (0, TABLE_STEP_DN, ..., 255 DN): linear interpolation weights.

A map's predicted moments are its linear-weight histogram on the grid times the model's tables
(E[n|v], E[n^2|v]); the monitor and the estimator's physics prior both integrate this way.
"""
from __future__ import annotations

import numpy as np

from .constants import DN_MAX
from .model import TABLE_STEP_DN

GRID_LEN = int(round(DN_MAX / TABLE_STEP_DN)) + 1


def grid_position(levels: np.ndarray, g: int = GRID_LEN) -> tuple[np.ndarray, np.ndarray]:
    """Lower grid index and interpolation weight of each level (DN, within 0..255) on a grid of ``g`` points
    (the weight in the levels' floating-point type: float32 levels stay float32)."""
    pos = levels / TABLE_STEP_DN
    i0 = np.minimum(pos.astype(np.intp), g - 2)
    return i0, pos - i0.astype(pos.dtype)


def histogram(i0: np.ndarray, frac: np.ndarray, g: int = GRID_LEN) -> np.ndarray:
    """(N, g) linear-weight histograms of N maps (``i0`` <= g - 2, ``frac`` of shape (N, ...)); rows sum to 1."""
    n = i0.shape[0]
    rows = (np.arange(n) * g).reshape((n,) + (1,) * (i0.ndim - 1))
    idx = (i0 + rows).ravel()
    upper = np.bincount(idx, frac.ravel(), n * g)  # weight of the grid point above: shifted by one (never past a row)
    hist = np.bincount(idx, None, n * g) - upper  # the lower point's weights 1 - frac, summed
    hist[1:] += upper[:-1]
    return hist.reshape(n, g) / (i0.size // max(n, 1))
