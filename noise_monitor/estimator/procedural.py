"""Procedural clean images with structure at the noise's own scale (no photograph involved).

Fine texture is where one image cannot tell scene from noise; these images teach the confidence head to
decline it and let it be measured on content no photo provides often enough: shaded fractal relief
(like a DEM hillshade), sine gratings of 1.5-6 px periods at random orientations, woven fabric, halftone
dots and small text rendered by matplotlib; grainy pictures (near-white grain as scene content); man-made
scenes (straight edges, bars); test charts (tiles over the whole intensity range). Every image is drawn from ``rng`` (seeded, reproducible).
"""
from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

SIZE = 256
#: Periods (px) of the gratings and fabrics (log-uniform).
PERIODS = (1.5, 6.0)


def _fractal(rng: np.random.Generator, size: int, beta: float) -> np.ndarray:
    """Gaussian field of power spectrum 1/f^beta, unit std."""
    f = np.hypot(np.fft.fftfreq(size)[:, None], np.fft.rfftfreq(size)[None, :])
    f[0, 0] = 1.0
    spec = (rng.standard_normal(f.shape) + 1j * rng.standard_normal(f.shape)) * f ** (-beta / 2)
    spec[0, 0] = 0.0
    field = np.fft.irfft2(spec, s=(size, size))
    return field / field.std()


def hillshade(rng: np.random.Generator, size: int = SIZE) -> np.ndarray:
    """Shaded relief of a fractal terrain (random roughness, sun azimuth and elevation)."""
    from matplotlib.colors import LightSource

    dem = _fractal(rng, size, rng.uniform(2.0, 3.4)) * rng.uniform(5.0, 60.0)
    ls = LightSource(azdeg=rng.uniform(0, 360), altdeg=rng.uniform(20, 70))
    return 255.0 * ls.hillshade(dem, vert_exag=rng.uniform(0.05, 1.0))


def _drawn(kind: Callable[[np.random.Generator, int], np.ndarray], rng: np.random.Generator, n: int,
           size: int) -> list[np.ndarray]:
    """``n`` images of one kind drawn in turn from ``rng`` (float32 DN, clipped to 0..255)."""
    return [np.clip(kind(rng, size), 0.0, 255.0).astype(np.float32) for _ in range(n)]


def _period(rng: np.random.Generator) -> float:
    return float(np.exp(rng.uniform(*np.log(PERIODS))))


def _wave(rng: np.random.Generator, size: int, period: float, angle: float) -> np.ndarray:
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float64)
    return np.sin(2 * np.pi * (np.cos(angle) * xx + np.sin(angle) * yy) / period + rng.uniform(0, 2 * np.pi))


def _smooth_mask(rng: np.random.Generator, size: int) -> np.ndarray:
    """A smooth 0..1 field (where a texture is present, fading out elsewhere)."""
    return np.clip(0.5 + _fractal(rng, size, 3.5) * 0.6, 0.0, 1.0)


def grating(rng: np.random.Generator, size: int = SIZE) -> np.ndarray:
    """One to three sine gratings at pixel-scale periods and random orientations over a smooth background."""
    img = 128.0 + 40.0 * _fractal(rng, size, 3.5)
    for _ in range(int(rng.integers(1, 4))):
        amp = float(np.exp(rng.uniform(np.log(2.0), np.log(60.0))))
        img += amp * _wave(rng, size, _period(rng), rng.uniform(0, np.pi)) * _smooth_mask(rng, size)
    return img


def plain_grating(rng: np.random.Generator, size: int = SIZE) -> np.ndarray:
    """One sine grating (two, a third of the time) of a pixel-scale period over the whole image, on a flat or gently
    ramped background: the unmasked periodic content a patch of a fence, a screen or a fabric close up holds, and
    which :func:`grating` shows only faded into a fractal background."""
    img = _ramp(rng, size, size, float(rng.uniform(20.0, 235.0)), float(rng.uniform(0.0, 40.0))).astype(np.float64)
    for _ in range(1 if rng.random() < 2 / 3 else 2):
        amp = float(np.exp(rng.uniform(np.log(2.0), np.log(60.0))))
        img += amp * _wave(rng, size, _period(rng), rng.uniform(0, np.pi))
    return img


