"""The monitor's debug view: the frame with its evaluated patches outlined, coloured by their xi.

Green: |xi| below the threshold; red: xi < -threshold (the image is noisier than the model); blue:
xi > threshold (the model predicts more noise). The gray frame is shown as is (DN, 0..255).
"""
from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

GREEN, RED, BLUE = (0, 200, 0), (230, 0, 0), (0, 90, 255)  # RGB


def debug_view(image_dn: np.ndarray, corners: Sequence[tuple[int, int]], size: int, patch_xi: Sequence[float],
               threshold_dn: float) -> np.ndarray:
    """(H, W, 3) uint8 RGB: the gray frame with each patch's square (top-left ``corners``, edge ``size``)."""
    gray = np.clip(np.rint(image_dn), 0, 255).astype(np.uint8)
    rgb = np.ascontiguousarray(np.repeat(gray[:, :, None], 3, axis=2))
    for (y, x), xi in zip(corners, patch_xi):
        colour = GREEN if abs(xi) <= threshold_dn else (RED if xi < 0 else BLUE)
        cv2.rectangle(rgb, (int(x), int(y)), (int(x) + size - 1, int(y) + size - 1), colour, 1)
    return rgb
