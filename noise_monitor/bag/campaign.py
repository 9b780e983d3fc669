"""Field-like campaigns: photographs and textures over most of the frame, a few small flat chart patches,
a camera that holds still for a varying number of frames and pans between holds with sub-pixel
(bilinear) resampling, auto-exposure-like gain/exposure changes at each new view, a sensor temperature
that changes every frame, and vignetting in sensor coordinates.

Two variants: ``tuned`` (scikit-image photographs, procedural textures; the lab was developed on it) and
``heldout`` (matplotlib and PyWavelets photographs, other textures, hold lengths, pans, exposure and
temperature laws; never used to tune the lab). Either can take a user's own scenes for its photo panels
(``make_world(..., photos=...)``, ``simulate-bag --images``) and objects moving through the view while the
camera holds still (``moving_objects``, ``simulate-bag --moving-objects``), and a camera that vibrates (``vibration``,
``simulate-bag --vibration``: a parked robot with its motors running, a mast in the wind).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

#: World size relative to the camera view (the camera pans over the extra area).
WORLD_SCALE = (1.6, 1.8)  # (rows, columns)
VARIANTS = ("tuned", "heldout")
#: Smallest side (pixels, after downsampling) of a user's image read for a campaign's photo panels.
MIN_PHOTO_SIDE = 32
#: Share of a world's panels filled with photographs by default (the others: procedural textures).
PHOTO_SHARE = 0.75


@dataclass(frozen=True)
class Law:
    """How a variant's campaign evolves."""

    hold_frames: tuple[int, int]  # static hold length, inclusive range
    pan_frames: tuple[int, int]  # frames of motion between holds
    exposure_s: tuple[float, float]  # auto-exposure range
    max_gain_db: float
    temperature_c: tuple[float, float]  # start, end of the drift (every frame)
    temperature_wiggle_c: float  # amplitude of a slow oscillation on the drift
    vignetting: float  # relative fall-off at the image corners
    flat_patches: int  # small flat chart patches in the world
    panels: tuple[int, int]  # photo/texture panels (rows, columns) of the world


LAWS = {
    "tuned": Law((5, 14), (2, 4), (0.002, 0.06), 24.0, (30.0, 55.0), 1.5, 0.30, 10, (2, 3)),
    "heldout": Law((4, 18), (1, 5), (0.001, 0.1), 24.0, (22.0, 60.0), 2.5, 0.40, 8, (3, 3)),
}


@dataclass(frozen=True)
class FramePlan:
    """Conditions of one campaign frame: the view's top-left corner in the world (sub-pixel), true
    metadata, scene brightness and whether the view moved since the previous frame."""

    x: float
    y: float
    gain_db: float
    exposure_time_s: float
    sensor_temperature_c: float
    brightness: float
    moving: bool
    hold: int  # index of the static hold (-1 while panning)


def _photos(variant: str) -> list[np.ndarray]:
    from noise_monitor.estimator.images import matplotlib_photos, pywavelets_photos, skimage_photos

    if variant == "tuned":
        return skimage_photos()
    return matplotlib_photos() + pywavelets_photos()


def _procedural(rng: np.random.Generator, h: int, w: int, variant: str) -> np.ndarray:
    """A texture in [0, 1]: multi-scale noise (tuned) or oriented stripes on noise (held-out)."""
    out = np.zeros((h, w), np.float32)
    for s in (1.0, 3.0, 9.0) if variant == "tuned" else (1.5, 5.0, 14.0):
        n = cv2.GaussianBlur(rng.standard_normal((h, w)).astype(np.float32), (0, 0), s)
        out += n / max(float(n.std()), 1e-6) * s ** 0.5
    if variant == "heldout":
        y, x = np.mgrid[0:h, 0:w].astype(np.float32)
        a = rng.uniform(0, math.pi)
        out += 2.0 * np.sin((x * math.cos(a) + y * math.sin(a)) / rng.uniform(2.0, 6.0))
    return (out - out.min()) / max(float(np.ptp(out)), 1e-6)


