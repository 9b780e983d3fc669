"""Fast seeded random draws for the simulator (torch's vectorised normal, Poisson where it matters)."""
from __future__ import annotations

import numpy as np

#: Above this mean a Poisson draw is replaced by a normal one (skewness < 0.03); the analytic model
#: uses the exact Poisson up to the same mean.
POISSON_NORMAL_LAMBDA = 1000.0


def standard_normal(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """float32 N(0, 1) draws seeded from ``rng`` (torch's generator: ~4x numpy's speed here)."""
    import torch

    gen = torch.Generator().manual_seed(int(rng.integers(0, 2**63 - 1)))
    return torch.empty(tuple(shape), dtype=torch.float32).normal_(generator=gen).numpy()


def poisson(rng: np.random.Generator, lam: np.ndarray, normal_above: float = POISSON_NORMAL_LAMBDA) -> np.ndarray:
    """float32 Poisson draws; normal draws where lam > ``normal_above``."""
    lam = np.asarray(lam, dtype=np.float64)
    big = lam > normal_above
    if not big.any():
        return rng.poisson(lam).astype(np.float32)
    out = (lam + np.sqrt(lam) * standard_normal(rng, lam.shape)).astype(np.float32)
    if not big.all():
        small = ~big
        out[small] = rng.poisson(lam[small])
    return out
