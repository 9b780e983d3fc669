"""Clean grayscale source images (DN, float32): bundled photographs and procedural dead leaves.

Training photographs come from scikit-image's bundled samples; held-out photographs from
matplotlib's bundled sample data (a different package, never used in training) and, for the
images-only check, also PyWavelets' bundled photographs. Only images that load offline are listed.
Photographs are downsampled 2x (area) to suppress their own noise (the ``photos_native`` split keeps the
held-out ones at their native resolution). :class:`Imagery` describes the training imagery beyond the
paper-style recipe: photographs at 1x and arbitrary rotations, JPEG-compressed sources and man-made
procedural scenes (``procedural.manmade_images``).
"""
from __future__ import annotations

import gzip
import json
import math
from dataclasses import asdict, dataclass

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
#: photos: matplotlib + PyWavelets images only (no dead leaves; generalisation to photographs);
#: photos_native: the same images at their native resolution (no 2x downsample: the scale is unknown).
SPLITS = ("train", "heldout", "photos", "photos_native")
#: Ranges (log-uniform) of the area downscale and gamma of ``photo_variants``.
PHOTO_DOWNSCALE = (1.5, 4.0)
PHOTO_GAMMA = (0.6, 1.6)
#: Range of the JPEG quality of ``Imagery.jpeg`` (uniform integers, inclusive).
JPEG_QUALITY = (40, 95)


