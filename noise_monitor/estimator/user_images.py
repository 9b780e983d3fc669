"""A user's own clean images as a held-out set (``noise-monitor evaluate --images``).

The benchmark's photographs are six small sample images; a camera engineer wants to know how the estimator
reads the noise on the scenes *their* robot sees. Give clean images of such scenes (low gain, well exposed,
ideally averaged frames): each is turned into grayscale DN (colour by ITU-R 601 luma; :func:`to_scene_dn`: integer
images at the bit depth of their values, floats in [0, 1] or [0, 255] as such), area-downsampled by ``downsample`` (2 by default, as the benchmark's photographs: it
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

#: Bit depths integer images are read at: the fewest holding 99.9 % of an image's pixels (:func:`to_scene_dn`).
BIT_DEPTHS = (8, 10, 12, 14, 16)
#: An image with more of its pixels at 0 or 255 DN is no scene (black, or saturated).
MAX_CLIPPED = 0.5
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


def to_scene_dn(a: np.ndarray, name: str | Path) -> np.ndarray:
    """A user's image -> float32 grayscale DN on 0..255, its brightness as recorded: 8-bit as it is; other integers at
    the bit depth of their values (the fewest of ``BIT_DEPTHS`` holding 99.9 % of the pixels: a 12-bit scene in
    16-bit words reads as 12-bit, a hot pixel clips instead of darkening the rest); floats in [0, 1] times 255, in
    [0, 255] as they are, others stretched between their 0.1 and 99.9 percentiles. Until 2026-12-04 16-bit and float
    images were stretched between their minimum and maximum: one hot pixel put a 12-bit scene into 0..15 DN, a constant
    float image read 0 DN. Negative integers and images mostly at 0 or 255 DN are refused (ValueError)."""
    if a.dtype.kind == "b":
        return to_gray_dn(a)
    if a.dtype.kind == "i" and a.min() < 0:
        raise ValueError(f"--images: {name} holds negative values (signed {a.dtype}): give DN, 0 and above")
    g = a.astype(np.float32)
    if g.ndim == 3:  # ITU-R 601 luma of the colour values, on their own scale
        g = g[..., :3] @ np.array([0.299, 0.587, 0.114], dtype=np.float32)
    if a.dtype.kind in "ui":
        top = float(np.percentile(g, 99.9))
        bits = next((b for b in BIT_DEPTHS if top <= 2**b - 1), None)
        g = _stretch(g) if bits is None else np.minimum(g * np.float32(255.0 / (2**bits - 1)), 255.0)
    else:
        lo, hi = float(g.min()), float(g.max())
        g = g * np.float32(255.0) if 0.0 <= lo and hi <= 1.0 else g if 0.0 <= lo and hi <= 255.0 else _stretch(g)
    clipped = float(np.mean((g <= 0.5) | (g >= 254.5)))
    if clipped > MAX_CLIPPED:
        raise ValueError(f"--images: {name} has {clipped:.0%} of its pixels at 0 or 255 DN: a black or saturated image "
                         "is no scene to measure noise on")
    return np.asarray(g, dtype=np.float32)


def _stretch(g: np.ndarray) -> np.ndarray:
    """Between the 0.1 and 99.9 percentiles onto 0..255 (clipped beyond)."""
    lo, hi = np.percentile(g, [0.1, 99.9])
    return np.clip((g - lo) * np.float32(255.0 / max(float(hi - lo), 1e-6)), 0.0, 255.0)


def load_image_set(paths: Sequence[Path], downsample: int = 2, patch_size: int = 64) -> ImageSet:
    """The images in ``paths`` (files, or directories of ``SUFFIXES`` files), grayscale DN, area-downsampled by
    ``downsample`` (1-4); each must keep at least ``patch_size`` px on its shorter side."""
    if not 1 <= downsample <= 4:
        raise ValueError(f"--image-downsample must be 1-4, got {downsample}")
    names, ims = [], []
    for f in _files(paths):
        im = to_scene_dn(_read(f), f)
        if downsample > 1:
            im = cv2.resize(im, (im.shape[1] // downsample, im.shape[0] // downsample), interpolation=cv2.INTER_AREA)
        if min(im.shape) < patch_size:
            raise ValueError(f"--images: {f} is {im.shape[1]}x{im.shape[0]} px after {downsample}x downsampling, "
                             f"smaller than the {patch_size} px it needs on its shorter side")
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
