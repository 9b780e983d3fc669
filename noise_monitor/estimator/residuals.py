"""Pixel-scale residuals of patches and their block energies (shared by the measurement's inputs and the
texture evidence)."""
from __future__ import annotations

import cv2
import numpy as np

#: Block size of the block-wise residual energies.
BLOCK = 8
#: Immerkaer's mask (Immerkaer 1996): outer([1, -2, 1], [1, -2, 1]) / 6, unit gain on white noise. It
#: annihilates every image that is linear along rows or columns, so edges along either axis leave none.
IMMERKAER = (np.outer([1.0, -2.0, 1.0], [1.0, -2.0, 1.0]) / 6.0).astype(np.float32)


def block_energies(resid: np.ndarray, block: int = BLOCK) -> np.ndarray:
    """Mean squared residual per ``block`` x ``block`` block, (N, blocks), float64."""
    n, h, w = resid.shape
    hb, wb = h // block, w // block
    e = (resid[:, :hb * block, :wb * block].astype(np.float64) ** 2).reshape(n, hb, block, wb, block).mean(axis=(2, 4))
    return e.reshape(n, -1)


def laplacian(patches: np.ndarray) -> np.ndarray:
    """4-neighbour Laplacian of every patch of an (N, H, W) float32 batch (cv2, reflect-101 border)."""
    out = np.empty_like(patches, dtype=np.float32)
    for i, p in enumerate(patches):
        out[i] = cv2.Laplacian(np.asarray(p, dtype=np.float32), cv2.CV_32F, ksize=1)
    return out


def immerkaer(patches: np.ndarray) -> np.ndarray:
    """Immerkaer residual of every patch of an (N, H, W) float32 batch (cv2, reflect-101 border)."""
    out = np.empty_like(patches, dtype=np.float32)
    for i, p in enumerate(patches):
        out[i] = cv2.filter2D(np.asarray(p, dtype=np.float32), cv2.CV_32F, IMMERKAER)
    return out
