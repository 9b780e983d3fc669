"""Clean grayscale source images (DN, float32): bundled photographs and procedural dead leaves.

Training photographs come from scikit-image's bundled samples; held-out photographs from
matplotlib's bundled sample data (a different package, never used in training) and, for the
images-only check, also PyWavelets' bundled photographs. Only images that load offline are listed.
Photographs are downsampled 2x (area) to suppress their own noise.
"""
from __future__ import annotations

import gzip

import cv2
import numpy as np

#: scikit-image samples that ship with the wheel (no network fetch).
SKIMAGE_PHOTOS = ("astronaut", "brick", "camera", "cat", "chelsea", "clock", "coffee", "coins", "grass",
                  "gravel", "hubble_deep_field", "immunohistochemistry", "moon", "page", "retina", "rocket",
                  "text", "cell", "stereo_motorcycle")
#: matplotlib sample data used only for the held-out benchmark.
MATPLOTLIB_PHOTOS = ("grace_hopper.jpg", "s1045.ima.gz", "jacksboro_fault_dem.npz", "Minduka_Present_Blue_Pack.png")
#: PyWavelets' bundled photographs (its ``camera`` is scikit-image's, a training image: not listed).
PYWAVELETS_PHOTOS = ("aero", "ascent")
#: train: scikit-image photos + dead leaves; heldout: matplotlib images + dead leaves (the benchmark);
#: photos: matplotlib + PyWavelets images only (no dead leaves; generalisation to photographs).
SPLITS = ("train", "heldout", "photos")
#: Ranges (log-uniform) of the area downscale and gamma of ``photo_variants``.
PHOTO_DOWNSCALE = (1.5, 4.0)
PHOTO_GAMMA = (0.6, 1.6)


def to_gray_dn(img: np.ndarray) -> np.ndarray:
    """Any image array -> float32 grayscale on 0..255 (colour: ITU-R 601 luma; floats: rescaled)."""
    a = np.asarray(img)
    if a.dtype == bool:
        a = a.astype(np.float32) * 255.0
    if a.ndim == 3:
        a = a[..., :3].astype(np.float32) @ np.array([0.299, 0.587, 0.114], dtype=np.float32)
    a = a.astype(np.float32)
    if np.issubdtype(np.asarray(img).dtype, np.floating) or a.max() > 255.0:
        lo, hi = float(a.min()), float(a.max())
        a = (a - lo) / max(hi - lo, 1e-6) * 255.0
    return a


