"""Model-independent noise measurement from a frame sequence, separating the scene from the noise.

Frames are grouped into *segments*, static holds: consecutive frames with no global shift (phase
correlation, :mod:`noise_monitor.measure.temporal`) and metadata that agree within a tolerance; frames
outside holds (pans, metadata changes) have no temporal reference and are counted as skipped. Every
frame is cut into B x B blocks and a plane is fitted to each block; the residual ``r`` is split into
three orthogonal parts:

- the column-constant part (dimension B - 2 after the fit): column offsets,
- the row-constant part (B - 2): row offsets,
- the rest ((B - 1)^2 dimensions): pixel-wise (white) noise.

White noise of variance s2 puts ``d * s2`` into a part of dimension d; per-column (per-row) offsets of
variance c2 put ``B (B - 2) c2`` into the column (row) part. Solving these relations per block gives
unbiased per-pixel variances. Within a hold the spread of the residuals over frames gives the temporal
noise, once the light's change from frame to frame (a flicker, a rolling shutter's bands) and the camera's
vibration are taken out, in blocks whose frame differences fit pure noise (no residual motion, no light changing
in part of the view). Blocks are chosen flat and unclipped on the hold mean and in every frame's light. The fixed-pattern, column and row components are cross
energies of a block's hold-mean residual with the same sensor block seen from other camera poses
(:func:`_cross_views`): the scene moves, the fixed pattern does not; with one pose only they are the
hold mean's own residual (temporal / K removed) and ``Measurements.not_measured`` says so; where that residual's
neighbouring pixels are correlated (a sensor's fixed pattern is white, the optics' image of a scene is not) the
view shows the scene, and those components' errors take the scene's variance. Outlier pixels count when another
view confirms them; in a single view, unless their neighbours share their offset (the scene's specks). Every cell
(segment x intensity bin) carries the standard error of its mean over blocks, from its blocks' spread but at least
its segment's pooled within-cell spread (a few blocks' own spread can come out far too small). The fixed pattern's *shape* (:class:`.shape.FixedShape`): its
kurtosis from four views of each sensor pixel at four camera poses (a Gaussian pattern such as PRNU has
3; a few pixels far off, such as random telegraph pixels below the outlier threshold, far more).
The temporal deviations are split like the residual: white temporal noise (``temporal``) and row/column
offsets that change from frame to frame (``temporal_row``, ``temporal_column``); single-view column/row
components have ``temporal_row / K`` (``temporal_column / K``) removed, cross-view ones need not (the
temporal parts of two holds are independent). Blinking pixels are counted per hold (``temporal_spikes``).
"""
from __future__ import annotations

import bisect
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np
from scipy import ndimage
from scipy.special import ndtri
from scipy.stats import chi2 as chi2_dist
from scipy.stats import t as t_dist

from ..measure.temporal import (
    HOLD_SHIFT_PX,
    LightChange,
    block_temporal,
    camera_shift,
    energy_and_lag,
    light_and_motion,
    motion_rms,
    steady_run,
)
from ..monitor.config import MonitorConfig
from ..monitor.frame import Frame, skip_reason
from ..physics import CameraMetadata
from . import hold_change
from .hold_change import NoiseChange
from .shape import FixedShape, fixed_shape, fourth_moments

BLOCK = 8
BIN_WIDTH_DN = 16.0
INTENSITY_RANGE_DN = (8.0, 240.0)
# Per-pixel variance components measured per block: temporal, fixed (white fixed-pattern core), column
# and row (line offsets), outlier (outlier pixels); "single" (temporal + fixed) replaces the first two
# in single-frame segments.
#: a block is textured if its residual is correlated along both axes beyond this lag-1 correlation
TEXTURE_CORRELATION = 0.3
#: ... or if its robust sigma (temporal spread) exceeds this multiple of its bin's median
OUTLIER_BLOCK_FACTOR = 3.0
#: a pixel of the segment's mean residual beyond this many robust sigmas is an outlier pixel
OUTLIER_PIXEL_SIGMAS = 6.0
MIN_BLOCKS_PER_CELL = 6
#: a block is near clipping if its mean is within this many noise sigmas of 0 or 255
CLIP_SIGMAS = 3.0
#: largest |residuals| of a block left out of its robust sigma (room for a few hot pixels)
TRIM_PIXELS = 4
#: smallest per-block standard deviation of a variance estimate (DN^2): 8-bit rounding noise scale
MIN_VAR_ERR_DN2 = 0.01
#: skip reason of frames outside static holds when the sequence has static holds
NOT_HELD = "not in a static hold (camera moving, or metadata changed at this frame)"
#: skip reason of a hold's first or last frame alone on its side of a noise change inside the hold
LONE = "alone on its side of a noise change at its hold's edge (one frame has no temporal noise of its own)"
#: smallest camera displacement (px) between two holds for a cross-view fixed-pattern measurement
MIN_PARTNER_SHIFT_PX = 16.0
#: most partner views per hold
MAX_PARTNERS = 8
#: components that are cross energies between views when a segment has partners (zero-mean noise either way)
CROSS_VIEW = ("fixed", "column", "row")
#: the partner views show the scene when one of a cell's mean cross energies lies below 0 (a fixed pattern's
#: is a_s * a_p >= 0 in every view) with a one-sided p-value (Student t over its blocks) below this, beyond
#: chance over the recording's ~10^3 cells x views: the scene repeats under the views' shifts (a periodic
#: texture), and every cell's errors of that component take the views' spread (Birge ratio)
PARTNER_NEGATIVE_P = 1e-6
#: a block whose own white variance exceeds this multiple of its neighbours' shows the scene's texture (a fixed
#: pattern's realization over a block's 49 degrees of freedom does that with p ~ 1e-5): the cross-view exclusion
#: takes its own there, its neighbours' elsewhere (:func:`_texture_white`)
TEXTURED_WHITE = 2.0
#: largest standard error of a block's cross-view fixed variance, relative to its temporal variance
CROSS_SE_MAX = 0.5
#: an outlier pixel is confirmed when a partner view shows it beyond this many robust sigmas, same sign
CONFIRM_SIGMAS = 3.0
#: ... in this many partner views (fewer when the block has fewer valid partners)
CONFIRM_VIEWS = 2
#: ... whose block has at most this many other pixels beyond CONFIRM_SIGMAS (white noise: 4 or more in
#: < 0.1 % of 8 x 8 blocks; 2 % random telegraph pixels: in 4 %; a speckled scene texture has many and
#: would confirm a speck by chance)
CONFIRM_MAX_OTHERS = 3
#: a pixel whose own temporal variance exceeds this multiple of its block's typical one is a temporal
#: spike (a blinking / random telegraph pixel); counted against the chi-square expectation
SPIKE_FACTOR = 5.0
#: blinking pixels of a block that touch one another (4-neighbours) in a group this large are a scene change
#: (an object's edge passing through the hold), not blinking pixels, which sit apart: white noise and 2 %
#: telegraph pixels make such a group in ~0.3 % of blocks at 2 frames, fewer at more (left out of the
#: pure-noise test as blinking, the edge's pixels would pass into the temporal variance)
MIN_CHANGE_CLUSTER = 4
#: a single view shows the scene in its fixed pattern when its blocks' mean lag-1 excess (:func:`_lag1_excess`: the
#: neighbour covariance of the de-lined hold-mean residual beyond white noise's; a fixed pattern such as PRNU, DSNU
#: or hot pixels is white on the sensor, the optics' image of a scene is not) lies this many standard errors from 0
#: (above: a scene the optics blurred; below: a grating at 2-3 px)
SCENE_SIGMAS = 4.0
#: the lag-1 excess per DN^2 of scene variance in a flat block: 0.44-0.61 measured on the campaigns' photographs
#: and the lab chart (clean cameras, where the single view's fixed part is all scene); the lower end taken, so the
#: scene's variance (excess / this) errs high; a texture finer than the optics' blur (white at pixel scale) escapes,
#: and one of scikit-learn's photographs (an evaluation, not tuned on) gave 0.27: a third of its variance escapes
SCENE_LAG1_PER_DN2 = 0.4
#: a single view's outlier pixels are the scene's specks when their 4-neighbours carry more than this share of their
#: offset (mean over the view's outlier pixels, SCENE_SIGMAS standard errors above it, the errors a defect's noisy
#: neighbours give): a defect is one sensor pixel, the optics spread a speck over its neighbours (0.14-0.33 on the
#: campaigns' photographs, -0.02-0 for hot pixels)
NEIGHBOUR_SHARE = 0.05
#: draws of the Monte-Carlo behind :func:`spike_fraction` (seeded)
SPIKE_DRAWS = 20000
_NO_DYNAMIC = {"gain_db": 0.0, "exposure_time_s": 1.0, "sensor_temperature_c": 0.0}