def make_world(rng: np.random.Generator, height: int, width: int, variant: str = "tuned",
               photos: Sequence[np.ndarray] | None = None, photo_share: float = PHOTO_SHARE) -> np.ndarray:
    """A float32 world in DN larger than the view: panels of photographs (random crops, contrast and
    gamma; each panel with probability ``photo_share``) and procedural textures, with a few small flat chart
    patches (8..247 DN) on top. ``photos``: grayscale DN images (e.g. a user's own scenes) instead of the
    variant's photographs; ``photo_share`` 1: every panel is one of them."""
    if variant not in LAWS:
        raise ValueError(f"campaign variant must be one of {', '.join(LAWS)}, got {variant!r}")
    check_photo_share(photo_share)
    if height < 32 or width < 32:
        raise ValueError(f"image size must be at least 32x32 pixels for a campaign, got {width}x{height}")
    law = LAWS[variant]
    wh, ww = int(round(height * WORLD_SCALE[0])), int(round(width * WORLD_SCALE[1]))
    photos = _photos(variant) if photos is None else list(photos)
    if not photos or any(p.ndim != 2 or min(p.shape) < 8 for p in photos):
        raise ValueError("a campaign's photos must be grayscale images of at least 8x8 pixels")
    pr, pc = law.panels
    world = np.empty((wh, ww), np.float32)
    ys, xs = np.linspace(0, wh, pr + 1).astype(int), np.linspace(0, ww, pc + 1).astype(int)
    for r in range(pr):
        for c in range(pc):
            ph, pw = ys[r + 1] - ys[r], xs[c + 1] - xs[c]
            if rng.random() < photo_share:
                img = photos[int(rng.integers(len(photos)))]
                f = min(img.shape[0] / ph, img.shape[1] / pw) * rng.uniform(0.5, 1.0)
                ch, cw = max(8, int(ph * f)), max(8, int(pw * f))
                y0 = int(rng.integers(0, img.shape[0] - ch + 1))
                x0 = int(rng.integers(0, img.shape[1] - cw + 1))
                panel = cv2.resize(img[y0:y0 + ch, x0:x0 + cw], (pw, ph), interpolation=cv2.INTER_AREA) / 255.0
                if rng.random() < 0.5:
                    panel = panel[:, ::-1]
            else:
                panel = _procedural(rng, ph, pw, variant)
            lo = rng.uniform(5.0, 80.0)
            hi = rng.uniform(max(lo + 60.0, 150.0), 250.0)
            gamma = math.exp(rng.uniform(-0.4, 0.4))
            world[ys[r]:ys[r + 1], xs[c]:xs[c + 1]] = lo + (hi - lo) * np.clip(panel, 0.0, 1.0) ** gamma
    side = max(12, width // 14)
    for level in rng.permutation(np.linspace(8.0, 247.0, law.flat_patches)):
        y0 = int(rng.integers(0, wh - side))
        x0 = int(rng.integers(0, ww - side))
        world[y0:y0 + side, x0:x0 + side] = level
    return np.clip(world, 0.0, 255.0)


def check_photo_share(share: float) -> None:
    """ValueError unless ``share`` is a share of panels (0-1)."""
    if not 0.0 <= share <= 1.0:  # NaN fails too
        raise ValueError(f"photo share must be in [0, 1] (the share of a world's panels that are photographs), got {share}")


def _auto_exposure(rng: np.random.Generator, law: Law, luminance: float) -> tuple[float, float]:
    """(exposure s, gain dB) an auto-exposure picks for a scene luminance in [0, 1] (dark to bright):
    exposure first, gain once the exposure hits its limit."""
    lo, hi = law.exposure_s
    need = math.log(hi / lo) + law.max_gain_db / 20.0 * math.log(10.0)  # total range in nepers
    want = (1.0 - luminance) * need
    exp_part = min(want, math.log(hi / lo))
    gain_db = (want - exp_part) * 20.0 / math.log(10.0)
    return lo * math.exp(exp_part) * math.exp(rng.uniform(-0.05, 0.05)), round(gain_db * 4.0) / 4.0


def plan(rng: np.random.Generator, frames: int, variant: str = "tuned") -> list[FramePlan]:
    """Per-frame conditions: holds of varying length at sub-pixel poses, pans in between (poses are
    fractions of the pan range), auto-exposure per hold, temperature drifting every frame."""
    law = LAWS[variant]
    out: list[FramePlan] = []
    lum = rng.permutation(np.linspace(0.0, 1.0, 8))
    pose = rng.uniform(0.0, 1.0, 2)
    hold = 0
    t0, t1 = law.temperature_c
    phase = rng.uniform(0.0, 2.0 * math.pi)

    def temp(i: int) -> float:
        u = i / max(frames - 1, 1)
        return t0 + (t1 - t0) * u + law.temperature_wiggle_c * math.sin(2.0 * math.pi * 1.5 * u + phase)

    while len(out) < frames:
        exposure, gain = _auto_exposure(rng, law, float(lum[hold % lum.size]))
        brightness = rng.uniform(0.85, 1.05)
        for _ in range(int(rng.integers(law.hold_frames[0], law.hold_frames[1] + 1))):
            if len(out) == frames:
                break
            out.append(FramePlan(float(pose[0]), float(pose[1]), gain, exposure, temp(len(out)), brightness,
                                 False, hold))
        nxt = rng.uniform(0.0, 1.0, 2)
        n = int(rng.integers(law.pan_frames[0], law.pan_frames[1] + 1))
        for j in range(1, n + 1):
            if len(out) == frames:
                break
            p = pose + (nxt - pose) * j / (n + 1)
            out.append(FramePlan(float(p[0]), float(p[1]), gain, exposure, temp(len(out)), brightness, True, -1))
        pose = nxt
        hold += 1
    return out


def vignetting(height: int, width: int, strength: float) -> np.ndarray:
    """Relative illumination in sensor coordinates: 1 at the centre, 1 - strength at the corners."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    r2 = ((x - (width - 1) / 2) / (width / 2)) ** 2 + ((y - (height - 1) / 2) / (height / 2)) ** 2
    return (1.0 - strength * r2 / 2.0).astype(np.float32)


def render(world: np.ndarray, fp: FramePlan, vignette: np.ndarray,
           shake: np.ndarray | tuple[float, float] = (0.0, 0.0)) -> tuple[np.ndarray, tuple[float, float]]:
    """The clean view (DN, float32) of a frame: bilinear sub-pixel crop of the world, times the
    brightness and the vignetting, clipped to 0..255; and its nominal top-left corner in world pixels.
    ``shake``: the view's displacement (dx, dy, px) from that corner by vibration, or (n, 2) displacements over
    the exposure (:func:`vibration_during_exposure`), whose views the sensor integrates (their mean), or
    (rows, n, 2) those of each row of a rolling shutter (rolling-shutter wobble)."""
    h, w = vignette.shape
    x = fp.x * (world.shape[1] - w - 1)
    y = fp.y * (world.shape[0] - h - 1)
    win = np.zeros((h, w), dtype=np.float32)
    shake = np.asarray(shake, dtype=np.float64)
    if shake.ndim == 3:  # (rows, n, 2): a rolling shutter's rows, each displaced along its own stretch of the path
        gx, gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
        for j in range(shake.shape[1]):
            d = shake[:, j, :].astype(np.float32)
            mx = np.clip(gx + np.float32(x) + d[:, :1], 0.0, world.shape[1] - 1.0)
            my = np.clip(gy + np.float32(y) + d[:, 1:], 0.0, world.shape[0] - 1.0)
            win += cv2.remap(world, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        win /= np.float32(shake.shape[1])
        return np.clip(win * vignette * np.float32(fp.brightness), 0.0, 255.0), (round(x, 4), round(y, 4))
    path = shake.reshape(-1, 2)
    for dx, dy in path:
        cx = min(max(x + dx, 0.0), world.shape[1] - w - 1.0) + (w - 1) / 2.0
        cy = min(max(y + dy, 0.0), world.shape[0] - h - 1.0) + (h - 1) / 2.0
        win += cv2.getRectSubPix(world, (w, h), (cx, cy))
    win /= np.float32(len(path))  # exact for one displacement
    return np.clip(win * vignette * np.float32(fp.brightness), 0.0, 255.0), (round(x, 4), round(y, 4))


def vibration(rng: np.random.Generator, frames: int, rms_px: float) -> np.ndarray:
    """(frames, 2) displacements (dx, dy, px) of a vibrating camera, independent from frame to frame (a
    vibration far faster than the frame rate), Gaussian with ``rms_px`` per axis."""
    return rng.normal(0.0, rms_px, (frames, 2)) if rms_px > 0 else np.zeros((frames, 2))


#: instants per vibration period at which :func:`vibration_during_exposure` samples a frame's exposure, and at most
#: per frame
SAMPLES_PER_PERIOD, MAX_EXPOSURE_SAMPLES = 16, 64


def vibration_during_exposure(rng: np.random.Generator, exposures_s: Sequence[float], rms_px: float,
                              hz: float, rows: int = 0, line_s: float = 0.0) -> list[np.ndarray]:
    """Per frame, (n, 2) displacements (dx, dy, px) of a camera vibrating at ``hz`` over the frame's exposure: a
    sinusoid per axis of ``rms_px`` rms, its phases random per frame and axis (the frame clock runs free of the
    vibration), sampled at n evenly spaced instants (``SAMPLES_PER_PERIOD`` per period, at least one). A short
    exposure freezes one displacement; one of about half a period or more smears the view along the path (motion
    blur that changes from frame to frame); over many periods every frame sees the same blur about the pose.
    ``rows`` > 0: a rolling shutter starts each row's exposure ``line_s`` after the previous one's, so each row
    sees the path that much later: per frame (rows, n, 2), row 0 the path above (rolling-shutter wobble)."""
    amplitude = math.sqrt(2.0) * rms_px
    delays = np.arange(max(rows, 1)) * line_s
    out = []
    for t_exp in exposures_s:
        n = int(min(MAX_EXPOSURE_SAMPLES, max(1, math.ceil(SAMPLES_PER_PERIOD * hz * t_exp))))
        phase = rng.uniform(0.0, 2.0 * math.pi, 2)
        t = (np.arange(n) + 0.5) / n * t_exp
        path = amplitude * np.sin(2.0 * math.pi * hz * (delays[:, None, None] + t[None, :, None]) + phase[None, None, :])
        out.append(path if rows else path[0])
    return out


def first_row(path: np.ndarray) -> np.ndarray:
    """(n, 2) a frame's displacements over its exposure: its first row's of a rolling shutter's (rows, n, 2)."""
    return path[0] if path.ndim == 3 else path


def wobble_px(path: np.ndarray) -> float:
    """The rms (px) over a frame's rows (rows, n, 2) of each row's mean displacement about the frame's: the
    distortion a rolling shutter reads into a vibrating view (0 for a whole-frame path)."""
    if path.ndim != 3:
        return 0.0
    rows = path.mean(axis=1)
    d = rows - rows.mean(axis=0)
    return math.sqrt(float(np.mean(np.sum(d * d, axis=1))))


def smear_px(path: np.ndarray) -> float:
    """The rms (px) of a frame's displacements over its exposure (n, 2) about their mean: its motion blur."""
    d = path - path.mean(axis=0)
    return math.sqrt(float(np.mean(np.sum(d * d, axis=1))))


@dataclass(frozen=True)
class MovingObject:
    """An object crossing the view (a person or a vehicle passing a parked camera), in view coordinates: its
    top-left corner at frame 0 and its velocity (px, px per frame; it wraps around the view), and its clean
    texture (DN; its shape)."""

    y0: float
    x0: float
    vy: float
    vx: float
    texture: np.ndarray


def moving_objects(rng: np.random.Generator, n: int, height: int, width: int) -> list[MovingObject]:
    """``n`` objects of 30-90 x 15-40 px with a smooth texture (2.5 px blur, 25 DN about a level of 30-220 DN),
    2-8 px per frame across the view and up to 2 down or up."""
    out = []
    for _ in range(n):
        tex = cv2.GaussianBlur(rng.standard_normal((90, 40)), (0, 0), 2.5)
        y0, x0 = rng.uniform(0, height * 200 / 256), rng.uniform(-width * 100 / 320, width * 300 / 320)
        vy, vx = rng.uniform(-2, 2), rng.choice([-1, 1]) * rng.uniform(2, 8)
        h, w = int(rng.integers(30, 90)), int(rng.integers(15, 40))
        level = rng.uniform(30, 220)
        out.append(MovingObject(y0, x0, vy, vx, (level + 25.0 * tex / tex.std())[:h, :w].astype(np.float32)))
    return out


def paint(clean: np.ndarray, objects: Sequence[MovingObject], index: int) -> tuple[np.ndarray, bool]:
    """The clean view with the objects at frame ``index`` painted over it (clipped to 0..255), and whether any
    object is in view."""
    out = clean.copy()
    h, w = out.shape
    seen = False
    for o in objects:
        th, tw = o.texture.shape
        y = int(o.y0 + o.vy * index) % (h + 60) - 30
        x = int(o.x0 + o.vx * index) % (w + 80) - 40
        ys, xs = slice(max(y, 0), min(y + th, h)), slice(max(x, 0), min(x + tw, w))
        if ys.start < ys.stop and xs.start < xs.stop:
            out[ys, xs] = np.clip(o.texture[ys.start - y:ys.stop - y, xs.start - x:xs.stop - x], 0, 255)
            seen = True
    return out, seen