def _downsample(a: np.ndarray) -> np.ndarray:
    if min(a.shape) < 256:
        return a
    return cv2.resize(a, (a.shape[1] // 2, a.shape[0] // 2), interpolation=cv2.INTER_AREA)


def _skimage_originals() -> list[np.ndarray]:
    import skimage.data

    out = []
    for name in SKIMAGE_PHOTOS:
        img = getattr(skimage.data, name)()
        out.append(to_gray_dn(img[0] if isinstance(img, tuple) else img))
    return out


def skimage_photos() -> list[np.ndarray]:
    return [_downsample(img) for img in _skimage_originals()]


def photo_variants(rng: np.random.Generator, per_photo: int) -> list[np.ndarray]:
    """``per_photo`` versions of every training photograph, each area-downsampled by a random factor
    (``PHOTO_DOWNSCALE``, for originals of at least 256 px) and with a random gamma (``PHOTO_GAMMA``):
    the same scenes with texture at other scales and contrasts than the fixed 2x of ``skimage_photos``."""
    out = []
    for img in _skimage_originals():
        for _ in range(per_photo):
            f = float(np.exp(rng.uniform(*np.log(PHOTO_DOWNSCALE)))) if min(img.shape) >= 256 else 1.0
            im = img if f == 1.0 else cv2.resize(img, (int(img.shape[1] / f), int(img.shape[0] / f)),
                                                 interpolation=cv2.INTER_AREA)
            gamma = np.exp(rng.uniform(*np.log(PHOTO_GAMMA)))  # float64: the product is computed in float64
            out.append((255.0 * (im / 255.0) ** gamma).astype(np.float32))
    return out


def matplotlib_photos() -> list[np.ndarray]:
    import matplotlib.cbook as cbook
    import matplotlib.image as mimage
    from matplotlib.colors import LightSource

    out = []
    for name in MATPLOTLIB_PHOTOS:
        path = cbook.get_sample_data(name, asfileobj=False)
        if name.endswith(".ima.gz"):
            with gzip.open(path) as f:
                img = np.frombuffer(f.read(), dtype=">u2").reshape(256, 256)
        elif name.endswith(".npz"):
            dem = np.load(path)["elevation"]
            img = LightSource(azdeg=315, altdeg=45).hillshade(dem, vert_exag=0.05)  # shaded relief
        else:
            img = mimage.imread(path)
        out.append(_downsample(to_gray_dn(img)))
    return out


def pywavelets_photos() -> list[np.ndarray]:
    import pywt.data

    return [_downsample(to_gray_dn(getattr(pywt.data, name)())) for name in PYWAVELETS_PHOTOS]


def dead_leaves(rng: np.random.Generator, size: int = 256, leaves: int = 600) -> np.ndarray:
    """A dead-leaves image: occluding disks, power-law radii, random gray levels, slight anti-aliasing."""
    img = np.full((size, size), rng.uniform(0, 255), dtype=np.float32)
    radii = np.exp(rng.uniform(np.log(2.0), np.log(size / 3.0), leaves))
    centres = rng.integers(0, size, (leaves, 2))
    levels = rng.uniform(0, 255, leaves)
    for (cx, cy), r, v in zip(centres, radii, levels):
        cv2.circle(img, (int(cx), int(cy)), int(r), float(v), thickness=-1, lineType=cv2.LINE_AA)
    return cv2.GaussianBlur(img, (0, 0), 0.6)


def source_images(split: str, rng: np.random.Generator, n_dead_leaves: int = 24,
                  variants: int = 0, procedural: int = 0) -> list[np.ndarray]:
    """Clean images of a split (see ``SPLITS``): its photographs plus ``n_dead_leaves`` dead-leaves images
    from ``rng`` (none for ``photos``). ``variants`` > 0 (train only): the training photographs as
    ``photo_variants(rng, variants)`` instead of once at 2x; ``procedural`` > 0 (train only): that many
    images of pixel-scale structure from ``procedural.procedural_images`` besides."""
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    if variants < 0 or (variants and split != "train"):
        raise ValueError(f"photo variants must be >= 0 and only for the train split, got {variants} for {split!r}")
    if procedural < 0 or (procedural and split != "train"):
        raise ValueError(f"procedural images must be >= 0 and only for the train split, got {procedural} for {split!r}")
    if split == "photos":
        return matplotlib_photos() + pywavelets_photos()
    if variants:
        photos = photo_variants(rng, variants)
    else:
        photos = skimage_photos() if split == "train" else matplotlib_photos()
    from .procedural import procedural_images

    return photos + [dead_leaves(rng) for _ in range(n_dead_leaves)] + procedural_images(rng, procedural)


def sample_clean_patches(images: list[np.ndarray], rng: np.random.Generator, n: int, size: int,
                         shift_dn: float = 20.0) -> tuple[np.ndarray, np.ndarray]:
    """n random crops (random image, position, flip, rotation) with a uniform +-shift_dn offset, clipped;
    and the index in ``images`` of each crop's source image."""
    usable = [i for i, im in enumerate(images) if min(im.shape) >= size]
    if not usable:
        raise ValueError(f"no source image is at least {size}x{size} px")
    out = np.empty((n, size, size), dtype=np.float32)
    source = np.asarray(usable)[rng.integers(0, len(usable), n)]
    for i, k in enumerate(source):
        im = images[k]
        y = rng.integers(0, im.shape[0] - size + 1)
        x = rng.integers(0, im.shape[1] - size + 1)
        p = np.rot90(im[y:y + size, x:x + size], int(rng.integers(0, 4)))
        if rng.random() < 0.5:
            p = p[:, ::-1]
        out[i] = p
    out += rng.uniform(-shift_dn, shift_dn, (n, 1, 1)).astype(np.float32)
    return np.clip(out, 0.0, 255.0), source