def sine_grating(size: int, period: float, amp: float, angle: float, phase: float, level: float = 100.0) -> np.ndarray:
    """A square patch of one sine grating over its whole area (float64 DN): ``level`` + ``amp`` x the sine of
    period ``period`` px across the direction ``angle`` (rad), shifted by ``phase`` (rad)."""
    yy, xx = np.mgrid[0:size, 0:size]
    return level + amp * np.sin(2 * np.pi * (np.cos(angle) * xx + np.sin(angle) * yy) / period + phase)


def plain_grating_images(rng: np.random.Generator, n: int, size: int = SIZE) -> list[np.ndarray]:
    """``n`` plain gratings (:func:`plain_grating`; float32 DN, clipped to 0..255)."""
    return _drawn(plain_grating, rng, n, size)


def fabric(rng: np.random.Generator, size: int = SIZE) -> np.ndarray:
    """A woven pattern: crossed gratings multiplied, with a weave-scale modulation, under smooth shading."""
    angle, period = rng.uniform(0, np.pi), _period(rng)
    weave = _wave(rng, size, period, angle) * _wave(rng, size, period * rng.uniform(0.8, 1.25), angle + np.pi / 2)
    shade = 128.0 + 50.0 * _fractal(rng, size, 3.0)
    return shade + rng.uniform(5.0, 50.0) * weave


def halftone(rng: np.random.Generator, size: int = SIZE) -> np.ndarray:
    """Halftone dots (period 2.5-6 px) of a smooth picture: dot area follows the picture's gray level."""
    period = float(np.exp(rng.uniform(np.log(2.5), np.log(6.0))))
    tone = np.clip(0.5 + 0.3 * _fractal(rng, size, 3.0), 0.05, 0.95)
    screen = 0.5 + 0.25 * (_wave(rng, size, period, 0.0) + _wave(rng, size, period, np.pi / 2))
    dots = (screen < tone).astype(np.float32)
    return cv2.GaussianBlur(dots, (0, 0), rng.uniform(0.3, 0.8)) * rng.uniform(80, 230) + rng.uniform(0, 25)