@dataclass(frozen=True)
class SegmentTolerance:
    """How far metadata may drift inside one segment (from its first frame). The segment's model is
    evaluated at the frames' mean metadata (:func:`_mean_meta`): over 3 degC the dark current's
    exponential law makes the mean of its variance differ from its value at the mean temperature by
    < 0.5 %, while a hold cut every degree loses frames and their statistics (short high-gain holds
    dominate the measurement's scatter). A driver's auto-exposure moves the gain and exposure a little every
    frame: the frames stay one scene through another gain (the light change taken out before the differences),
    and over +-0.5 dB and +-12 % (the live monitor's drift window: 1 dB, a ratio of 1.25) the mean of their noise
    variance is the model's at the mean metadata within 0.3 %."""

    gain_db: float = 0.5
    exposure_rel: float = 0.12
    temperature_c: float = 3.0
    max_frames: int = 64

    def same(self, a: CameraMetadata, b: CameraMetadata) -> bool:
        return (
            a.replace(**_NO_DYNAMIC) == b.replace(**_NO_DYNAMIC)
            and abs(a.gain_db - b.gain_db) <= self.gain_db
            and abs(a.exposure_time_s - b.exposure_time_s) <= self.exposure_rel * a.exposure_time_s
            and abs(a.sensor_temperature_c - b.sensor_temperature_c) <= self.temperature_c
        )


def _mean_meta(metas: list[CameraMetadata]) -> CameraMetadata:
    """A segment's representative metadata: its middle frame's, with the gain, exposure and temperature
    averaged over its frames (the metadata drift inside a segment, e.g. a temperature changing every
    frame; the middle frame of an even count sits half a frame off the mean)."""
    return metas[len(metas) // 2].replace(**{f: float(np.mean([getattr(m, f) for m in metas]))
                                              for f in _NO_DYNAMIC})


@dataclass
class SegmentMeasurement:
    """Per-block measurements of one segment (accepted blocks only)."""

    index: int
    meta: CameraMetadata
    stamp_ns: int
    frames: list[int]
    intensity_dn: np.ndarray  # (B,) block mean intensity
    region: np.ndarray  # (B,) region index 0..8 (3 x 3 grid, row-major)
    position: np.ndarray  # (B, 2) block centre (y, x) on the sensor, normalised to 0..1
    values: dict[str, np.ndarray]  # component -> (B,) variance DN^2 per block
    robust_sigma_dn: np.ndarray  # (B,) robust sigma of the mean residual (outlier threshold basis)
    span_dn: np.ndarray  # (B,) range of the fitted plane over the block (DN)
    outlier_pixels: int
    outlier_amplitude_dn: float  # mean |residual| of the outlier pixels
    outlier_amplitude_err_dn: float
    pixels_checked: int
    blocks_total: int
    excluded: dict[str, int]
    #: segments whose hold-mean residuals the fixed/column/row components are cross energies with
    #: (empty: a single-view estimate, the hold mean's residual minus temporal / k)
    partners: tuple[int, ...] = ()
    partner_weight: np.ndarray | None = None  # (B, P) weight of each partner per block (0: not used)
    partner_intensity_dn: np.ndarray | None = None  # (B, P) the block's intensity in each partner view
    partner_sigma_dn: np.ndarray | None = None  # (B, P) the block's robust sigma in each partner view
    #: (B, P) whether the block in each partner view can confirm an outlier pixel (CONFIRM_MAX_OTHERS)
    partner_confirms: np.ndarray | None = None
    #: component -> (B, P) the block's cross energy with each partner view (fixed, column, row; used where
    #: ``partner_weight`` > 0)
    partner_values: dict[str, np.ndarray] | None = None
    #: pixels of the accepted blocks whose temporal variance is a SPIKE_FACTOR outlier, and the number
    #: white temporal noise would give
    temporal_spikes: int = 0
    temporal_spikes_expected: float = 0.0
    #: (B,) per block, the fixed pattern's fourth moment and the product of two of its second moments from
    #: four views at distinct poses (:func:`.shape.fourth_moments`; 0 where the block has no three partners)
    fixed_fourth: np.ndarray | None = None
    fixed_square: np.ndarray | None = None
    #: what was taken out of the hold's frames before its temporal noise: the light's change from frame to frame
    #: (:meth:`..measure.temporal.LightChange.percent`, %) and the camera's vibration (rms displacement, px)
    light_pct: float = 0.0
    motion_px: float = 0.0
    last_stamp_ns: int = 0  # the stamp of its last frame
    #: (B,) where a single view shows the scene (``SCENE_SIGMAS``), per block the scene's variance in its fixed
    #: pattern (lag-1 excess / ``SCENE_LAG1_PER_DN2``, DN^2; None: measured across views, or no scene shown)
    scene_dn2: np.ndarray | None = None
    #: False where a single view's outlier pixels show the scene (:func:`_specks_of_the_scene`): their count,
    #: amplitude and energy are not a measurement of the sensor's outlier pixels
    outliers_measured: bool = True
    #: the sample variance (ddof 1) of the hold's frames' sensor temperatures (degC^2): a fixed pattern that follows
    #: the temperature (a DSNU) changes by that much from frame to frame and shows in the temporal noise
    temperature_var_c2: float = 0.0

    @property
    def n_frames(self) -> int:
        return len(self.frames)

    @property
    def components(self) -> tuple[str, ...]:
        return tuple(self.values)


@dataclass
class Cell:
    """One (segment, intensity bin) cell: mean variance per component and its standard error."""

    segment: int
    bin_index: int
    intensity_dn: float
    block_index: np.ndarray  # indices into the segment's block arrays
    values: dict[str, float]
    errors: dict[str, float]
    #: cross-view component -> (its partner views' lowest p-value of a mean below 0, their Birge ratio):
    #: :func:`partner_views`
    partner_views: dict[str, tuple[float, float]] = field(default_factory=dict)


@dataclass
class Measurements:
    """Everything measured from a frame sequence, independent of any model."""

    segments: list[SegmentMeasurement]
    cells: list[Cell]
    quant_step_dn: float
    quant_step_err_dn: float
    output_step_dn: float
    histogram: np.ndarray
    histogram_bin_dn: float
    frames_total: int
    frames_used: int
    skipped: dict[str, int] = field(default_factory=dict)
    shape: tuple[int, int] = (0, 0)
    #: what could not be measured and why (component -> reason); never a silent zero
    not_measured: dict[str, str] = field(default_factory=dict)
    #: the fixed pattern's kurtosis (None: no segment with three partner views at distinct poses)
    fixed_shape: FixedShape | None = None
    #: cross-view components whose errors took the partner views' spread (the scene showed in their views)
    scene_in_views: list[str] = field(default_factory=list)

    #: the changes of the noise inside holds, in time order (each cut its hold in two; a lone frame on one side of it
    #: is not measured)
    noise_changes: list[NoiseChange] = field(default_factory=list)

    def after_changes(self) -> set[int]:
        """Positions in ``segments`` of the segments a noise change came just before (in their hold, or at the end of
        the hold before them where the change left one frame there)."""
        firsts = [s.frames[0] for s in self.segments]
        return {j for j in (bisect.bisect_left(firsts, c.frame) for c in self.noise_changes) if 0 < j < len(firsts)}

    def field_conditions(self) -> dict[str, Any]:
        """What the holds' temporal measurement took out: how many holds (of those measured from frame differences)
        saw the light change from frame to frame or the camera vibrate, and the largest of each. A hold of 2-3
        frames that moved has no static block (too few frames to tell its light from its motion) and is not counted."""
        holds = [s for s in self.segments if s.n_frames >= 2 and s.intensity_dn.size]
        lit, shaken = [s.light_pct for s in holds if s.light_pct > 0], [s.motion_px for s in holds if s.motion_px > 0]
        return {"holds": len(holds), "light_changing": len(lit), "light_pct_max": round(max(lit, default=0.0), 3),
                "vibrating": len(shaken), "motion_px_max": round(max(shaken, default=0.0), 3)}

    def scene_in_single_views(self) -> dict[str, Any]:
        """The holds and single frames measured from one view (no partner view) and how many of them show the scene: in their fixed
        pattern (``fixed_pattern``: errors widened by the scene's variance, the largest hold mean ``scene_dn2_max``)
        and in their outlier pixels (``outlier_pixels``: not counted)."""
        single = [s for s in self.segments if not s.partners and s.intensity_dn.size]
        fixed = [abs(float(np.mean(s.scene_dn2))) for s in single if s.scene_dn2 is not None]
        return {"views": len(single), "fixed_pattern": len(fixed), "scene_dn2_max": round(max(fixed, default=0.0), 3),
                "outlier_pixels": sum(not s.outliers_measured for s in single)}

    def summary(self) -> dict[str, Any]:
        shape = (self.fixed_shape.summary() if self.fixed_shape else
                 {"not_measured": "no hold seen from three other, mutually distinct camera poses"})
        return {
            "fixed_pattern_shape": shape,
            "frames_total": self.frames_total,
            "frames_used": self.frames_used,
            "frames_skipped": dict(self.skipped),
            "not_measured": dict(self.not_measured),
            "scene_in_partner_views": list(self.scene_in_views),
            "scene_in_single_views": self.scene_in_single_views(),
            "field_conditions": self.field_conditions(),
            "noise_changes": [c.summary(self.segments[0].stamp_ns) for c in self.noise_changes],
            "segments": len(self.segments),
            "cells": len(self.cells),
            "image_shape": list(self.shape),
            "quantization_step_dn": round(self.quant_step_dn, 4),
            "quantization_step_err_dn": round(self.quant_step_err_dn, 4),
            "outlier_pixel_fraction": (
                sum(s.outlier_pixels for s in self.segments) / max(1, sum(s.pixels_checked for s in self.segments))
            ),
        }