@dataclass(frozen=True)
class Imagery:
    """What the training imagery holds beyond the paper-style recipe; the defaults add nothing, so a
    dataset generated with them is bit-identical to one generated before the option existed.

    - ``photo_scales``: log-uniform range of the area downscale of the photo variants (``photo_variants``);
      1 = native resolution;
    - ``photo_native``: probability that a photo variant is kept at its native resolution (no resampling);
    - ``photo_rotate``: probability that a photo variant is rotated by an arbitrary angle (Lanczos, at
      native resolution before the downscale; cropped to the largest axis-aligned rectangle inside);
    - ``jpeg``: probability that a clean source image (any kind) is JPEG-compressed at a quality in
      ``JPEG_QUALITY`` before cropping (blocking and ringing as scene content);
    - ``manmade``: man-made procedural scenes added (``procedural.manmade_images``: dead leaves of
      polygons, periodic bars);
    - ``grain``: grainy procedural pictures added (``procedural.grain_images``: near-white grain as scene
      content);
    - ``charts``: test charts added (``procedural.chart_images``: tiles over the whole intensity range);
    - ``gratings``: plain gratings added (``procedural.plain_grating_images``: pixel-scale sine gratings over the
      whole image).
    """

    photo_scales: tuple[float, float] = PHOTO_DOWNSCALE
    photo_native: float = 0.0
    photo_rotate: float = 0.0
    jpeg: float = 0.0
    manmade: int = 0
    grain: int = 0
    charts: int = 0
    gratings: int = 0

    def __post_init__(self) -> None:
        lo, hi = self.photo_scales
        if not 1.0 <= lo <= hi:
            raise ValueError(f"photo scales must be 1 <= low <= high, got {self.photo_scales}")
        for name in ("photo_native", "photo_rotate", "jpeg"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must be a probability in [0, 1], got {getattr(self, name)}")
        if min(self.manmade, self.grain, self.charts, self.gratings) < 0:
            raise ValueError(f"manmade, grain, chart and grating images must be >= 0, got {self.manmade}, {self.grain}, "
                             f"{self.charts} and {self.gratings}")

    @property
    def default_photos(self) -> bool:
        """True when the photo variants are drawn as before the option (``photo_variants`` alone)."""
        return (tuple(self.photo_scales) == PHOTO_DOWNSCALE and self.photo_native == 0.0
                and self.photo_rotate == 0.0)

    def is_default(self) -> bool:
        return self == Imagery()

    def as_dict(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    def to_json(self) -> str:
        return json.dumps(self.as_dict(), sort_keys=True)

    @classmethod
    def from_dict(cls, d: dict) -> Imagery:
        return cls(**{**d, "photo_scales": tuple(d.get("photo_scales", PHOTO_DOWNSCALE))})



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


def skimage_originals() -> list[np.ndarray]:
    """The training photographs at their native resolution (grayscale DN)."""
    import skimage.data

    out = []
    for name in SKIMAGE_PHOTOS:
        img = getattr(skimage.data, name)()
        out.append(to_gray_dn(img[0] if isinstance(img, tuple) else img))
    return out


def skimage_photos() -> list[np.ndarray]:
    return [_downsample(img) for img in skimage_originals()]


def inscribed_size(w: int, h: int, angle: float) -> tuple[int, int]:
    """Width and height of the largest axis-aligned rectangle inside a w x h rectangle rotated by
    ``angle`` (radians) about its centre (floored, 1 px margin)."""
    sin_a, cos_a = abs(math.sin(angle)), abs(math.cos(angle))
    long_side, short_side = max(w, h), min(w, h)
    if short_side <= 2.0 * sin_a * cos_a * long_side or abs(sin_a - cos_a) < 1e-10:
        x = 0.5 * short_side  # half-constrained: two corners touch the longer sides
        wr, hr = (x / sin_a, x / cos_a) if w >= h else (x / cos_a, x / sin_a)
    else:
        cos_2a = cos_a * cos_a - sin_a * sin_a
        wr, hr = (w * cos_a - h * sin_a) / cos_2a, (h * cos_a - w * sin_a) / cos_2a
    return max(int(wr) - 2, 1), max(int(hr) - 2, 1)


def rotate_inscribed(img: np.ndarray, angle_deg: float) -> np.ndarray:
    """``img`` rotated by ``angle_deg`` about its centre (Lanczos, at its own resolution) and cropped to
    the largest axis-aligned rectangle inside the rotated image (no border fill), clipped to 0..255."""
    h, w = img.shape
    rot = cv2.getRotationMatrix2D(((w - 1) / 2.0, (h - 1) / 2.0), angle_deg, 1.0)
    out = cv2.warpAffine(img, rot, (w, h), flags=cv2.INTER_LANCZOS4, borderMode=cv2.BORDER_REFLECT)
    cw, ch = inscribed_size(w, h, math.radians(angle_deg))
    y0, x0 = (h - ch) // 2, (w - cw) // 2
    return np.clip(out[y0:y0 + ch, x0:x0 + cw], 0.0, 255.0)


def jpeg_compress(img: np.ndarray, quality: int) -> np.ndarray:
    """The image (DN) after a JPEG round trip at ``quality`` (cv2; rounded to 8 bits first)."""
    ok, buf = cv2.imencode(".jpg", np.clip(np.rint(img), 0, 255).astype(np.uint8), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    decoded = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE) if ok else None
    if decoded is None:
        raise RuntimeError("JPEG round trip failed")
    return decoded.astype(np.float32)


def photo_variants(rng: np.random.Generator, per_photo: int, imagery: Imagery | None = None) -> list[np.ndarray]:
    """``per_photo`` versions of every training photograph, each area-downsampled by a random factor
    (``PHOTO_DOWNSCALE``, for originals of at least 256 px) and with a random gamma (``PHOTO_GAMMA``):
    the same scenes with texture at other scales and contrasts than the fixed 2x of ``skimage_photos``.
    With ``imagery`` (non-default photo options): :func:`diverse_photo_variants`."""
    if imagery is not None and not imagery.default_photos:
        return diverse_photo_variants(rng, per_photo, imagery)
    out = []
    for img in skimage_originals():
        for _ in range(per_photo):
            f = float(np.exp(rng.uniform(*np.log(PHOTO_DOWNSCALE)))) if min(img.shape) >= 256 else 1.0
            im = img if f == 1.0 else cv2.resize(img, (int(img.shape[1] / f), int(img.shape[0] / f)),
                                                 interpolation=cv2.INTER_AREA)
            gamma = np.exp(rng.uniform(*np.log(PHOTO_GAMMA)))  # float64: the product is computed in float64
            out.append((255.0 * (im / 255.0) ** gamma).astype(np.float32))
    return out


def diverse_photo_variants(rng: np.random.Generator, per_photo: int, imagery: Imagery) -> list[np.ndarray]:
    """``per_photo`` versions of every training photograph: with probability ``imagery.photo_rotate``
    rotated by an arbitrary angle (:func:`rotate_inscribed`, at native resolution); then kept at native
    resolution with probability ``imagery.photo_native`` or else area-downsampled by a log-uniform factor
    in ``imagery.photo_scales`` (originals of at least 256 px; smaller ones stay native); and a random
    gamma (``PHOTO_GAMMA``). Scenes at the photos' own scale (where their fine content and grain sit at
    pixel scale) and with edges at every angle."""
    out = []
    lo, hi = np.log(imagery.photo_scales)
    for img in skimage_originals():
        for _ in range(per_photo):
            im = img
            if rng.random() < imagery.photo_rotate:
                im = rotate_inscribed(im, float(rng.uniform(0.0, 360.0)))
            native = rng.random() < imagery.photo_native
            f = float(np.exp(rng.uniform(lo, hi)))
            if not native and f > 1.0 and min(img.shape) >= 256:
                im = cv2.resize(im, (max(int(im.shape[1] / f), 1), max(int(im.shape[0] / f), 1)),
                                interpolation=cv2.INTER_AREA)
            gamma = np.exp(rng.uniform(*np.log(PHOTO_GAMMA)))
            out.append((255.0 * (np.clip(im, 0.0, 255.0) / 255.0) ** gamma).astype(np.float32))
    return out


def matplotlib_photos(native: bool = False) -> list[np.ndarray]:
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
        out.append(to_gray_dn(img) if native else _downsample(to_gray_dn(img)))
    return out


def pywavelets_photos(native: bool = False) -> list[np.ndarray]:
    import pywt.data

    imgs = [to_gray_dn(getattr(pywt.data, name)()) for name in PYWAVELETS_PHOTOS]
    return imgs if native else [_downsample(im) for im in imgs]


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
                  variants: int = 0, procedural: int = 0, imagery: Imagery = Imagery()) -> list[np.ndarray]:
    """Clean images of a split (see ``SPLITS``): its photographs plus ``n_dead_leaves`` dead-leaves images
    from ``rng`` (none for ``photos`` and ``photos_native``). ``variants`` > 0 (train only): the training
    photographs as ``photo_variants(rng, variants, imagery)`` instead of once at 2x; ``procedural`` > 0
    (train only): that many images of pixel-scale structure from ``procedural.procedural_images`` besides;
    ``imagery`` (train only; :class:`Imagery`): ``imagery.manmade`` man-made scenes, ``imagery.grain`` grainy pictures, ``imagery.charts`` test charts and ``imagery.gratings`` plain gratings besides, then each
    image JPEG-compressed with probability ``imagery.jpeg``. The draws of ``imagery`` come after all
    others, so its defaults leave every earlier dataset bit-identical."""
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    if variants < 0 or (variants and split != "train"):
        raise ValueError(f"photo variants must be >= 0 and only for the train split, got {variants} for {split!r}")
    if procedural < 0 or (procedural and split != "train"):
        raise ValueError(f"procedural images must be >= 0 and only for the train split, got {procedural} for {split!r}")
    if not imagery.is_default() and split != "train":
        raise ValueError(f"imagery options are only for the train split, got {imagery} for {split!r}")
    if not imagery.default_photos and not variants:
        raise ValueError("the photo options of the imagery (scales, native, rotate) need photo variants (variants >= 1)")
    if split in ("photos", "photos_native"):
        native = split == "photos_native"
        return matplotlib_photos(native) + pywavelets_photos(native)
    if variants:
        photos = photo_variants(rng, variants, imagery)
    else:
        photos = skimage_photos() if split == "train" else matplotlib_photos()
    from .procedural import chart_images, grain_images, manmade_images, plain_grating_images, procedural_images

    images = photos + [dead_leaves(rng) for _ in range(n_dead_leaves)] + procedural_images(rng, procedural)
    if imagery.manmade:
        images += manmade_images(rng, imagery.manmade)
    if imagery.grain:
        images += grain_images(rng, imagery.grain)
    if imagery.charts:
        images += chart_images(rng, imagery.charts)
    if imagery.gratings:
        images += plain_grating_images(rng, imagery.gratings)
    if imagery.jpeg:
        lo, hi = JPEG_QUALITY
        images = [jpeg_compress(im, int(rng.integers(lo, hi + 1))) if rng.random() < imagery.jpeg else im
                  for im in images]
    return images


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
