"""How a quantizer of step L changes the temporal noise the lab measures.

The output is Q(u + n) = L round((u + n) / L) for a level u and Gaussian temporal noise n of std sigma.
Its temporal variance depends on r = sigma / L and on the phase of u within a step: about L^2/12 is
added when the noise dithers the quantizer (r >~ 0.5); far below the step the noise is mostly erased,
except where the level sits on a decision threshold. A flat region has one phase: it is recovered from
the region's measured mean (E[Q] is monotonic in the phase) and the variance is averaged over the
levels the region spans (gradient, fixed-pattern noise). Without a level, the phase average and its
spread over phases are returned.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.special import ndtr

_RATIOS = np.geomspace(1e-3, 8.0, 160)
_PHASES = -0.5 + (np.arange(64) + 0.5) / 64.0
_STEP = 1.0 / _PHASES.size


@lru_cache(maxsize=1)
def _tables() -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Per (ratio, phase), LSB units: E[Q]; the added variance Var[Q] - r^2; and cumulatives over 3
    periods of that, of the bias b = E[Q] - phase and of b^2."""
    mean = np.empty((_RATIOS.size, _PHASES.size))
    added = np.empty_like(mean)
    for i, r in enumerate(_RATIOS):
        k = np.arange(-int(np.ceil(8 * r)) - 2, int(np.ceil(8 * r)) + 3, dtype=float)[:, None]
        p = ndtr((k + 0.5 - _PHASES) / r) - ndtr((k - 0.5 - _PHASES) / r)
        mean[i] = np.sum(k * p, axis=0)
        added[i] = np.sum(k * k * p, axis=0) - mean[i] ** 2 - r * r
    bias = mean - _PHASES
    cum = {name: np.concatenate([np.zeros((_RATIOS.size, 1)), np.cumsum(np.tile(a, 3), axis=1) * _STEP], axis=1)
           for name, a in (("added", added), ("bias", bias), ("bias2", bias**2))}
    return mean, added, cum


def quantized_variance(sigma_dn: np.ndarray, lsb_dn: float, level_dn: np.ndarray | None = None,
                       span_dn: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(temporal variance added by the quantizer, fixed-pattern variance it adds, the model's spread of
    the temporal part), all in DN^2.

    ``level_dn``: measured mean output of each region (then the region's own phase is used, spread 0);
    ``span_dn``: range of levels inside each region (gradient, fixed-pattern noise), averaged over; the
    quantizer's bias E[Q] - level varies over that range and shows as fixed-pattern noise.
    """
    mean, added, cum = _tables()
    r = np.asarray(sigma_dn, dtype=float) / lsb_dn
    logr = np.log(np.clip(r, _RATIOS[0], _RATIOS[-1]))
    i1 = np.clip(np.searchsorted(_RATIOS, np.exp(logr)), 1, _RATIOS.size - 1)
    i0 = i1 - 1
    w = np.clip((logr - np.log(_RATIOS[i0])) / (np.log(_RATIOS[i1]) - np.log(_RATIOS[i0])), 0.0, 1.0)
    if level_dn is None:
        phase = np.zeros_like(r)
        half = np.full_like(r, 0.5)
        spread = (1.0 - w) * added[i0].std(axis=1) + w * added[i1].std(axis=1)
    else:
        i = np.where(w < 0.5, i0, i1)
        t = np.asarray(level_dn, dtype=float) / lsb_dn
        t = t - np.rint(t)
        # invert the monotonic E[Q](phase) of each region's row (rows offset to search all at once)
        offset = 4.0 * np.arange(_RATIOS.size)
        j = np.searchsorted((mean + offset[:, None]).ravel(), t + offset[i]) - i * _PHASES.size
        j = np.clip(j, 1, _PHASES.size - 1)
        m0, m1 = mean[i, j - 1], mean[i, j]
        phase = _PHASES[j - 1] + _STEP * np.clip((t - m0) / np.maximum(m1 - m0, 1e-12), 0.0, 1.0)
        half = np.clip(0.5 * np.asarray(span_dn if span_dn is not None else 0.0) / lsb_dn, 0.5 * _STEP, 0.5)
        spread = np.zeros_like(r)

    def window(name: str) -> np.ndarray:
        def one(row: np.ndarray) -> np.ndarray:
            return (_cumulative(cum[name], row, phase + half) - _cumulative(cum[name], row, phase - half)) / (2 * half)
        return (1.0 - w) * one(i0) + w * one(i1)

    temporal = window("added")
    fixed = np.maximum(window("bias2") - window("bias") ** 2, 0.0)
    dithered = r >= _RATIOS[-1]
    return (lsb_dn**2 * np.where(dithered, 1.0 / 12.0, temporal), lsb_dn**2 * np.where(dithered, 0.0, fixed),
            lsb_dn**2 * np.where(dithered, 0.0, spread))


def _cumulative(cum: np.ndarray, i: np.ndarray, phase: np.ndarray) -> np.ndarray:
    """Integral of Var over phase from -1.5 to ``phase`` (in [-1, 1]) on row ``i``, linear in between."""
    x = (phase + 1.5) / _STEP
    k = np.clip(np.floor(x).astype(int), 0, cum.shape[1] - 2)
    f = x - k
    return cum[i, k] * (1.0 - f) + cum[i, k + 1] * f
