"""Closed-form moments of clipped noise: Poisson x Gaussian x offset-mixture noise, clipped to [0, 255].

The noise at clean value x is  n = clip(x + a (K - lam) + o + G, lo, hi) - x  with K ~ Poisson(lam),
G ~ N(0, s2) and o an offset drawn from a mixture. The moments E[n], E[n^2] are sums over K of the
closed-form moments of a clipped normal (exact for the stated model; a Poisson with lam > 1000 is
folded into the Gaussian, skewness < 0.03).
"""
from __future__ import annotations

import numpy as np
from scipy.special import gammaln, ndtr

DN_MAX = 255.0
POISSON_EXACT_MAX = 1000.0
_INV_SQRT_2PI = 1.0 / np.sqrt(2.0 * np.pi)
_TINY_SIGMA = 1e-9


def _phi(z: np.ndarray) -> np.ndarray:
    return _INV_SQRT_2PI * np.exp(-0.5 * np.minimum(z * z, 1e4))


def clipped_normal_moments(mu, s, lo, hi):
    """E[Y], E[Y^2] of Y = clip(N(mu, s^2), lo, hi), broadcast over the arguments."""
    s = np.maximum(s, _TINY_SIGMA)
    a = (lo - mu) / s
    b = (hi - mu) / s
    pa, pb = ndtr(a), ndtr(b)
    fa, fb = _phi(a), _phi(b)
    mid = pb - pa
    m1 = lo * pa + hi * (1.0 - pb) + mu * mid + s * (fa - fb)
    m2 = (
        lo * lo * pa
        + hi * hi * (1.0 - pb)
        + (mu * mu + s * s) * mid
        + 2.0 * mu * s * (fa - fb)
        + s * s * (np.where(np.isfinite(a), a, 0.0) * fa - np.where(np.isfinite(b), b, 0.0) * fb)
    )
    return m1, m2


def noise_moments(
    x: np.ndarray,
    lam: np.ndarray | float = 0.0,
    scale: float = 1.0,
    s2: np.ndarray | float = 0.0,
    mixtures: list[tuple[float, np.ndarray]] | None = None,
    lo: float = 0.0,
    hi: float = DN_MAX,
) -> tuple[np.ndarray, np.ndarray]:
    """E[n], E[n^2] of the clipped noise at clean values ``x`` (1-D); see the module docstring."""
    x = np.asarray(x, dtype=float)
    n = x.shape[0]
    lam = np.broadcast_to(np.asarray(lam, dtype=float), (n,)).copy()
    s2 = np.broadcast_to(np.asarray(s2, dtype=float), (n,)).copy()
    big = lam > POISSON_EXACT_MAX
    s2[big] += scale**2 * lam[big]
    lam[big] = 0.0

    # mixture components: weights (C,) and offsets (C, n)
    weights = np.ones(1)
    offsets = np.zeros((1, n))
    for frac, off in mixtures or []:
        off = np.broadcast_to(np.asarray(off, dtype=float), (n,))
        weights = np.concatenate([weights * (1.0 - frac), weights * frac])
        offsets = np.concatenate([offsets, offsets + off[None, :]])
    keep = weights > 0
    weights, offsets = weights[keep], offsets[keep]

    lam_max = float(lam.max()) if n else 0.0
    if lam_max > 0.0:
        k0 = np.maximum(np.floor(lam - 8.0 * np.sqrt(lam) - 2.0), 0.0)
        span = int(np.ceil(16.0 * np.sqrt(lam_max) + 16.0))
        k = k0[None, :] + np.arange(span, dtype=float)[:, None]  # (K, n)
        with np.errstate(divide="ignore", invalid="ignore"):
            logp = np.where(lam[None, :] > 0, k * np.log(np.maximum(lam[None, :], 1e-300)), np.where(k == 0, 0.0, -np.inf))
        pk = np.exp(logp - lam[None, :] - gammaln(k + 1.0))
        shift = scale * (k - lam[None, :])  # (K, n)
    else:
        pk = np.ones((1, n))
        shift = np.zeros((1, n))

    s = np.sqrt(s2)[None, None, :]
    mu = shift[None, :, :] + offsets[:, None, :]  # (C, K, n)
    m1, m2 = clipped_normal_moments(mu, s, (lo - x)[None, None, :], (hi - x)[None, None, :])
    w = weights[:, None, None] * pk[None, :, :]
    return np.sum(w * m1, axis=(0, 1)), np.sum(w * m2, axis=(0, 1))


def clipped_pmf(
    x: np.ndarray,
    grid: np.ndarray,
    mean: np.ndarray,
    var: np.ndarray,
    mixtures: list[tuple[float, np.ndarray]] | None = None,
    lo: float = 0.0,
    hi: float = DN_MAX,
) -> np.ndarray:
    """Distribution of clip(x + noise) on ``grid`` (rows: x), noise Gaussian-approximated per component.

    Used only to carry the intermediate image of the sequential protocol to the next source; the
    moments themselves come from :func:`noise_moments` (exact).
    """
    x = np.asarray(x, dtype=float)
    n = x.shape[0]
    edges = np.concatenate([[-np.inf], 0.5 * (grid[1:] + grid[:-1]), [np.inf]])
    weights = [1.0]
    offsets = [np.zeros(n)]
    for frac, off in mixtures or []:
        off = np.broadcast_to(np.asarray(off, dtype=float), (n,))
        weights = [w * (1 - frac) for w in weights] + [w * frac for w in weights]
        offsets = offsets + [o + off for o in offsets]
    s = np.maximum(np.sqrt(np.broadcast_to(var, (n,))), _TINY_SIGMA)[:, None]
    pmf = np.zeros((n, grid.size))
    for w, off in zip(weights, offsets):
        if w == 0:
            continue
        centre = np.clip(x + np.broadcast_to(mean, (n,)) + off, -1e9, 1e9)[:, None]
        cdf = ndtr((edges[None, :] - centre) / s)
        pmf += w * np.diff(cdf, axis=1)
    return pmf
