"""Pixel-scale residuals of patches and their block energies (shared by the measurement's inputs and the
texture evidence)."""
from __future__ import annotations

from functools import cache

import cv2
import numpy as np

#: Block size of the block-wise residual energies.
BLOCK = 8
#: Immerkaer's mask (Immerkaer 1996): outer([1, -2, 1], [1, -2, 1]) / 6, unit gain on white noise. It
#: annihilates every image that is linear along rows or columns, so edges along either axis leave none.
IMMERKAER = (np.outer([1.0, -2.0, 1.0], [1.0, -2.0, 1.0]) / 6.0).astype(np.float32)


@cache
def _block_sums(h: int, w: int, block: int) -> tuple[np.ndarray, np.ndarray]:
    """(hb, h), (w, wb) float32 indicator matrices: R @ X @ C sums X over its block x block blocks."""
    hb, wb = h // block, w // block
    rows = np.kron(np.eye(hb, dtype=np.float32), np.ones((1, block), np.float32))
    cols = np.kron(np.eye(wb, dtype=np.float32), np.ones((block, 1), np.float32))
    return np.pad(rows, ((0, 0), (0, h - hb * block))), np.pad(cols, ((0, w - wb * block), (0, 0)))


def block_energies(resid: np.ndarray, block: int = BLOCK) -> np.ndarray:
    """Mean squared residual per ``block`` x ``block`` block (row-major), (N, blocks), float64; pixels beyond
    the last whole block are left out. Summed by two matrix products with block indicators (float32: a
    sum of 64 squares is exact to ~1e-7), three times faster than strided reductions."""
    return block_means(np.square(resid, dtype=np.float32), block)


def block_means(x: np.ndarray, block: int = BLOCK) -> np.ndarray:
    """Mean of ``x`` per ``block`` x ``block`` block (row-major), (N, blocks), float64; pixels beyond the last
    whole block are left out."""
    n, h, w = x.shape
    rows, cols = _block_sums(h, w, block)
    m = np.matmul(np.matmul(rows, np.asarray(x, dtype=np.float32)), cols) / np.float32(block * block)
    return m.reshape(n, -1).astype(np.float64)


def quantiles(x: np.ndarray, qs: tuple[float, ...]) -> np.ndarray:
    """Quantiles ``qs`` of each row of ``x`` (N, M), (N, len(qs)): numpy's default (linear) method by one
    sort, without ``np.quantile``'s per-call overhead (4x faster on a batch of 16 patches' blocks)."""
    s = np.sort(x, axis=1)
    pos = np.asarray(qs) * (x.shape[1] - 1)
    lo = np.floor(pos).astype(np.intp)
    hi = np.minimum(lo + 1, x.shape[1] - 1)
    return s[:, lo] + (s[:, hi] - s[:, lo]) * (pos - lo)


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
