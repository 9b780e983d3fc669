"""A user's own clean images as a held-out set (``noise-monitor evaluate --images``).

The benchmark's photographs are six small sample images; a camera engineer wants to know how the estimator
reads the noise on the scenes *their* robot sees. Give clean images of such scenes (low gain, well exposed,
ideally averaged frames): each is turned into grayscale DN (colour by ITU-R 601 luma; 16-bit and float images
stretched to 0..255), area-downsampled by ``downsample`` (2 by default, as the benchmark's photographs: it
halves the image's own noise), and the set's parts are drawn from them like the benchmark's (``data.PARTS``,
seeds ``SEEDS``). The truth counts whatever the clean image holds as scene, including its own noise, film grain
or JPEG blocking; :func:`own_noise_floor` says how much of that each image has, so that an error which is the
image's and not the estimator's can be told apart.
"""
from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from .features import reference_sigma
from .images import to_gray_dn

#: File types read (``.npy``: a 2-D or H x W x 3 array).
SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".pgm", ".ppm", ".npy")
#: Data seeds of the parts (never used for training or the bundled sets).
SEEDS = {"a": 3001, "b": 3002, "c": 3003}


@dataclass(frozen=True)
class ImageSet:
    """Clean grayscale images (DN, float32) with their names and a content key (cache file names)."""

    names: tuple[str, ...]
    images: tuple[np.ndarray, ...]
    downsample: int

    @property
    def key(self) -> str:
        h = hashlib.sha256(str(self.downsample).encode())
        for name, im in zip(self.names, self.images):
            h.update(name.encode())
            h.update(str(im.shape).encode())
            h.update(np.ascontiguousarray(im).tobytes())
        return h.hexdigest()[:16]


def _files(paths: Sequence[Path]) -> list[Path]:
    out: list[Path] = []
    for p in paths:
        if p.is_dir():
            found = sorted(f for f in p.iterdir() if f.is_file() and f.suffix.lower() in SUFFIXES)
            if not found:
                raise ValueError(f"--images: no image ({', '.join(SUFFIXES)}) in directory {p}")
            out += found
        elif p.is_file():
            out.append(p)
        else:
            raise FileNotFoundError(f"--images: {p} not found")
    return out


def _read(path: Path) -> np.ndarray:
    if path.suffix.lower() == ".npy":
        try:
            a = np.load(path, allow_pickle=False)
        except ValueError as e:
            raise ValueError(f"--images: {path} is not a plain numpy array ({e})") from None
    else:
        a = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if a is None:
            raise ValueError(f"--images: {path} could not be read as an image")
        if a.ndim == 3 and a.shape[2] in (3, 4):  # OpenCV reads colour as BGR(A)
            a = a[..., 2::-1]
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] not in (3, 4)) or a.dtype.kind not in "uifb":
        raise ValueError(f"--images: {path} must be a grayscale or colour image, got shape {a.shape}, dtype {a.dtype}")
    if not np.isfinite(a).all():
        raise ValueError(f"--images: {path} holds non-finite values")
    return a


def load_image_set(paths: Sequence[Path], downsample: int = 2, patch_size: int = 64) -> ImageSet:
    """The images in ``paths`` (files, or directories of ``SUFFIXES`` files), grayscale DN, area-downsampled by
    ``downsample`` (1-4); each must keep at least ``patch_size`` px on its shorter side."""
    if not 1 <= downsample <= 4:
        raise ValueError(f"--image-downsample must be 1-4, got {downsample}")
    names, ims = [], []
    for f in _files(paths):
        im = to_gray_dn(_read(f))
        if downsample > 1:
            im = cv2.resize(im, (im.shape[1] // downsample, im.shape[0] // downsample), interpolation=cv2.INTER_AREA)
        if min(im.shape) < patch_size:
            raise ValueError(f"--images: {f} is {im.shape[1]}x{im.shape[0]} px after {downsample}x downsampling, "
                             f"smaller than a {patch_size} px patch")
        names.append(f.name)
        ims.append(np.ascontiguousarray(im, dtype=np.float32))
    if len(set(names)) != len(names):
        raise ValueError("--images: two images share a file name; rename one (the per-image table is by name)")
    return ImageSet(tuple(names), tuple(ims), downsample)


def own_noise_floor(image: np.ndarray, patch_size: int = 64) -> float:
    """Median over the clean image's non-overlapping ``patch_size`` tiles of the image-only reference reading
    (``features.reference_sigma`` with a flat shape: the noise-like content of the tile's flattest blocks, DN).
    Noise-free smooth content reads ~0; a clean image with its own white noise of sigma s reads ~s."""
    h, w = image.shape[0] // patch_size, image.shape[1] // patch_size
    tiles = image[:h * patch_size, :w * patch_size].reshape(h, patch_size, w, patch_size).swapaxes(1, 2)
    tiles = np.ascontiguousarray(tiles.reshape(-1, patch_size, patch_size), dtype=np.float32)
    return float(np.median(reference_sigma(tiles, np.ones_like(tiles))))