# --- block algebra -----------------------------------------------------------------------------
def _plane_fit(b: int) -> tuple[np.ndarray, np.ndarray]:
    """(residual projector, slope extractor (b*b, 2)) of a least-squares plane fit on a b x b block."""
    y, x = np.mgrid[0:b, 0:b]
    design = np.stack([np.ones(b * b), x.ravel() - x.mean(), y.ravel() - y.mean()], axis=1)
    pinv = np.linalg.pinv(design)
    return np.eye(b * b) - design @ pinv, pinv[1:].T


def _blocks(img: np.ndarray, b: int) -> np.ndarray:
    h, w = (img.shape[0] // b) * b, (img.shape[1] // b) * b
    return img[:h, :w].reshape(h // b, b, w // b, b).transpose(0, 2, 1, 3).reshape(-1, b * b)


def _energies(r: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(total, column-part, row-part) energies of block residuals r (N, b*b)."""
    r3 = r.reshape(-1, b, b)
    col = b * np.sum(r3.mean(axis=1) ** 2, axis=1)
    row = b * np.sum(r3.mean(axis=2) ** 2, axis=1)
    return np.sum(r * r, axis=1), col, row


def _split(total: np.ndarray, col: np.ndarray, row: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-pixel variances (white, column offsets, row offsets) from block energies."""
    white = (total - col - row) / (b - 1) ** 2
    line = b * (b - 2)
    return white, (col - (b - 2) * white) / line, (row - (b - 2) * white) / line


def _lag1(r: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray]:
    r3 = r.reshape(-1, b, b)
    e = np.maximum(np.sum(r * r, axis=1), 1e-12)
    return np.sum(r3[:, :, 1:] * r3[:, :, :-1], axis=(1, 2)) / e, np.sum(r3[:, 1:, :] * r3[:, :-1, :], axis=(1, 2)) / e


@lru_cache(maxsize=8)
def _white_lag1(b: int) -> float:
    """White noise's expected ratio of :func:`..measure.temporal.energy_and_lag`'s neighbour sum to its energy on
    plane-fit residuals of b x b blocks (exact, from the projector: -0.25 at 8 x 8)."""
    n = b * b
    col = np.kron(np.ones((b, b)) / b, np.eye(b))  # pixel (i, j) -> mean of column j
    row = np.kron(np.eye(b), np.ones((b, b)) / b)  # pixel (i, j) -> mean of row i
    proj = (np.eye(n) - col) @ (np.eye(n) - row) @ _plane_fit(b)[0]
    step = np.eye(b, k=1)
    pairs = 0.5 * (np.kron(np.eye(b), step) + np.kron(step, np.eye(b)))  # each neighbour pair once in x^T (P + P^T) x
    return float(np.trace(proj.T @ (pairs + pairs.T) @ proj) / np.trace(proj.T @ proj))


def _lag1_excess(r: np.ndarray, b: int) -> np.ndarray:
    """(N,) per block, the mean product of neighbouring pixels of plane-fit residuals ``r`` (N, b*b) with the
    column and row means taken out, beyond what white noise of the same energy gives (DN^2, 0 in expectation for
    any white pattern, temporal or fixed; positive for a spatially correlated scene)."""
    energy, lag = energy_and_lag(r[None], b)
    return (lag - _white_lag1(b) * energy[0]) / (2 * b * (b - 1))


def _delined(r: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray]:
    """(residual minus its column and row medians, that line model) per block (N, b*b)."""
    r3 = r.reshape(-1, b, b)
    col = np.median(r3, axis=1, keepdims=True)
    row = np.median(r3 - col, axis=2, keepdims=True)
    lines = np.broadcast_to(col + row, r3.shape).reshape(r.shape)
    return r - lines, lines


def _without_line_noise(stack: np.ndarray, lit: np.ndarray) -> np.ndarray:
    """The hold's frames (k x H x W) less each frame's column and row offsets: the medians over the rows (columns) of
    its deviation from the hold mean in ``lit`` (the frames with the light's change out). For the pure-noise test
    alone: temporal column or row noise (a noisy ADC reference) moves the block means from frame to frame as a scene
    change would, but it is the camera's noise, measured as ``temporal_column`` / ``temporal_row`` (1 DN of column
    noise left a quarter of a campaign's blocks out, 2026-11-29)."""
    dev = lit - lit.mean(axis=0)
    col = np.median(dev, axis=1, keepdims=True)
    row = np.median(dev - col, axis=2, keepdims=True)
    return stack - col - row


def _robust_sigma(d: np.ndarray) -> np.ndarray:
    """Robust per-pixel sigma of de-lined residuals: rms of all but the largest TRIM_PIXELS |values|,
    rescaled for a Gaussian (not discretized by 8-bit values as a MAD would be)."""
    n = d.shape[1]
    keep = n - TRIM_PIXELS
    small = np.sort(np.abs(d), axis=1)[:, :keep]
    a = float(ndtri(1.0 - 0.5 * TRIM_PIXELS / n))
    kept_var = 1.0 - 2.0 * a * math.exp(-0.5 * a * a) / math.sqrt(2.0 * math.pi) / (1.0 - TRIM_PIXELS / n)
    return np.sqrt(np.mean(small**2, axis=1) / kept_var)


def _without_line_pattern(r: np.ndarray, b: int, grid: tuple[int, int]) -> np.ndarray:
    """Block residuals minus the image-wide column and row profiles (median over the blocks sharing
    a line): offsets common to a whole image line are removed, an edge inside one block is not."""
    gy, gx = grid
    r4 = r.reshape(gy, gx, b, b)
    col = np.median(r4.mean(axis=2), axis=0)  # (gx, b): per image column
    r4 = r4 - col[None, :, None, :]
    row = np.median(r4.mean(axis=3), axis=1)  # (gy, b): per image row
    return (r4 - row[:, None, :, None]).reshape(r.shape)


def _line_ratio(r: np.ndarray, b: int, robust: np.ndarray) -> np.ndarray:
    """Spread of the column (row) medians relative to the robust sigma: an edge in a block stands out,
    legitimate column/row offsets do not (they are alike in every block), hot pixels do not move medians."""
    r3 = r.reshape(-1, b, b)
    spread = np.maximum(np.median(r3, axis=1).std(axis=1), np.median(r3, axis=2).std(axis=1))
    return spread / np.maximum(robust, 1e-6)


def _typical(values: np.ndarray, bins: np.ndarray, use: np.ndarray) -> np.ndarray:
    """Per block, the median of ``values`` over the ``use`` blocks of its intensity bin (interpolated
    between bins with fewer than 3 such blocks; the block's own value when no bin has 3)."""
    centres, medians = [], []
    for k in np.unique(bins[use]):
        sel = use & (bins == k)
        if sel.sum() >= 3:
            centres.append(float(k))
            medians.append(float(np.median(values[sel])))
    if not centres:
        return values
    return np.interp(bins.astype(float), centres, medians)


def _bin_outliers(values: np.ndarray, bins: np.ndarray, keep: np.ndarray, factor: float) -> np.ndarray:
    """Blocks whose value exceeds ``factor`` x the median of their bin (among ``keep``)."""
    out = np.zeros(values.shape, dtype=bool)
    for k in np.unique(bins[keep]):
        sel = keep & (bins == k)
        out[sel] = values[sel] > factor * np.median(values[sel])
    return out


def _largest_cluster(mask: np.ndarray, b: int) -> np.ndarray:
    """(N,) size of the largest 4-connected group of True pixels in each block of ``mask`` (N, b*b)."""
    structure = np.zeros((3, 3, 3), dtype=bool)
    structure[1] = ndimage.generate_binary_structure(2, 1)  # within a block only
    labels, count = ndimage.label(mask.reshape(-1, b, b), structure=structure)
    if count == 0:
        return np.zeros(mask.shape[0], dtype=int)
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    return sizes[labels].reshape(mask.shape[0], -1).max(axis=1)


@lru_cache(maxsize=256)
def spike_fraction(k: int, pixels: int) -> float:
    """The share of white-noise pixels that ``_SegmentAccumulator._blinking`` flags in a block of ``pixels`` with
    ``k`` frames (k - 1 degrees of freedom per pixel). Its level is the block's own median, whose scatter the chi-square tail alone leaves out (it
    undercounts by 15 % at 2 frames and 50-90 % at 5-9 for 8 x 8 blocks, enough to read a clean recording as
    blinking pixels). A flagged pixel lies above the median, so the median is that of the other ``pixels`` - 1;
    their median is drawn (seeded, ``SPIKE_DRAWS``) and the tail beyond SPIKE_FACTOR x the level it gives averaged."""
    rng = np.random.default_rng(1288)
    others = np.sort(rng.chisquare(k - 1, (SPIKE_DRAWS, pixels - 1)), axis=1)
    median = 0.5 * (others[:, (pixels - 1) // 2] + others[:, pixels // 2])
    return float(chi2_dist.sf(SPIKE_FACTOR * (k - 1) * median / chi2_dist.median(k - 1), k - 1).mean())


class _SegmentAccumulator:
    """Running sums over the frames of one segment."""

    def __init__(self, index: int, meta: CameraMetadata, stamp_ns: int, b: int,
                 plane: tuple[np.ndarray, np.ndarray], black_level: float = 0.0) -> None:
        self.index, self.meta, self.stamp_ns, self.b = index, meta, stamp_ns, b
        self.black_level = black_level  # taken off the images: the ADC clips at -black_level and 255 - black_level
        self.proj, self.slopes = plane
        self.frames: list[int] = []
        self.metas: list[CameraMetadata] = []
        self.stamps: list[int] = []
        self.images: list[np.ndarray] = []
        self.pose = np.zeros(2)
        # accumulators, shaped by the first frame (blocks x components)
        self.s1: Any = None
        self.s2: Any = None
        self.s2_col: Any = None
        self.s2_row: Any = None
        self.s2_pixel: Any = None
        self.mean: Any = None
        self.slope: Any = None
        self.pixel_var: np.ndarray | None = None  # (N, b*b) per-pixel temporal variance once vibration is removed
        self.dof = 0  # its degrees of freedom (k - 1 without vibration)
        self.light: LightChange | None = None  # the light's change from frame to frame, once measured
        self.motion_px = 0.0  # the camera's vibration taken out (rms displacement, px), once measured

    def add(self, frame_index: int, img: np.ndarray, meta: CameraMetadata, stamp_ns: int) -> None:
        self.images.append(img.astype(np.float32))
        self.stamps.append(stamp_ns)
        blocks = _blocks(img, self.b)
        r = blocks @ self.proj
        if self.s1 is None:
            self.s1 = np.zeros_like(r)
            self.s2 = np.zeros(r.shape[0])
            self.s2_col = np.zeros(r.shape[0])
            self.s2_row = np.zeros(r.shape[0])
            self.s2_pixel = np.zeros_like(r)
            self.mean = np.zeros(r.shape[0])
            self.slope = np.zeros((r.shape[0], 2))
        self.slope += blocks @ self.slopes
        self.s1 += r
        self.s2_pixel += r * r
        self._add_energies(r)
        self.mean += blocks.mean(axis=1)
        self.frames.append(frame_index)
        self.dof = len(self.frames) - 1
        self.metas.append(meta)

    def _blinking(self, k: int) -> np.ndarray:
        """(N, b*b) blinking pixels: per-pixel temporal variance beyond SPIKE_FACTOR x the block's typical
        one (its median, scaled to the chi-square mean of the ``dof`` degrees of freedom)."""
        vp = (self.s2_pixel - self.s1**2 / k) / (k - 1) if self.pixel_var is None else self.pixel_var
        level = np.median(vp, axis=1, keepdims=True) / (chi2_dist.median(self.dof) / self.dof)
        return vp > SPIKE_FACTOR * level

    def _add_energies(self, r: np.ndarray) -> None:
        energy, col, row = _energies(r, self.b)
        self.s2 += energy
        self.s2_col += col
        self.s2_row += row

    def _steady(self, stack: np.ndarray) -> np.ndarray:
        """The frames' sums, energies and per-pixel variances again, with the light's change from frame to frame
        (flicker, a rolling shutter's bands: :func:`..measure.temporal.light_and_motion`) and the camera's vibration
        (:func:`..measure.temporal.steady_run`) taken out of every pixel (nothing when neither shows); the frames
        themselves (``stack``) stay for the pure-noise test, which rejects the blocks where the motion shows.
        Returns the frames with the light's change out."""
        self.light, lit, displacement, _ = light_and_motion(stack, self.b)
        steady = steady_run(lit, self.b, displacement)
        if steady is None and self.light is None:
            return lit
        zero = np.zeros_like(self.s2)
        self.s1, self.s2_pixel = np.zeros_like(self.s1), np.zeros_like(self.s2_pixel)
        self.s2, self.s2_col, self.s2_row = zero, zero.copy(), zero.copy()
        for img in lit if steady is None else steady.frames:
            r = _blocks(img, self.b) @ self.proj
            self.s1 += r
            self.s2_pixel += r * r
            self._add_energies(r)
        if steady is not None:
            self.pixel_var = sum((_blocks(r, self.b) @ self.proj) ** 2 for r in steady.residual) / steady.dof
            self.dof = steady.dof
            self.motion_px = motion_rms(displacement[0])
        return lit

    def finish(self, grid: tuple[int, int], shape: tuple[int, int] | None = None) -> list[_Full]:
        """The hold's measurement, or those of its parts when its noise changed (:mod:`.hold_change`)."""
        full = self._measure(grid, shape)
        found = self._noise_change(full.still)
        at = found.at
        if not at:
            self.images = []
            return [full]
        before, after = (self._part(lo, hi).finish(grid, shape) for lo, hi in ((0, at), (at, len(self.frames))))
        self.images = []
        for part in before + after:  # a part of one frame, here or where a part was cut again
            part.lone = len(part.frames) == 1
        # the change's size from the parts on either side of it, once cut again where they changed too (else from the
        # whole hold's blocks: a lone frame, or no block flat and still in both parts)
        both = (before[-1].still & after[0].still if not (before[-1].lone or after[0].lone)
                else np.zeros(0, dtype=bool))
        size = (hold_change.sigmas(before[-1].values["temporal"][both], after[0].values["temporal"][both])
                if both.any() else (found.sigma_before_dn, found.sigma_after_dn))
        after[0].change = NoiseChange(self.frames[at], self.stamps[at], *size)
        return before + after

    def _part(self, lo: int, hi: int) -> _SegmentAccumulator:
        """The hold's frames lo..hi-1, to be measured on their own."""
        part = _SegmentAccumulator(self.index, self.metas[lo], self.stamps[lo], self.b, (self.proj, self.slopes),
                                   self.black_level)
        part.pose = self.pose.copy()
        for j in range(lo, hi):
            part.add(self.frames[j], self.images[j], self.metas[j], self.stamps[j])
        return part

    def _noise_change(self, still: np.ndarray) -> hold_change.Cut:
        """The hold's largest material noise change among its frames, read on its ``still`` blocks."""
        if len(self.frames) < hold_change.MIN_FRAMES or not still.any():
            return hold_change.Cut(0)
        residuals, light = hold_change.residuals(self.images, still, self.b)
        stepped = np.array([i > 0 and (m.gain_db, m.exposure_time_s) != (self.metas[i - 1].gain_db,
                                                                        self.metas[i - 1].exposure_time_s)
                            for i, m in enumerate(self.metas)])
        return hold_change.cut(residuals, light, stepped)

    def _measure(self, grid: tuple[int, int], shape: tuple[int, int] | None) -> _Full:
        stack = np.stack(self.images)
        lit = self._steady(stack)
        b, k = self.b, len(self.frames)
        rm = self.s1 / k
        v = self.mean / k
        # outlier pixels (hot pixels, defects) stand out of the column/row structure and the noise; they
        # are measured apart (count, amplitude, energy) and replaced by the line model in the rest
        centred, lines = _delined(rm, b)
        robust = _robust_sigma(centred)
        is_out = np.abs(centred) > OUTLIER_PIXEL_SIGMAS * robust[:, None]
        clean = np.where(is_out, lines, rm) @ self.proj  # re-fit the plane
        core, col, row = _split(*_energies(clean, b), b)
        values: dict[str, np.ndarray] = {}
        if k >= 2:
            # energies of the frames' deviations from the mean, split like the mean's
            e_tot, e_col, e_row = _energies(rm, b)
            d_tot, d_col, d_row = ((x - k * e) / (k - 1) for x, e in (
                (self.s2, e_tot), (self.s2_col, e_col), (self.s2_row, e_row)))
            temporal, t_col, t_row = _split(d_tot, d_col, d_row, b)
            values = {"temporal": temporal, "fixed": core - temporal / k,
                      "temporal_column": t_col, "temporal_row": t_row}
            col, row = col - t_col / k, row - t_row / k
        else:
            temporal = None
            values = {"single": core}
        still = np.zeros(0, dtype=bool)
        values |= {"column": col, "row": row, "outlier": np.sum(np.where(is_out, centred**2, 0.0), axis=1) / (b * b)}

        n = v.size
        bins = np.floor(v / BIN_WIDTH_DN).astype(int)
        lo, hi = INTENSITY_RANGE_DN
        excluded: dict[str, int] = {}
        in_range = (v >= lo) & (v <= hi)
        # the texture tests see the residual with the outlier pixels replaced: a hot pixel's energy would
        # swamp a textured block's lag-1 correlation and pass it as flat (blocks holding hot pixels were
        # kept 2-4 x as often as others on textured campaigns, more outliers and at other levels than
        # a random choice of blocks holds); real column/row offsets removed: edges stand out
        flat = _without_line_pattern(clean, b, grid)
        rho_x, rho_y = _lag1(flat, b)
        lines = _line_ratio(flat, b, robust)
        tex = in_range & (
            (np.minimum(rho_x, rho_y) > TEXTURE_CORRELATION)
            | _bin_outliers(robust, bins, in_range, OUTLIER_BLOCK_FACTOR)
            | (lines > OUTLIER_BLOCK_FACTOR * np.median(lines[in_range]) if in_range.any() else False)
        )
        # blocks whose noise reaches the clipping limits are left out (their statistics are distorted):
        # the block's clean level range (its fitted plane) within CLIP_SIGMAS x the typical noise of its
        # intensity, both independent of the block's own noise realization (a test on the noisy hold
        # mean's darkest pixel or on the block's own variance keeps the blocks whose noise came out small
        # and biases short, high-gain holds low by up to 5 %)
        white = values["temporal"] + values["fixed"] if k >= 2 else values["single"]
        # (a frame's light change, flicker or a rolling shutter's bands, moves the block's level in that frame)
        span = (b - 1) * np.abs(self.slope / k).sum(axis=1)
        reach = CLIP_SIGMAS * np.sqrt(np.maximum(_typical(white, bins, in_range & ~tex), 0.0))
        lowest, highest = (v, v) if self.light is None else self.light.block_levels(v, b, grid[1])
        keep = (in_range & (lowest - span / 2 - reach >= -self.black_level)
                & (highest + span / 2 + reach <= 255.0 - self.black_level))
        excluded["near_clipping"] = int(np.sum(~keep))
        tex &= keep
        excluded["texture"] = int(np.sum(tex))
        keep &= ~tex
        flat_mask = keep.copy()
        if temporal is not None:
            # frame differences that do not fit pure noise: residual motion, flicker, a moving object
            # (blinking pixels are temporal noise, measured as temporal_spikes, not a scene change)
            blinking = self._blinking(k)
            run = block_temporal(_without_line_noise(stack, lit), b, exclude=blinking, whiteness=True)
            changed = _largest_cluster(blinking, b) >= MIN_CHANGE_CLUSTER
            moving = keep & (~run.accepted | changed)
            still = keep & run.still & ~changed
            excluded["not_static"] = int(np.sum(moving))
            keep &= ~moving
        spikes = self._blinking(k).sum(axis=1) if k >= 2 else np.zeros(n, dtype=int)
        gy, gx = grid
        iy, ix = np.divmod(np.arange(n), gx)
        region = (3 * iy // max(gy, 1)) * 3 + (3 * ix // max(gx, 1))
        h, w = shape if shape is not None else (gy * b, gx * b)
        position = np.stack([(iy + 0.5) * b / h, (ix + 0.5) * b / w], axis=1)
        return _Full(self.index, _mean_meta(self.metas), self.stamp_ns, list(self.frames), self.dof, self.pose,
                     v, region, values, robust, span, is_out, centred,
                     keep, flat_mask, excluded, clean, np.maximum(white, 0.0), position, spikes,
                     light_pct=0.0 if self.light is None else self.light.percent(), motion_px=self.motion_px,
                     last_stamp_ns=self.stamps[-1], still=still, lag1=_lag1_excess(clean, b),
                     temperature_var_c2=float(np.var([m.sensor_temperature_c for m in self.metas], ddof=1))
                     if k >= 2 else 0.0)


@dataclass
class _Full:
    """A segment's measurements for every block, before the final selection (see :func:`_select`)."""

    index: int
    meta: CameraMetadata
    stamp_ns: int
    frames: list[int]
    dof: int  # per-pixel temporal degrees of freedom (k - 1, fewer once a vibration is regressed out)
    pose: np.ndarray  # camera position (px) by accumulated global shifts
    v: np.ndarray
    region: np.ndarray
    values: dict[str, np.ndarray]
    robust: np.ndarray
    span: np.ndarray
    is_out: np.ndarray
    centred: np.ndarray
    keep: np.ndarray
    flat: np.ndarray  # unclipped and flat on the hold mean (before the pure-noise test)
    excluded: dict[str, int]
    residual: np.ndarray  # (N, b*b) plane-fit residual of the hold mean, outlier pixels replaced
    white: np.ndarray  # (N,) white variance of that residual (fixed + temporal / k), single view
    position: np.ndarray  # (N, 2) block centre (y, x), normalised to 0..1
    spikes: np.ndarray  # (N,) blinking pixels per block (SPIKE_FACTOR outliers of the temporal variance)
    partners: tuple[int, ...] = ()
    partner_weight: np.ndarray | None = None  # (N, P)
    partner_v: np.ndarray | None = None  # (N, P)
    partner_robust: np.ndarray | None = None  # (N, P)
    partner_confirms: np.ndarray | None = None  # (N, P)
    partner_values: dict[str, np.ndarray] | None = None  # component -> (N, P)
    fourth: np.ndarray | None = None  # (N,) see SegmentMeasurement.fixed_fourth
    square: np.ndarray | None = None  # (N,)
    light_pct: float = 0.0  # the light's change taken out of the hold's frames (%)
    motion_px: float = 0.0  # the camera's vibration taken out (rms displacement, px)
    change: NoiseChange | None = None  # the noise change the segment starts at
    last_stamp_ns: int = 0  # the stamp of its last frame
    #: (N,) bool: flat, unclipped and without a scene change, whatever its noise did (the blocks a change of the
    #: noise is read on: :mod:`.hold_change`); empty for a single frame
    still: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    lone: bool = False  # a hold's edge frame alone on its side of a noise change (not measured: ``LONE``)
    temperature_var_c2: float = 0.0  # see SegmentMeasurement
    #: (N,) the hold mean's lag-1 excess per block (:func:`_lag1_excess`), the scene's signature in a single view
    lag1: np.ndarray = field(default_factory=lambda: np.zeros(0))


def _select(f: _Full, b: int) -> SegmentMeasurement:
    keep = f.keep
    amp = np.abs(f.centred[keep][f.is_out[keep]])
    k = len(f.frames)
    spikes_expected = float(keep.sum()) * b * b * spike_fraction(f.dof + 1, b * b) if k >= 2 else 0.0
    return SegmentMeasurement(
        index=f.index,
        meta=f.meta,
        stamp_ns=f.stamp_ns,
        frames=f.frames,
        intensity_dn=f.v[keep],
        region=f.region[keep],
        position=f.position[keep],
        values={c: a[keep] for c, a in f.values.items()},
        robust_sigma_dn=f.robust[keep],
        span_dn=f.span[keep],
        outlier_pixels=int(amp.size),
        outlier_amplitude_dn=float(amp.mean()) if amp.size else 0.0,
        outlier_amplitude_err_dn=float(amp.std() / math.sqrt(amp.size)) if amp.size > 1 else 0.0,
        pixels_checked=int(keep.sum()) * b * b,
        blocks_total=f.v.size,
        excluded=f.excluded,
        partners=f.partners,
        partner_weight=None if f.partner_weight is None else f.partner_weight[keep],
        partner_intensity_dn=None if f.partner_v is None else f.partner_v[keep],
        partner_sigma_dn=None if f.partner_robust is None else f.partner_robust[keep],
        partner_confirms=None if f.partner_confirms is None else f.partner_confirms[keep],
        partner_values=None if f.partner_values is None else {c: a[keep] for c, a in f.partner_values.items()},
        temporal_spikes=int(f.spikes[keep].sum()),
        temporal_spikes_expected=spikes_expected,
        fixed_fourth=None if f.fourth is None else f.fourth[keep],
        fixed_square=None if f.square is None else f.square[keep],
        light_pct=f.light_pct,
        temperature_var_c2=f.temperature_var_c2,
        motion_px=f.motion_px,
        last_stamp_ns=f.last_stamp_ns,
        scene_dn2=_scene_in_single_view(f),
        outliers_measured=not _specks_of_the_scene(f, b),
    )


def _specks_of_the_scene(f: _Full, b: int) -> bool:
    """Whether a single view's outlier pixels are the scene's specks: their 4-neighbours in the block (outliers
    left out) carry on average more than ``NEIGHBOUR_SHARE`` of their offset, ``SCENE_SIGMAS`` standard errors
    beyond it, the errors of defects (isolated pixels: their neighbours' mean scatters by the block's robust sigma
    over the square root of their number); never across views: partner views confirm outliers there."""
    if f.partners:
        return False
    c, out = f.centred[f.keep].reshape(-1, b, b), f.is_out[f.keep].reshape(-1, b, b)
    sigma = np.broadcast_to(f.robust[f.keep][:, None, None], c.shape)
    near, count = (_neighbour_sum(np.where(out, 0.0, c)), _neighbour_sum((~out).astype(float)))
    sel = out & (count > 0)
    if not sel.any():
        return False
    share = near[sel] / count[sel] / c[sel]
    se = math.sqrt(float(np.sum(sigma[sel] ** 2 / count[sel] / c[sel] ** 2))) / share.size
    return bool(share.mean() - NEIGHBOUR_SHARE > SCENE_SIGMAS * se)


def _neighbour_sum(x: np.ndarray) -> np.ndarray:
    """(N, b, b) per pixel, the sum of its 4-neighbours' values inside its block (N, b, b)."""
    p = np.pad(x, ((0, 0), (1, 1), (1, 1)))
    return p[:, :-2, 1:-1] + p[:, 2:, 1:-1] + p[:, 1:-1, :-2] + p[:, 1:-1, 2:]


def _scene_in_single_view(f: _Full) -> np.ndarray | None:
    """Per accepted block, the scene's variance in a single view's fixed pattern, when the view shows the scene
    (its blocks' mean lag-1 excess ``SCENE_SIGMAS`` standard errors from 0); None across views or without it. A
    cell's scene variance is the magnitude of its blocks' mean (a grating's excess is negative)."""
    x = f.lag1[f.keep]
    if f.partners or x.size < MIN_BLOCKS_PER_CELL:
        return None
    if abs(x.mean()) <= SCENE_SIGMAS * x.std(ddof=1) / math.sqrt(x.size):
        return None
    return x / SCENE_LAG1_PER_DN2


def _cross_energies(a: np.ndarray, c: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(total, column-part, row-part) cross energies of two residual sets (N, b*b): the energies of
    :func:`_energies` with one factor from each set (noise and scene that differ between them cancel)."""
    a3, c3 = a.reshape(-1, b, b), c.reshape(-1, b, b)
    col = b * np.sum(a3.mean(axis=1) * c3.mean(axis=1), axis=1)
    row = b * np.sum(a3.mean(axis=2) * c3.mean(axis=2), axis=1)
    return np.sum(a * c, axis=1), col, row


def _texture_white(g: _Full, grid: tuple[int, int]) -> np.ndarray:
    """Per block, its white variance for the cross-view exclusion: as its neighbours see it (the bin's typical
    white variance times the median over the 8 neighbouring flat blocks, 1 without one, of their white variance
    over their bins' typical: the scene's texture around it and the view's noise), or its own where that exceeds
    ``TEXTURED_WHITE`` times theirs (the block's own texture). Not the block's own elsewhere: its fixed pattern's
    realization and its hold mean's noise enter its cross energies too."""
    bins = np.floor(g.v / BIN_WIDTH_DN).astype(int)
    typical = np.maximum(_typical(g.white, bins, g.flat), MIN_VAR_ERR_DN2)
    gy, gx = grid
    ratio = np.pad(np.where(g.flat, g.white / typical, np.nan).reshape(gy, gx), 1, constant_values=np.nan)
    around = np.stack([ratio[1 + dy:1 + dy + gy, 1 + dx:1 + dx + gx] for dy in (-1, 0, 1) for dx in (-1, 0, 1)
                       if dy or dx]).reshape(8, -1)
    seen = np.isfinite(around).any(axis=0)
    factor = np.ones(g.v.size)
    factor[seen] = np.nanmedian(around[:, seen], axis=0)
    around_it = typical * factor
    return np.where(g.white > TEXTURED_WHITE * around_it, g.white, around_it)


def _cross_views(fulls: list[_Full], b: int, grid: tuple[int, int]) -> int:
    """Fixed-pattern, column and row components from what stays in sensor coordinates while the scene
    moves: per block, the cross energies of the hold-mean residuals of this hold and of up to
    ``MAX_PARTNERS`` holds (nearest in time) seen from a camera pose at least ``MIN_PARTNER_SHIFT_PX``
    away, where that block is flat and unclipped too. Temporal noise and scene texture differ between the
    views and cancel in expectation; a fixed pattern ``a_s * P(x)`` gives ``a_s * a_p`` per pixel.
    Returns the number of segments measured this way (the others keep the single-view estimate)."""
    done = 0
    # the exclusion below must not see a block's own realization: from its own white variance it left out the
    # blocks whose pattern came out large (PRNU 1.2 % low in variance)
    texture = {g.index: _texture_white(g, grid) for g in fulls if "temporal" in g.values}
    for f in fulls:
        if "temporal" not in f.values:
            continue
        cands = [g for g in fulls if g is not f and "temporal" in g.values
                 and float(np.hypot(*(g.pose - f.pose))) >= MIN_PARTNER_SHIFT_PX]
        if not cands:
            continue
        cands = sorted(cands, key=lambda g: abs(g.index - f.index))[:MAX_PARTNERS]
        valid = np.stack([g.flat for g in cands], axis=1).astype(float)  # (N, P)
        parts = [_split(*_cross_energies(f.residual, g.residual, b), b) for g in cands]
        count = valid.sum(axis=1)
        # inverse-variance weights: a cross energy's noise grows with the partner's white variance
        inv = valid / np.maximum(np.stack([g.white for g in cands], axis=1), MIN_VAR_ERR_DN2)
        weight = inv / np.maximum(inv.sum(axis=1), 1e-300)[:, None]
        f.partner_values = {comp: np.stack([p[j] for p in parts], axis=1) for j, comp in enumerate(CROSS_VIEW)}
        for comp, per_partner in f.partner_values.items():
            f.values[comp] = np.sum(per_partner * weight, axis=1)
        # an outlier pixel (hot pixel, defect) stays where it is on the sensor; a scene detail moves:
        # keep the outliers that stand out with the same sign (> CONFIRM_SIGMAS) in CONFIRM_VIEWS partner
        # views (all of them when fewer are valid): one view confirms a scene speck by chance (texture
        # beyond 3 sigma somewhere in a flat block), two rarely do; a partner block with other pixels
        # beyond CONFIRM_SIGMAS (a speckled texture: bright specks on a flat background pass the flat
        # tests) would confirm by chance and does not count
        confirmed = np.zeros(f.is_out.shape, dtype=np.int16)
        capable = []  # per partner: its block can confirm a pixel beyond CONFIRM_SIGMAS there
        for j, g in enumerate(cands):
            beyond = np.abs(g.centred) > CONFIRM_SIGMAS * g.robust[:, None]
            n_beyond = beyond.sum(axis=1, keepdims=True)
            same = (np.sign(g.centred) == np.sign(f.centred)) & beyond & (n_beyond - beyond <= CONFIRM_MAX_OTHERS)
            confirmed += same & (valid[:, j] > 0)[:, None]
            capable.append(n_beyond[:, 0] <= CONFIRM_MAX_OTHERS + 1)
        need = np.maximum(np.minimum(CONFIRM_VIEWS, count), 1)
        f.is_out = f.is_out & (confirmed >= need[:, None])
        f.values["outlier"] = np.sum(np.where(f.is_out, f.centred**2, 0.0), axis=1) / (b * b)
        # noise of the cross estimate (Gaussian): white_s / (d * sum(1 / white_p)); a block whose scene
        # texture (white_s) or partners' noise make it large against its own temporal noise is left out
        white_p = np.stack([texture[g.index] for g in cands], axis=1)
        se = np.sqrt(texture[f.index] * np.sum(weight * white_p * weight, axis=1) / (b - 1) ** 2)
        lost = f.keep & ((count == 0) | (se > CROSS_SE_MAX * np.maximum(f.values["temporal"], MIN_VAR_ERR_DN2)))
        f.excluded["no_partner_view"] = int(lost.sum())
        f.keep = f.keep & ~lost
        f.partners = tuple(g.index for g in cands)
        f.partner_weight = weight
        f.partner_v = np.stack([g.v for g in cands], axis=1)
        f.partner_robust = np.stack([g.robust for g in cands], axis=1)
        f.partner_confirms = np.stack(capable, axis=1)
        moments = fourth_moments(f, cands, valid * f.keep[:, None], MIN_PARTNER_SHIFT_PX, MIN_VAR_ERR_DN2)
        if moments is not None:
            f.fourth, f.square = moments
        done += 1
    return done


#: components that are pooled over the whole segment in every cell: line offsets belong to image lines
#: (a cell covers few of them) and outlier pixels are sparse; both are assumed independent of intensity
POOLED = ("column", "row", "outlier", "temporal_column", "temporal_row")


#: pooled components whose gross outliers (an edge that slipped through) are trimmed
TRIMMED = ("column", "row", "temporal_column", "temporal_row")
#: single-view components whose errors take the scene's variance where the view shows the scene
#: (:func:`_scene_in_single_view`): the fixed pattern, column and row offsets are the hold mean's residual there
SCENE_WIDENED = ("fixed", "single", "column", "row")
TRIM_MADS = 8.0


def _inliers(x: np.ndarray, symmetric: bool = False) -> np.ndarray:
    """Values not beyond TRIM_MADS robust deviations above the median (an edge only adds energy), or on
    either side for cross-view estimates (zero-mean noise either way: a one-sided cut would bias them)."""
    med = np.median(x)
    mad = TRIM_MADS * max(1.4826 * float(np.median(np.abs(x - med))), 1e-9)
    return np.flatnonzero(np.abs(x - med) <= mad if symmetric else x <= med + mad)


#: degrees of freedom a segment's pooled within-cell spread needs before it floors its cells' errors
MIN_SPREAD_DOF = 10


def _within_cell_spread(values: Mapping[str, np.ndarray], bins: np.ndarray) -> dict[str, float]:
    """Per component measured per cell (not pooled per segment; ``values``: per block): the standard deviation of a
    segment's blocks about their intensity bin's mean (``bins``: per block), pooled over its bins (where its bins of two
    blocks or more give MIN_SPREAD_DOF degrees of freedom). A cell's error is at least this over the square root of
    its blocks: the spread of a cell's own 6-10 blocks is uncertain by a third and can come out far too small (a hold
    at 54.6 degC whose 6-block cell read 7 of its stated errors off with the true model: experiments/lab_several_effects/
    section 11)."""
    groups = [idx for k in np.unique(bins) if (idx := np.flatnonzero(bins == k)).size >= 2]
    dof = sum(idx.size - 1 for idx in groups)
    if dof < MIN_SPREAD_DOF:
        return {}
    return {comp: math.sqrt(sum(float(np.sum((arr[idx] - arr[idx].mean()) ** 2)) for idx in groups) / dof)
            for comp, arr in values.items() if comp not in POOLED}


def _cells(seg: SegmentMeasurement, b: int) -> list[Cell]:
    out: list[Cell] = []
    if seg.intensity_dn.size == 0:
        return out
    bins = np.floor(seg.intensity_dn / BIN_WIDTH_DN).astype(int)
    pooled = {comp: _inliers(arr, bool(seg.partners) and comp in CROSS_VIEW) if comp in TRIMMED else np.arange(arr.size)
              for comp, arr in seg.values.items() if comp in POOLED}
    spread = _within_cell_spread(seg.values, bins)
    for k in np.unique(bins):
        idx = np.flatnonzero(bins == k)
        if idx.size < MIN_BLOCKS_PER_CELL:
            continue
        sel = {comp: pooled.get(comp, idx) for comp in seg.values}
        vals = {comp: float(arr[sel[comp]].mean()) for comp, arr in seg.values.items()}
        floor = _theoretical_se(vals, seg.n_frames, b)
        errs = {
            comp: max(float(arr[sel[comp]].std(ddof=1)), floor[comp], MIN_VAR_ERR_DN2) / math.sqrt(sel[comp].size)
            for comp, arr in seg.values.items()
        }
        if not seg.outliers_measured:  # the scene's specks: as much as measured may be scene
            errs["outlier"] = math.hypot(errs["outlier"], max(vals["outlier"], 0.0))
        if seg.scene_dn2 is not None:  # the scene's variance may sit in the single view's fixed pattern
            for comp in SCENE_WIDENED:
                if comp in errs:
                    scene = seg.scene_dn2[sel[comp]].mean()
                    errs[comp] = math.hypot(errs[comp], abs(float(scene)))
        for comp, sd in spread.items():  # a few blocks' own spread can come out far too small
            errs[comp] = max(errs[comp], sd / math.sqrt(sel[comp].size))
        views = {}
        for comp, per_partner in (seg.partner_values or {}).items():
            assert seg.partner_weight is not None
            views[comp] = partner_views(per_partner[sel[comp]], seg.partner_weight[sel[comp]] > 0)
        out.append(Cell(seg.index, int(k), float(seg.intensity_dn[idx].mean()), idx, vals, errs, views))
    return out


def field_conditions_text(conditions: dict[str, Any]) -> str:
    """One line for people from ``Measurements.summary()['field_conditions']``."""
    if not conditions["holds"]:
        return "no hold measured from frame differences"
    light = (f"the light changed from frame to frame in {conditions['light_changing']} of {conditions['holds']} holds measured "
             f"(flicker, a lamp switched or a rolling shutter's bands; up to {conditions['light_pct_max']:.2g} % rms)"
             if conditions["light_changing"] else f"steady light in all {conditions['holds']} holds measured")
    shake = (f"the camera vibrated in {conditions['vibrating']} (up to {conditions['motion_px_max']:.2f} px rms)"
             if conditions["vibrating"] else "no vibration")
    return f"{light}, {shake}; taken out before the temporal noise"


def scene_in_views_text(components: list[str]) -> str:
    """One line for people from ``Measurements.summary()['scene_in_partner_views']`` (not empty)."""
    return (f"the scene repeats under the camera's shifts (a periodic texture) in the {', '.join(components)} "
            "measurements across views: their errors take the views' spread, and a weak pattern there cannot be told "
            "from the scene")


def scene_in_single_views_text(found: dict[str, Any]) -> str | None:
    """One line for people from ``Measurements.summary()['scene_in_single_views']`` (None: no view shows it)."""
    parts = []
    if found["fixed_pattern"]:
        parts.append(f"in the fixed pattern of {found['fixed_pattern']} of {found['views']} views without a partner "
                     f"(neighbouring pixels correlated: fixed pattern, column and row errors take the scene's variance, "
                     f"up to {found['scene_dn2_max']:.3g} DN^2)")
    if found["outlier_pixels"]:
        parts.append(f"in the outlier pixels of {found['outlier_pixels']} (their neighbours share their offset: "
                     "the scene's specks, not counted)")
    if not parts:
        return None
    return "the scene shows " + "; ".join(parts) + "; partner views (a moved camera) or a flat chart separate it"


def _widen_where_the_scene_shows(cells: list[Cell]) -> list[str]:
    """The cross-view components in which some cell's partner view lies below 0 beyond chance
    (``PARTNER_NEGATIVE_P``: the scene repeats under the views' shifts somewhere in the recording); their errors
    take the views' spread (Birge ratio) in every cell, whatever its sign, so the widening selects no sign."""
    shown = [comp for comp in CROSS_VIEW if any(c.partner_views.get(comp, (1.0, 1.0))[0] < PARTNER_NEGATIVE_P
                                                 for c in cells)]
    for c in cells:
        for comp in shown:
            c.errors[comp] *= c.partner_views.get(comp, (1.0, 1.0))[1]
    return shown


def partner_views(per_partner: np.ndarray, used: np.ndarray) -> tuple[float, float]:
    """(the lowest one-sided p-value of a view's mean cross energy being that far below 0 (Student t over its
    blocks), the Birge ratio of the views' means (>= 1)) of a cell: ``per_partner`` (N, P) each block's cross
    energy with each partner view, ``used`` (N, P) where the view is used; views with fewer than 3 blocks are
    left out ((1, 1) when fewer than two views remain).

    A fixed pattern stays in sensor coordinates and gives each view a_s * a_p >= 0 (its own value: the views
    differ in exposure, gain, intensity); a scene that repeats under the views' shifts (a grating) gives each
    view a bias of either sign (the scene's autocorrelation at that shift), the same in every block of the
    cell, which the blocks' scatter cannot show but the views' spread does."""
    n = used.sum(axis=0)
    cols = np.flatnonzero(n >= 3)
    if cols.size < 2:
        return 1.0, 1.0
    x, m, k = per_partner[:, cols], used[:, cols], n[cols]
    mean = np.sum(x * m, axis=0) / k
    se = np.sqrt(np.maximum(np.sum(((x - mean) * m) ** 2, axis=0) / (k - 1), MIN_VAR_ERR_DN2**2) / k)
    w = se**-2.0
    chi2 = float(np.sum(w * (mean - np.sum(w * mean) / np.sum(w)) ** 2))
    return float(np.min(t_dist.cdf(mean / se, k - 1))), max(1.0, math.sqrt(chi2 / (cols.size - 1)))


def _theoretical_se(vals: dict[str, float], k: int, b: int) -> dict[str, float]:
    """Per-block standard deviation of each estimator for Gaussian noise (floor of the empirical one)."""
    pos = {c: max(v, 0.0) for c, v in vals.items()}
    d_rest, d_line = (b - 1) ** 2, b - 2
    if k >= 2:
        t, f = pos["temporal"], pos["fixed"]
        white = f + t / k
        out = {
            "temporal": t * math.sqrt(2.0 / ((k - 1) * (b * b - 3))),
            "fixed": math.sqrt(2.0 * white**2 / d_rest + 2.0 * (t / k) ** 2 / ((k - 1) * (b * b - 3))),
        }
    else:
        white = pos["single"]
        out = {"single": white * math.sqrt(2.0 / d_rest)}
    for comp in ("column", "row"):
        out[comp] = math.sqrt(2.0 / d_line) * (white + b * pos[comp]) / b
    if k >= 2:
        for comp in ("temporal_column", "temporal_row"):
            out[comp] = math.sqrt(2.0 / ((k - 1) * d_line)) * (pos["temporal"] + b * pos[comp]) / b
    out["outlier"] = 0.0
    return out


def _quant_step(hist: np.ndarray, bin_dn: float) -> tuple[float, float]:
    """Quantization step from the gaps between occupied histogram bins (median gap) and its error."""
    total = hist.sum()
    if total == 0:
        return float("nan"), float("nan")
    occupied = np.flatnonzero(hist >= max(3, 1e-6 * total))
    gaps = np.diff(occupied) * bin_dn
    if gaps.size < 3:
        return float("nan"), float("nan")
    step = float(np.median(gaps))
    near = gaps[gaps <= 4 * step]
    err = float(max(0.1 * bin_dn, near.std() / math.sqrt(near.size))) if near.size else bin_dn
    return step, err


def measure_frames(
    frames: Iterable[Frame],
    block: int = BLOCK,
    tolerance: SegmentTolerance = SegmentTolerance(),
    progress: Any = None,
    metadata_timeout_s: float = MonitorConfig.metadata_timeout_s,
) -> Measurements:
    """Measure noise from frames.

    Frames the monitor would skip (unusable image, invalid, missing or stale metadata) are skipped here
    too, counted by reason; the image size must not change. ``progress`` is an optional tqdm-like
    object updated once per frame.
    """
    if block < 4:
        raise ValueError(f"block size must be >= 4 pixels, got {block}")
    plane = _plane_fit(block)
    segments: list[_Full] = []
    skipped: dict[str, int] = {}
    acc: _SegmentAccumulator | None = None
    shape: tuple[int, int] | None = None
    grid = (0, 0)
    hist = np.zeros(0)  # sized by the first usable frame
    hist_bin = 1.0
    prev: np.ndarray | None = None
    pose = np.zeros(2)
    total = used = 0
    for i, fr in enumerate(frames):
        total += 1
        if progress is not None:
            progress.update(1)
        reason = skip_reason(fr, metadata_timeout_s)
        if reason:
            skipped[reason] = skipped.get(reason, 0) + 1
            continue
        img = np.asarray(fr.image_dn, dtype=np.float64)
        raw = img + fr.black_level_dn if fr.black_level_dn else img  # the camera's output codes
        if shape is None:
            if img.shape[0] < block or img.shape[1] < block:
                raise ValueError(f"images of {img.shape[1]}x{img.shape[0]} pixels are smaller than one {block}x{block} block")
            shape = (img.shape[0], img.shape[1])
            grid = (img.shape[0] // block, img.shape[1] // block)
            hist_bin = 1.0 if np.all(raw == np.rint(raw)) else 1.0 / 64.0
            hist = np.zeros(int(round(255.0 / hist_bin)) + 1)
        elif img.shape != shape:
            skipped["image size changed"] = skipped.get("image size changed", 0) + 1
            continue
        used += 1
        idx = np.clip(np.rint(raw / hist_bin).astype(np.int64), 0, hist.size - 1)
        hist += np.bincount(idx.ravel(), minlength=hist.size)
        meta = fr.metadata
        assert meta is not None  # skip_reason checked it
        stamp_ns = int(getattr(fr, "stamp_ns", i))
        # a segment is a static hold: the camera stays within HOLD_SHIFT_PX of the hold's first frame (global
        # shifts accumulated: a vibrating camera returns about one pose), the metadata agree and so does the black
        # level (the ADC's clip limits)
        shift = np.asarray(camera_shift(prev, img)) if prev is not None else np.zeros(2)
        pose = pose + shift
        moved = acc is not None and math.hypot(*(pose - acc.pose)) > HOLD_SHIFT_PX
        prev = img
        if (acc is None or moved or len(acc.frames) >= tolerance.max_frames
                or not tolerance.same(acc.metas[0], meta) or fr.black_level_dn != acc.black_level):
            if acc is not None:
                segments.extend(acc.finish(grid, shape))
            acc = _SegmentAccumulator(len(segments), meta, stamp_ns, block, plane, fr.black_level_dn)
            acc.pose = pose.copy()
        acc.add(i, img, meta, stamp_ns)
    if acc is not None:
        segments.extend(acc.finish(grid, shape))
    if not segments:
        reasons = ", ".join(f"{k}: {v}" for k, v in skipped.items()) or "no frames"
        raise ValueError(f"no usable frames to measure ({reasons})")
    not_measured: dict[str, str] = {}
    changes = [s.change for s in segments if s.change is not None]
    held = [s for s in segments if len(s.frames) >= 2]
    if held:
        lone = sum(s.lone for s in segments)
        single = len(segments) - len(held) - lone
        if single:  # frames of a pan or between metadata changes: no temporal reference
            skipped[NOT_HELD] = single
        if lone:
            skipped[LONE] = lone
        used -= single + lone
        for j, s in enumerate(held):
            s.index = j
        segments = held
        if not _cross_views(segments, block, grid):
            not_measured["fixed_pattern_separation"] = (
                "one camera pose only: fixed pattern, column and row offsets are the hold mean's residual in "
                "blocks flat on that mean (scene texture finer than a block cannot be told from fixed pattern)")
    else:
        not_measured["temporal"] = ("no static hold of >= 2 frames (the camera moved or the metadata changed "
                                    "every frame): temporal and fixed-pattern noise are not separated; only "
                                    "single-frame spatial noise in flat regions is measured (component 'single')")
    measured = [_select(s, block) for s in segments]
    shape_of_fixed = fixed_shape(measured)
    cells = [c for s in measured for c in _cells(s, block)]
    if not cells:
        raise ValueError("no flat, unclipped image regions to measure noise in (every block is textured or clipped)")
    step, step_err = _quant_step(hist, hist_bin)
    assert shape is not None  # segments exist, so a frame was used
    return Measurements(
        segments=measured,
        cells=cells,
        quant_step_dn=step,
        quant_step_err_dn=step_err,
        output_step_dn=hist_bin if hist_bin == 1.0 else 0.0,
        histogram=hist,
        histogram_bin_dn=hist_bin,
        frames_total=total,
        frames_used=used,
        skipped=skipped,
        shape=(shape[0], shape[1]),
        not_measured=not_measured,
        fixed_shape=shape_of_fixed,
        scene_in_views=_widen_where_the_scene_shows(cells),
        noise_changes=changes,
    )
