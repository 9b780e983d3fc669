"""Closed-form moments of clipped noise: Poisson x Gaussian x offset-mixture noise, clipped to [0, 255].

The noise at clean value x is  n = clip(x + a (K - lam) + o + G, lo, hi) - x  with K ~ Poisson(lam),
G ~ N(0, s2) and o an offset drawn from a mixture. The moments E[n], E[n^2] are sums over K of the
closed-form moments of a clipped normal (exact for the stated model; a Poisson with lam > 1000 is
folded into the Gaussian, skewness < 0.03).
"""
from __future__ import annotations

import numpy as np
from scipy.special import gammaln, ndtr

from .constants import DN_MAX

POISSON_EXACT_MAX = 1000.0
_INV_SQRT_2PI = 1.0 / np.sqrt(2.0 * np.pi)
_TINY_SIGMA = 1e-9


def _phi(z: np.ndarray) -> np.ndarray:
    return _INV_SQRT_2PI * np.exp(-0.5 * np.minimum(z * z, 1e4))


def clipped_normal_moments(mu, s, lo, hi):
    """E[Y], E[Y^2], P(lo < Y < hi) of Y = clip(N(mu, s^2), lo, hi), broadcast over the arguments."""
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
    return m1, m2, mid


def noise_moments(
    x: np.ndarray,
    lam: np.ndarray | float = 0.0,
    scale: float = 1.0,
    s2: np.ndarray | float = 0.0,
    mixtures: list[tuple[float, np.ndarray]] | None = None,
    lo: float = 0.0,
    hi: float = DN_MAX,
    lsb: float | None = None,
    rounding: bool = False,
    slope: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """E[n], E[n^2] and P(not clipped) of the clipped noise at clean values ``x`` (1-D).

    ``slope`` (per x) scales the noise before clipping (a non-linear pixel response, linearised).

    With ``lsb`` the output is also rounded to the levels j * lsb (0 and 255 are levels), exactly
    where the noise is narrow against the step and with Sheppard's correction where it is wide;
    ``rounding=True`` then returns the moments of the rounding error Q(Y) - Y instead of n.
    See the module docstring for the noise model.
    """
    x = np.asarray(x, dtype=float)
    n = x.shape[0]
    lam = np.broadcast_to(np.asarray(lam, dtype=float), (n,)).copy()
    s2 = np.broadcast_to(np.asarray(s2, dtype=float), (n,)).copy()
    big = lam > POISSON_EXACT_MAX
    s2[big] += scale**2 * lam[big]
    lam[big] = 0.0
    mixtures = [(f, np.broadcast_to(np.asarray(o, dtype=float), (n,))) for f, o in mixtures or []]
    exact = lam > 0.0
    if exact.any() and not exact.all():  # only the exact-Poisson values need the sum over K
        out = [np.empty(n) for _ in range(3)]
        for sel in (exact, ~exact):
            part = noise_moments(x[sel], lam[sel], scale, s2[sel], [(f, o[sel]) for f, o in mixtures],
                                 lo, hi, lsb, rounding, None if slope is None else slope[sel])
            for arr, val in zip(out, part):
                arr[sel] = val
        return out[0], out[1], out[2]

    # mixture components: weights (C,) and offsets (C, n)
    weights = np.ones(1)
    offsets = np.zeros((1, n))
    for frac, off in mixtures:
        weights = np.concatenate([weights * (1.0 - frac), weights * frac])
        offsets = np.concatenate([offsets, offsets + off[None, :]])
    keep = weights > 0
    weights, offsets = weights[keep], offsets[keep]

    if n and float(lam.max()) > 0.0:
        shift, pk = poisson_terms(lam, scale)  # (K, n)
    else:
        pk = np.ones((1, n))
        shift = np.zeros((1, n))

    if slope is not None:
        slope = np.broadcast_to(np.asarray(slope, dtype=float), (n,))
        s2 = np.asarray(s2 * slope**2)
        shift, offsets = shift * slope, offsets * slope
    s = np.sqrt(s2)[None, None, :]
    mu = shift[None, :, :] + offsets[:, None, :]  # (C, K, n)
    lo_x, hi_x = (lo - x)[None, None, :], (hi - x)[None, None, :]
    if not s2.any():  # discrete noise only: clip the atoms directly
        y = np.clip(mu, lo_x, hi_x)
        m1, m2, inside = y, y * y, ((mu > lo_x) & (mu < hi_x)).astype(float)
    else:
        m1, m2, inside = clipped_normal_moments(mu, s, lo_x, hi_x)
    w = weights[:, None, None] * pk[None, :, :]
    e1, e2, p_in = np.sum(w * m1, axis=(0, 1)), np.sum(w * m2, axis=(0, 1)), np.sum(w * inside, axis=(0, 1))
    if lsb is None:
        return e1, e2, p_in
    q1, q2, r1, r2 = quantized_noise_moments(x, e1, e2, p_in, mu, np.sqrt(s2), w, lsb, hi)
    return (r1, r2, p_in) if rounding else (q1, q2, p_in)


#: Where the Gaussian part of the noise is wider than this many steps, the rounding error is uniform
#: and independent of the signal to ~exp(-2 pi^2 0.7^2) = 6e-5 (Sheppard's correction is exact enough)...
SHEPPARD_MIN_SIGMA_LSB = 0.7
#: ... except next to the clipped ends, where the last half step always rounds towards the end level:
#: there the rounding is computed exactly unless the noise is wider than this many steps.
EDGE_EXACT_MAX_SIGMA_LSB = 3.0


def quantized_noise_moments(x, e1, e2, p_in, mu, s, w, lsb, hi):
    """(E[n], E[n^2], E[r], E[r^2]) after rounding: exact where the Gaussian part is narrow, Sheppard elsewhere."""
    r2 = lsb**2 / 12.0 * p_in  # clipped outputs sit on the end levels: no rounding error there
    out = [e1.copy(), e2 + r2, np.zeros_like(x), r2.copy()]
    sd = np.sqrt(np.maximum(e2 - e1**2, 0.0))
    near_end = (np.minimum(x, hi - x) < 6.0 * sd + lsb) & (s < EDGE_EXACT_MAX_SIGMA_LSB * lsb)
    narrow = (s < SHEPPARD_MIN_SIGMA_LSB * lsb) | near_end
    if narrow.any():
        exact = _quantized_moments(x[narrow], mu[..., narrow], s[narrow], w[..., narrow], lsb, hi)
        for arr, val in zip(out, exact):
            arr[narrow] = val
    return tuple(out)


def _quantized_moments(x, mu, s, w, lsb, hi, chunk: int = 64):
    """Moments of rounding to the levels j * lsb, j = 0..M (M lsb = hi), of Y = clip(x + mu + N(0, s^2)).

    Returns (E[n], E[n^2], E[r], E[r^2]) with n = Q(Y) - x (the quantized noise) and r = Q(Y) - Y (the
    rounding error). Uses Q(y) = lsb * #{j : y > e_j} with edges e_j = (j + 1/2) lsb, summed over a
    window of edges around each component (edges far below count fully, far above not at all).
    """
    m_edges = int(round(hi / lsb))
    s_eff = np.maximum(s, 1e-9)
    half = int(np.ceil(8.0 * float(np.max(s_eff)) / lsb)) + 2
    offs = np.arange(-half, half + 1)
    acc = np.zeros((5, x.size))  # E[Q], E[Q^2], E[Y], E[Y^2], E[Q Y]
    for k0 in range(0, mu.shape[1], chunk):
        centre = x[None, None, :] + mu[:, k0:k0 + chunk, :]  # (C, k, n)
        ww = w[:, k0:k0 + chunk, :]
        sd = s_eff[None, None, :]
        y1, y2, _ = clipped_normal_moments(centre, sd, 0.0, hi)
        c0 = np.floor(centre / lsb - 0.5).astype(np.int64)
        j = c0[..., None] + offs  # (C, k, n, J)
        valid = (j >= 0) & (j < m_edges)
        jlo = np.clip(c0 - half, 0, m_edges).astype(float)  # edges below the window: always exceeded
        a = ((j + 0.5) * lsb - centre[..., None]) / sd[..., None]
        b = ((hi - centre) / sd)[..., None]
        above = np.where(valid, 1.0 - ndtr(a), 0.0)
        # E[Y 1{Y > e}] for Y = clip(Z, 0, hi), 0 < e < hi
        part = centre[..., None] * (ndtr(b) - ndtr(a)) + sd[..., None] * (_phi(a) - _phi(b)) + hi * (1.0 - ndtr(b))
        part = np.where(valid & (a < b), part, 0.0)
        eq = lsb * (jlo + above.sum(-1))
        eq2 = lsb**2 * (jlo**2 + ((2 * j + 1) * above).sum(-1))
        eqy = lsb * (jlo * y1 + part.sum(-1))
        for row, val in enumerate((eq, eq2, y1, y2, eqy)):
            acc[row] += np.sum(ww * val, axis=(0, 1))
    eq, eq2, ey, ey2, eqy = acc
    return eq - x, eq2 - 2.0 * x * eq + x * x, eq - ey, eq2 - 2.0 * eqy + ey2


def clipped_pmf(
    x: np.ndarray,
    grid: np.ndarray,
    mean: np.ndarray,
    var: np.ndarray,
    mixtures: list[tuple[float, np.ndarray]] | None = None,
) -> np.ndarray:
    """Distribution of clip(x + noise) on ``grid`` (rows: x), noise Gaussian-approximated per component.

    The grid spans the clip range: mass beyond its ends lands on the end points (the clipped atoms).

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


def poisson_terms(lam: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Atoms (K, n) of the noise scale * (K - lam) and their probabilities (lam <= 1000 exact)."""
    lam = np.asarray(lam, dtype=float)
    lam_max = float(lam.max()) if lam.size else 0.0
    k0 = np.maximum(np.floor(lam - 8.0 * np.sqrt(lam) - 2.0), 0.0)
    span = int(np.ceil(16.0 * np.sqrt(lam_max) + 16.0))
    k = k0[None, :] + np.arange(span, dtype=float)[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        logp = np.where(lam[None, :] > 0, k * np.log(np.maximum(lam[None, :], 1e-300)), np.where(k == 0, 0.0, -np.inf))
    return scale * (k - lam[None, :]), np.exp(logp - lam[None, :] - gammaln(k + 1.0))


def scatter_pmf(x: np.ndarray, shifts: np.ndarray, probs: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Distribution of clip(x + shift) on an evenly spaced grid from atoms (A, n), mean-preserving split."""
    step = grid[1] - grid[0]
    pos = np.clip(x[None, :] + shifts, grid[0], grid[-1])
    u = (pos - grid[0]) / step
    i0 = np.minimum(np.floor(u).astype(np.int64), grid.size - 2)
    frac = u - i0
    row = np.broadcast_to(np.arange(x.size)[None, :], pos.shape) * grid.size
    flat = np.concatenate([(row + i0).ravel(), (row + i0 + 1).ravel()])
    mass = np.concatenate([(probs * (1.0 - frac)).ravel(), (probs * frac).ravel()])
    return np.bincount(flat, weights=mass, minlength=x.size * grid.size).reshape(x.size, grid.size)