def text(rng: np.random.Generator, size: int = SIZE) -> np.ndarray:
    """Lines of random small characters (5-9 px high) rendered by matplotlib (Agg)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(size / 100, size / 100), dpi=100)
    canvas = FigureCanvasAgg(fig)
    fig.patch.set_facecolor(str(rng.uniform(0.6, 1.0)))
    ink = str(rng.uniform(0.0, 0.4))
    letters = np.array(list("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789.,;:-"))
    fontsize = rng.uniform(4.0, 7.0)
    y = 0.98
    while y > 0:
        line = "".join(rng.choice(letters, 80))
        fig.text(0.0, y, line, fontsize=fontsize, color=ink, family="monospace", va="top")
        y -= fontsize * 1.3 / size * 100 / 72
    canvas.draw()
    return np.asarray(canvas.buffer_rgba(), dtype=np.float32)[..., :3].mean(axis=2)


#: Grain of ``grainy``: correlation length (px, Gaussian sigma) and amplitude (DN, std), both log-uniform.
GRAIN_SCALE = (0.4, 1.5)
GRAIN_DN = (0.5, 8.0)


def grainy(rng: np.random.Generator, size: int = SIZE) -> np.ndarray:
    """A smooth picture under grain (film grain, a scanned print, the source's own sensor noise): Gaussian
    white noise blurred to a 0.4-1.5 px correlation length, 0.5-8 DN, uniform or strongest in the mid-tones
    (half each). Scene content, not camera noise, close to white at the pixel scale: the tuning set ``grain``
    checks that the confidence head declines it (``train --grain`` adds it to a head's training imagery)."""
    base = 128.0 + rng.uniform(20.0, 70.0) * _fractal(rng, size, rng.uniform(2.5, 4.0))
    scale = float(np.exp(rng.uniform(*np.log(GRAIN_SCALE))))
    grain = np.asarray(cv2.GaussianBlur(rng.standard_normal((size, size)), (0, 0), scale), dtype=np.float64)
    grain = grain * float(np.exp(rng.uniform(*np.log(GRAIN_DN)))) / grain.std()
    if rng.random() < 0.5:
        t = np.clip(base / 255.0, 0.0, 1.0)
        grain = grain * (0.25 + 3.0 * t * (1.0 - t))
    return base + grain


def grain_images(rng: np.random.Generator, n: int, size: int = SIZE) -> list[np.ndarray]:
    """``n`` grainy pictures (:func:`grainy`; float32 DN, clipped to 0..255)."""
    return _drawn(grainy, rng, n, size)


KINDS: dict[str, Callable[[np.random.Generator, int], np.ndarray]] = {
    "hillshade": hillshade, "grating": grating, "fabric": fabric, "halftone": halftone, "text": text}


def procedural_images(rng: np.random.Generator, n: int, size: int = SIZE) -> list[np.ndarray]:
    """``n`` images (float32 DN, clipped to 0..255), the kinds of :data:`KINDS` in turn."""
    kinds = list(KINDS.values())
    return [np.clip(kinds[i % len(kinds)](rng, size), 0.0, 255.0).astype(np.float32) for i in range(n)]


# --- man-made scenes: straight edges at arbitrary angles ------------------------------------------
#: Supersampling factor of the man-made scenes (anti-aliasing by area downsampling).
SUPERSAMPLE = 4
#: Periods (px) of the periodic bars (stairs, fences, blinds; log-uniform).
BAR_PERIODS = (4.0, 30.0)
#: Contrast (DN) of a shape's edge or a bar against its neighbours (log-uniform).
EDGE_CONTRAST = (3.0, 150.0)


def _ramp(rng: np.random.Generator, h: int, w: int, level: float, slope_dn: float) -> np.ndarray:
    """A linear shading ramp over an h x w box: ``level`` at its centre, changing by up to ``slope_dn`` DN
    across the box in a random direction."""
    angle = rng.uniform(0, 2 * np.pi)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    u = (np.cos(angle) * (xx - w / 2) + np.sin(angle) * (yy - h / 2)) / max(h, w, 1)
    return level + float(rng.uniform(-slope_dn, slope_dn)) * u


def _finish(rng: np.random.Generator, hi_res: np.ndarray) -> np.ndarray:
    """Area-downsample a supersampled scene (anti-aliased edges) and blur it slightly half the time."""
    size = hi_res.shape[0] // SUPERSAMPLE
    img = cv2.resize(hi_res, (size, size), interpolation=cv2.INTER_AREA)
    if rng.random() < 0.5:
        img = cv2.GaussianBlur(img, (0, 0), float(rng.uniform(0.3, 0.8)))
    return img


def _random_polygon(rng: np.random.Generator, centre: np.ndarray, radius: float) -> np.ndarray:
    """Vertices (K, 2) of a rotated rectangle, a thin stripe or a convex polygon of about ``radius``."""
    kind = rng.choice(3, p=(0.45, 0.2, 0.35))
    angle = rng.uniform(0, np.pi)
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    if kind == 0:  # rectangle of random aspect
        half = radius * np.array([1.0, float(np.exp(rng.uniform(np.log(0.2), 0.0)))])
        corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half
    elif kind == 1:  # stripe: long and thin (a pole, a rail, a window frame)
        half = np.array([radius * rng.uniform(1.5, 4.0), float(rng.uniform(0.75, 4.0)) * SUPERSAMPLE])
        corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half
    else:  # convex polygon: sorted random angles on an ellipse
        k = int(rng.integers(3, 9))
        t = np.sort(rng.uniform(0, 2 * np.pi, k))
        corners = np.stack([np.cos(t), rng.uniform(0.4, 1.0) * np.sin(t)], axis=1) * radius
    return centre + corners @ rot.T


def polygon_leaves(rng: np.random.Generator, size: int = SIZE, leaves: int | None = None) -> np.ndarray:
    """Dead leaves of polygons: occluding rotated rectangles, stripes and convex polygons at arbitrary
    angles (log-uniform sizes, drawn in random order), each filled with a smooth shading ramp; anti-aliased by 4x supersampling,
    slightly blurred half the time. Man-made content (walls, windows, furniture, stairs seen from afar):
    large flat areas separated by straight edges, which disks do not have. ``leaves``: shapes drawn
    (default 120 per 256 x 256 px)."""
    leaves = leaves if leaves is not None else max(int(round(120 * (size / SIZE) ** 2)), 1)
    s = size * SUPERSAMPLE
    img = _ramp(rng, s, s, float(rng.uniform(0, 255)), float(rng.uniform(0, 80)))
    radii = np.exp(rng.uniform(np.log(1.5 * SUPERSAMPLE), np.log(s / 3.0), leaves))
    for radius in radii:
        poly = _random_polygon(rng, rng.uniform(0, s, 2), float(radius))
        x0, y0 = np.maximum(np.floor(poly.min(axis=0)).astype(int), 0)
        x1, y1 = np.minimum(np.ceil(poly.max(axis=0)).astype(int) + 1, s)
        if x1 <= x0 or y1 <= y0:
            continue
        mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
        cv2.fillPoly(mask, [np.round(poly - [x0, y0]).astype(np.int32)], 1)
        shade = _ramp(rng, y1 - y0, x1 - x0, float(rng.uniform(0, 255)), float(rng.uniform(0, 60)))
        box = img[y0:y1, x0:x1]
        box[mask > 0] = shade[mask > 0]
    return _finish(rng, img)


def bars(rng: np.random.Generator, size: int = SIZE) -> np.ndarray:
    """Periodic bars (stairs, fences, blinds) of 4-30 px periods at arbitrary angles over a shaded
    background: one to three groups, each a rotated window of bars with a random duty cycle, alternating
    lit / shaded faces (stairs: tread and riser) and a shading ramp along the bars; anti-aliased by 4x
    supersampling, slightly blurred half the time."""
    s = size * SUPERSAMPLE
    img = _ramp(rng, s, s, float(rng.uniform(0, 255)), float(rng.uniform(0, 100)))
    yy, xx = np.mgrid[0:s, 0:s].astype(np.float32)
    for _ in range(int(rng.integers(1, 4))):
        period = float(np.exp(rng.uniform(*np.log(BAR_PERIODS)))) * SUPERSAMPLE
        angle = rng.uniform(0, np.pi)
        u = np.cos(angle) * xx + np.sin(angle) * yy
        v = -np.sin(angle) * xx + np.cos(angle) * yy
        phase = np.mod(u / period + rng.uniform(0, 1), 1.0)
        duty = rng.uniform(0.2, 0.8)
        base = float(rng.uniform(0, 255))
        contrast = float(np.exp(rng.uniform(*np.log(EDGE_CONTRAST)))) * rng.choice([-1.0, 1.0])
        along = float(rng.uniform(-40, 40)) * v / s  # shading along the bars
        across = float(rng.uniform(-0.3, 0.3)) * contrast * phase  # a ramp over each face (lit stair treads)
        group = np.where(phase < duty, base + contrast, base) + along + across
        # the group's window: a rotated rectangle of 30-120 % of the image's side
        cx, cy = rng.uniform(0.2 * s, 0.8 * s, 2)
        half = rng.uniform(0.15 * s, 0.6 * s, 2)
        wa = rng.uniform(0, np.pi)
        wu = np.abs(np.cos(wa) * (xx - cx) + np.sin(wa) * (yy - cy))
        wv = np.abs(-np.sin(wa) * (xx - cx) + np.cos(wa) * (yy - cy))
        inside = (wu < half[0]) & (wv < half[1])
        img[inside] = group[inside]
    return _finish(rng, img)


MANMADE_KINDS: dict[str, Callable[[np.random.Generator, int], np.ndarray]] = {
    "polygons": polygon_leaves, "bars": bars}


def manmade_images(rng: np.random.Generator, n: int, size: int = SIZE) -> list[np.ndarray]:
    """``n`` man-made procedural scenes (float32 DN, clipped to 0..255), the kinds of :data:`MANMADE_KINDS`
    in turn: straight anti-aliased edges at arbitrary angles, flat shaded faces, periodic bars."""
    kinds = list(MANMADE_KINDS.values())
    return [np.clip(kinds[i % len(kinds)](rng, size), 0.0, 255.0).astype(np.float32) for i in range(n)]


# --- test charts: tiles over the whole intensity range -------------------------------------------
#: Tile sides (px) of the test charts (log-uniform).
CHART_TILES = (10.0, 48.0)
#: Tile contents of the test charts and their probabilities.
CHART_KINDS = {"flat": 0.4, "ramp": 0.25, "texture": 0.2, "steps": 0.15}


def _chart_tile(rng: np.random.Generator, kind: str, side: int, level: float) -> np.ndarray:
    """One tile at ``level`` (DN): flat, a linear ramp, a smooth texture or a step wedge of 2-4 steps."""
    if kind == "ramp":
        return _ramp(rng, side, side, level, float(rng.uniform(10.0, 120.0)))
    if kind == "texture":
        tex = cv2.GaussianBlur(rng.standard_normal((side, side)).astype(np.float32), (0, 0), float(rng.uniform(1.0, 6.0)))
        return level + float(rng.uniform(5.0, 40.0)) * tex / max(float(np.abs(tex).max()), 1e-6)
    tile = np.full((side, side), level, np.float32)
    if kind == "steps":
        k = int(rng.integers(2, 5))
        steps = level + np.linspace(-1.0, 1.0, k) * float(rng.uniform(10.0, 60.0))
        idx = np.minimum(np.arange(side) * k // side, k - 1)
        tile = np.broadcast_to(steps[idx][None, :] if rng.random() < 0.5 else steps[idx][:, None], (side, side))
    return tile.astype(np.float32)


def chart_scene(rng: np.random.Generator, size: int = SIZE) -> np.ndarray:
    """A test chart: a grid of square tiles (10-48 px, 0-3 px borders of a background level) whose levels
    are a step wedge over the whole 0..255 range in random order, the clipped ends included; each tile flat,
    a ramp, a smooth texture or a step wedge (``CHART_KINDS``); slightly blurred half the time. Every level
    sits next to every other within a patch, which photographs rarely show (camera characterisation
    charts, lab scenes)."""
    side = int(np.exp(rng.uniform(*np.log(CHART_TILES))))
    pitch = side + int(rng.integers(0, 4))
    n = -(-size // pitch) + 1
    img = np.full((n * pitch, n * pitch), float(rng.uniform(0.0, 255.0)), np.float32)
    levels = rng.permutation(np.linspace(rng.uniform(0.0, 10.0), rng.uniform(245.0, 255.0), n * n))
    kinds = rng.choice(list(CHART_KINDS), n * n, p=list(CHART_KINDS.values()))
    for k in range(n * n):
        r, c = divmod(k, n)
        img[r * pitch:r * pitch + side, c * pitch:c * pitch + side] = _chart_tile(rng, kinds[k], side, float(levels[k]))
    y0, x0 = rng.integers(0, pitch, 2)
    chart = img[y0:y0 + size, x0:x0 + size]
    return cv2.GaussianBlur(chart, (0, 0), float(rng.uniform(0.3, 0.8))) if rng.random() < 0.5 else chart


def chart_images(rng: np.random.Generator, n: int, size: int = SIZE) -> list[np.ndarray]:
    """``n`` test charts (:func:`chart_scene`; float32 DN, clipped to 0..255)."""
    return _drawn(chart_scene, rng, n, size)
