"""An upper bound of the noise in a patch from the image alone, valid whatever the scene holds.

The camera's noise is independent of the scene, so in every block the energy of the Immerkaer residual
is the scene's plus the noise's (their cross term averages out): scene content can hide the noise, never
cancel it. A low quantile of the block energies therefore bounds the noise from above on any content;
on white noise it is calibrated so that the bound falls below the true sigma in only ``1 - COVERAGE``
of patches, and content only raises it. A patch the confidence head declines (texture hides the noise)
still proves ``sigma_image <= sigma_image_upper``, hence ``xi >= xi_lower = sigma_model -
sigma_image_upper``: "the model predicts more noise than the image holds" can be decided on any
content, "the image is noisier" only where the noise is measurable.

Blocks holding a clipped pixel (at 0 or ``DN_MAX``, where the noise is cut) or next to one (the residual's
3x3 support) are left out; the calibration follows the number of blocks that remain.
"""
from __future__ import annotations

from functools import cache

import numpy as np
import scipy.ndimage

from ..physics.constants import DN_MAX
from .residuals import BLOCK, block_energies, immerkaer

#: Probability that the bound is at or above the true noise on a pure-noise patch.
COVERAGE = 0.99
#: Quantile of the usable blocks' energies that the bound starts from.
BOUND_QUANTILE = 0.05
#: White-noise draws per block count in the calibration.
_DRAWS = 4000


@cache
def _white_block_energies() -> np.ndarray:
    """Immerkaer block energies of unit white noise (seeded pool of 512 patches of 64 px)."""
    noise = np.random.default_rng(20250).standard_normal((512, 64, 64)).astype(np.float32)
    return block_energies(immerkaer(noise)).ravel()


@cache
def bound_factor(n_blocks: int) -> float:
    """1 - COVERAGE quantile, over white-noise patches of ``n_blocks`` blocks, of
    sqrt(BOUND_QUANTILE quantile of their block energies) / sigma (seeded Monte-Carlo)."""
    pool = _white_block_energies()
    draws = np.random.default_rng(20251 + n_blocks).choice(pool, size=(_DRAWS, n_blocks))
    q = np.quantile(draws, BOUND_QUANTILE, axis=1)
    return float(np.sqrt(np.quantile(q, 1.0 - COVERAGE)))


def usable_blocks(noisy: np.ndarray, block: int = BLOCK) -> np.ndarray:
    """(N, blocks) bool: blocks with no clipped pixel within one pixel (row-major like ``block_energies``)."""
    clipped = (noisy <= 0.0) | (noisy >= DN_MAX)
    if not clipped.any():
        return np.ones((noisy.shape[0], (noisy.shape[1] // block) * (noisy.shape[2] // block)), dtype=bool)
    grown = scipy.ndimage.maximum_filter(clipped.astype(np.float32), size=(1, 3, 3), mode="constant")
    return block_energies(grown, block) == 0.0


def noise_upper_bound(noisy: np.ndarray, shaped_energies: np.ndarray) -> np.ndarray:
    """(N,) upper bound of each patch's noise sigma (DN, RMS over the patch like sigma_image; inf where
    every block is clipped). ``shaped_energies``: the Immerkaer block energies divided by the model's
    unit-RMS sigma shape (``features.compact_inputs``), so the bound follows the noise's intensity
    dependence like the measurement does."""
    ok = usable_blocks(noisy)
    e = np.where(ok, shaped_energies, np.inf)
    e.sort(axis=1)
    n = ok.sum(axis=1)
    out = np.full(len(e), np.inf)
    for k in np.unique(n[n > 0]):
        rows = np.flatnonzero(n == k)
        pos = BOUND_QUANTILE * (k - 1)
        lo = int(np.floor(pos))
        hi = min(lo + 1, k - 1)
        q = e[rows, lo] + (e[rows, hi] - e[rows, lo]) * (pos - lo)
        out[rows] = np.sqrt(q) / bound_factor(int(k))
    return out
