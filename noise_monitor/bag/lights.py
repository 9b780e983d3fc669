"""Light that changes in time, as a simulated camera sees it.

Lamps on an AC supply oscillate at twice the mains frequency, by a modulation depth from a few percent (an
incandescent bulb's thermal inertia) to near 100 % (cheap LED drivers). A rolling shutter starts each row's
exposure one line time after the previous row's, so each row averages the light over a different interval:
horizontal bands whose depth falls with the exposure (zero at whole light periods) and which roll through the
image from frame to frame when the frame clock is not locked to the mains.
"""
from __future__ import annotations

import numpy as np

#: a lamp's light oscillates at this many times the mains frequency
LIGHT_PER_MAINS = 2.0


def banding_depth(depth: float, exposure_s: float, mains_hz: float) -> float:
    """The bands' depth once a row's exposure of ``exposure_s`` averages a light modulated by ``depth`` at twice
    ``mains_hz``: depth x sinc(f T) (signed; 0 at whole light periods)."""
    return float(depth * np.sinc(LIGHT_PER_MAINS * mains_hz * exposure_s))


def rolling_shutter_gain(height: int, exposure_s: float, phase: float, depth: float, mains_hz: float,
                         line_s: float) -> np.ndarray:
    """(height,) relative brightness of each row of one frame: the light 1 + depth sin(2 pi f t + phase)
    (f = 2 x ``mains_hz``; ``phase`` the light's at the first row's exposure start) averaged over each row's
    exposure, which starts ``line_s`` after the previous row's: 1 + depth sinc(f T) sin(2 pi f (t_row + T / 2)
    + phase)."""
    f = LIGHT_PER_MAINS * mains_hz
    mid = np.arange(height) * line_s + 0.5 * exposure_s
    return 1.0 + banding_depth(depth, exposure_s, mains_hz) * np.sin(2.0 * np.pi * f * mid + phase)


def _pwm_on_time(t: np.ndarray, period: float, duty: float) -> np.ndarray:
    """Time the PWM light has been on from 0 to ``t`` (on for the first ``duty`` of every ``period``)."""
    n = np.floor(t / period)
    return n * duty * period + np.minimum(t - n * period, duty * period)


def pwm_gain(height: int, exposure_s: float, phase: float, depth: float, hz: float, duty: float,
             line_s: float) -> np.ndarray:
    """(height,) relative brightness of each row of one frame under an LED dimmed by pulse-width modulation: full
    for ``duty`` of each period of 1 / ``hz``, ``1 - depth`` of that otherwise (``phase``: where in the period the
    first row's exposure starts), averaged over each row's exposure (which starts ``line_s`` after the previous
    row's) and divided by the light's mean: trapezoidal bands, with sharp edges at exposures short of a period."""
    period = 1.0 / hz
    start = np.arange(height) * line_s + phase / (2.0 * np.pi) * period
    on = (_pwm_on_time(start + exposure_s, period, duty) - _pwm_on_time(start, period, duty)) / exposure_s
    return ((1.0 - depth) + depth * on) / ((1.0 - depth) + depth * duty)


def pwm_depth(depth: float, exposure_s: float, hz: float, duty: float) -> float:
    """Half the peak-to-peak of :func:`pwm_gain` over the rows: the bands' depth."""
    g = pwm_gain(1000, exposure_s, 0.0, depth, hz, duty, 1.0 / (hz * 1000))  # one period over 1,000 rows
    return float(g.max() - g.min()) / 2.0
