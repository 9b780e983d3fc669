"""Fast seeded random draws for the simulator (torch's vectorised normal, Poisson where it matters)."""
from __future__ import annotations

import numpy as np

#: Above this mean a Poisson draw is replaced by a normal one (skewness < 0.06: invisible in clipped
#: moments at the 1 % level); the analytic model keeps the exact Poisson up to a mean of 1000.
POISSON_NORMAL_LAMBDA = 300.0


def standard_normal(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """float32 N(0, 1) draws seeded from ``rng`` (torch's generator: ~4x numpy's speed here)."""
    import torch

    gen = torch.Generator().manual_seed(int(rng.integers(0, 2**63 - 1)))
    return torch.empty(tuple(shape), dtype=torch.float32).normal_(generator=gen).numpy()


def poisson(rng: np.random.Generator, lam: np.ndarray, normal_above: float = POISSON_NORMAL_LAMBDA) -> np.ndarray:
    """float32 Poisson draws; normal draws where lam > ``normal_above``."""
    lam = np.asarray(lam, dtype=np.float64)
    if lam.size > 1 and lam.min() == lam.max() and lam.flat[0] <= normal_above:
        return _poisson_constant(rng, float(lam.flat[0]), lam.shape)
    big = lam > normal_above
    if not big.any():
        return rng.poisson(lam).astype(np.float32)
    out = (lam + np.sqrt(lam) * standard_normal(rng, lam.shape)).astype(np.float32)
    if not big.all():
        small = ~big
        out[small] = rng.poisson(lam[small])
    return out


def _poisson_constant(rng: np.random.Generator, lam: float, shape: tuple[int, ...]) -> np.ndarray:
    """Poisson draws of one mean by inverting its CDF table (exact, ~5x faster than numpy's PTRS)."""
    from scipy.special import gammaln

    k = np.arange(int(lam + 12.0 * np.sqrt(lam) + 12.0) + 1, dtype=np.float64)
    logp = k * np.log(lam) - lam - gammaln(k + 1.0) if lam > 0 else np.where(k == 0, 0.0, -np.inf)
    cdf = np.cumsum(np.exp(logp))
    cdf[-1] = 1.0  # the tail beyond 12 sigma (< 1e-30) joins the last count
    u = rng.random(shape)
    return np.searchsorted(cdf, u, side="right").astype(np.float32)
