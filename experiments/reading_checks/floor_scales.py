"""Is the held-out photographs' noise-like content noise? Their image-only floors across scales.

``user_images.own_noise_floor`` (the image-only reference on the clean image's tiles, median) reads 2.54 DN on
grace_hopper and 2.65 DN on aero at the ``photos`` scale (2x area-downsampled), and their accepted patches read
sigma_image high by the floor added in quadrature. White noise in a source image halves with each 2x area
downsampling (four pixels averaged); content at the noise's scale (texture, grain of a print) does not. This prints
each photograph's floor at native resolution and 2x and 4x area-downsampled (32 px tiles, so that every image has tiles
at 4x), and the ratio of successive floors (2: noise; 1 or less: content).

Usage: .venv/bin/python experiments/reading_checks/floor_scales.py
"""
from __future__ import annotations

import cv2
import numpy as np

from noise_monitor.estimator import images
from noise_monitor.estimator.user_images import own_noise_floor

TILE = 32


def floor_at(image: np.ndarray, factor: int) -> float:
    """The own-noise floor of ``image`` area-downsampled by ``factor``."""
    h, w = image.shape[0] // factor, image.shape[1] // factor
    small = image if factor == 1 else cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA)
    return own_noise_floor(np.ascontiguousarray(small, dtype=np.float32), TILE)


def main() -> None:
    names = images.MATPLOTLIB_PHOTOS + images.PYWAVELETS_PHOTOS
    native = images.matplotlib_photos(native=True) + images.pywavelets_photos(native=True)
    print(f"{'photograph':32s} {'native px':>10s}  floor DN at native / 2x / 4x   ratio native/2x, 2x/4x (noise: 2)")
    for name, im in zip(names, native):
        f1, f2, f4 = (floor_at(im, k) for k in (1, 2, 4))
        print(f"{name:32s} {im.shape[1]:4d}x{im.shape[0]:<5d}  {f1:6.2f} / {f2:6.2f} / {f4:6.2f}"
              f"           {f1 / f2:5.2f}, {f2 / f4:5.2f}")


if __name__ == "__main__":
    main()
