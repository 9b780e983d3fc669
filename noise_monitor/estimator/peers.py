"""Classical image-noise estimators (peers): skimage's wavelet estimate, PCA (Chen et al. 2015) and
block-based B+F (Shin et al. 2005). Each maps a patch (H, W) in DN to a noise sigma in DN."""
from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np


def skimage_sigma(patch: np.ndarray) -> float:
    """``skimage.restoration.estimate_sigma`` (wavelet MAD, Donoho)."""
    from skimage.restoration import estimate_sigma

    return float(estimate_sigma(patch.astype(np.float64)))


def pca_sigma(patch: np.ndarray, block: int = 7) -> float:
    """Chen, Zhu & Heng (ICCV 2015): the noise variance is the mean of the smallest eigenvalues of the
    block covariance, taking the largest tail whose mean equals its median."""
    p = patch.astype(np.float64)
    windows = np.lib.stride_tricks.sliding_window_view(p, (block, block)).reshape(-1, block * block)
    eig = np.sort(np.linalg.eigvalsh(np.cov(windows, rowvar=False)))
    eig = np.maximum(eig, 0.0)
    for i in range(len(eig), 0, -1):
        tail = eig[:i]
        tau = tail.mean()
        if np.sum(tail > tau) == np.sum(tail < tau) or i == 1:
            return float(np.sqrt(tau))
    return float(np.sqrt(eig[0]))


def bf_sigma(patch: np.ndarray, block: int = 8, fraction: float = 0.1) -> float:
    """Shin, Park & Kang (2005) block-based estimate: in the most homogeneous blocks, the std of the
    residual to a Gaussian-filtered image, rescaled by the filter's noise-removal factor."""
    p = patch.astype(np.float32)
    sigma_g = 1.0
    resid = p - cv2.GaussianBlur(p, (0, 0), sigma_g)
    h, w = (s // block * block for s in p.shape)
    blocks = p[:h, :w].reshape(h // block, block, w // block, block).std(axis=(1, 3)).ravel()
    rblocks = resid[:h, :w].reshape(h // block, block, w // block, block).std(axis=(1, 3)).ravel()
    k = max(1, int(round(fraction * len(blocks))))
    keep = np.argsort(blocks)[:k]
    kernel = cv2.getGaussianKernel(int(2 * np.ceil(3 * sigma_g) + 1), sigma_g)
    k2 = kernel @ kernel.T
    c = k2[k2.shape[0] // 2, k2.shape[1] // 2]
    factor = np.sqrt((1.0 - c) ** 2 + (np.sum(k2**2) - c**2))  # residual std per unit noise std
    return float(np.mean(rblocks[keep]) / factor)


PEERS: dict[str, Callable[[np.ndarray], float]] = {
    "skimage_estimate_sigma": skimage_sigma,
    "pca_chen2015": pca_sigma,
    "bf_shin2005": bf_sigma,
}
