"""Inputs of the compact image-noise network, computed identically in training and inference."""
from __future__ import annotations

import numpy as np

from .physics_prior import SIGMA_MAP_FLOOR, box_smooth, predict_from_tables

#: Floor of sigma_model in the log-scalar inputs and in the ratio output (DN).
SIGMA_MODEL_FLOOR = 0.05
#: Block size and quantiles of the block-wise residual energy (texture-robust noise cues).
BLOCK = 8
BLOCK_QUANTILES = (0.1, 0.25, 0.5)


def block_energy_quantiles(resid: np.ndarray, block: int = BLOCK) -> np.ndarray:
    """log of low quantiles of the mean squared residual per ``block`` x ``block`` block (N, Q).

    Texture raises the energy of some blocks; the flattest blocks carry the noise alone, so low
    quantiles measure noise where the whole-patch energy would read texture as noise.
    """
    n, h, w = resid.shape
    hb, wb = h // block, w // block
    e = (resid[:, :hb * block, :wb * block].astype(np.float64) ** 2).reshape(n, hb, block, wb, block).mean(axis=(2, 4))
    return np.log(np.quantile(e.reshape(n, -1), BLOCK_QUANTILES, axis=1).T + 1e-6)


def compact_inputs(noisy: np.ndarray, tables: np.ndarray, group_of: np.ndarray,
                   meta_norm: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """(maps (N, 2, H, W), scalars (N, 19), physics prediction) for noisy patches (N, H, W) in DN.

    maps: residual to the 5x5 box filter divided by the model's sigma at the pixel's smoothed level,
    and the intensity / 255 - 0.5. scalars: normalised metadata (11), log sigma_model, the sources'
    shares of sigma_model^2 (3), the log mean squared normalised residual and its block quantiles (3).
    """
    smooth = box_smooth(noisy)
    phys = predict_from_tables(smooth, tables, group_of, with_map=True)
    resid = (noisy - smooth) / np.maximum(phys.pop("sigma_map"), SIGMA_MAP_FLOOR)
    maps = np.stack([resid, noisy / 255.0 - 0.5], axis=1).astype(np.float32)
    total = np.maximum(phys["total"], SIGMA_MODEL_FLOOR)
    shares = np.stack([phys[s] ** 2 for s in ("pn", "dcsn", "rn")], axis=1) / total[:, None] ** 2
    energy = np.log(np.mean(resid.astype(np.float64) ** 2, axis=(1, 2)) + 1e-6)
    scalars = np.concatenate([meta_norm, np.log(total)[:, None], shares, energy[:, None],
                              block_energy_quantiles(resid)], axis=1).astype(np.float32)
    return maps, scalars, phys
