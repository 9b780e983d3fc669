"""Inputs of the compact image-noise network, computed identically in training and inference."""
from __future__ import annotations

import cv2
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


#: Variance of the 4-neighbour Laplacian of unit white noise (16 + 4 x 1).
LAPLACIAN_GAIN = 20.0


def laplacian(patches: np.ndarray) -> np.ndarray:
    """4-neighbour Laplacian of every patch of an (N, H, W) float32 batch (cv2, reflect-101 border)."""
    out = np.empty_like(patches, dtype=np.float32)
    for i, p in enumerate(patches):
        out[i] = cv2.Laplacian(np.asarray(p, dtype=np.float32), cv2.CV_32F, ksize=1)
    return out


def compact_inputs(noisy: np.ndarray, tables: np.ndarray, group_of: np.ndarray,
                   meta_norm: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """(maps (N, 3, H, W), scalars (N, 23), physics prediction) for noisy patches (N, H, W) in DN.

    maps: the residual to the 5x5 box filter and the Laplacian / sqrt(20) (unit variance on white
    noise; a linear ramp leaves none), both divided by the model's sigma at the pixel's smoothed level,
    and the intensity / 255 - 0.5. scalars: normalised metadata (11), log sigma_model, the sources'
    shares of sigma_model^2 (3), per residual the log mean square and its block quantiles (2 x 4).
    """
    smooth = box_smooth(noisy)
    phys = predict_from_tables(smooth, tables, group_of, with_map=True)
    sigma_map = np.maximum(phys.pop("sigma_map"), SIGMA_MAP_FLOOR)
    resid = (noisy - smooth) / sigma_map
    lap = laplacian(noisy) / (np.sqrt(LAPLACIAN_GAIN, dtype=np.float32) * sigma_map)
    maps = np.stack([resid, lap, noisy / 255.0 - 0.5], axis=1).astype(np.float32)
    total = np.maximum(phys["total"], SIGMA_MODEL_FLOOR)
    shares = np.stack([phys[s] ** 2 for s in ("pn", "dcsn", "rn")], axis=1) / total[:, None] ** 2
    energy = [np.log(np.mean(r.astype(np.float64) ** 2, axis=(1, 2)) + 1e-6)[:, None] for r in (resid, lap)]
    scalars = np.concatenate([meta_norm, np.log(total)[:, None], shares, energy[0], block_energy_quantiles(resid),
                              energy[1], block_energy_quantiles(lap)], axis=1).astype(np.float32)
    return maps, scalars, phys
