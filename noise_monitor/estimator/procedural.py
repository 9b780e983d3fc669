"""Procedural clean images with structure at the noise's own scale (no photograph involved).

Fine texture is where one image cannot tell scene from noise; these images teach the confidence head to
decline it and let it be measured on content no photo provides often enough: shaded fractal relief
(like a DEM hillshade), sine gratings of 1.5-6 px periods at random orientations, woven fabric, halftone
dots and small text rendered by matplotlib. Every image is drawn from ``rng`` (seeded, reproducible).
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


KINDS: dict[str, Callable[[np.random.Generator, int], np.ndarray]] = {
    "hillshade": hillshade, "grating": grating, "fabric": fabric, "halftone": halftone, "text": text}


def procedural_images(rng: np.random.Generator, n: int, size: int = SIZE) -> list[np.ndarray]:
    """``n`` images (float32 DN, clipped to 0..255), the kinds of :data:`KINDS` in turn."""
    kinds = list(KINDS.values())
    return [np.clip(kinds[i % len(kinds)](rng, size), 0.0, 255.0).astype(np.float32) for i in range(n)]
