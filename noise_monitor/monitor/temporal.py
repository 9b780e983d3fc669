"""The stream's measurement of the noise: frame differences on static patches (``sigma_temporal``).

While the camera holds still (within a pixel of the hold's first frame by global shift,
same gain and exposure, temperature within a tolerance), the patches chosen on the first frame of the
hold are cut from every frame at the same sensor position. Frame differences cancel the scene, so
their statistics measure the temporal noise without reading texture as noise; the light's change (a flicker,
a rolling shutter's bands, fitted per patch) is taken out first and each 8x8 block must pass the pure-noise
test of :func:`noise_monitor.measure.block_temporal` (a moving object, residual motion or light changing in part
of the patch rejects it). Fixed-pattern noise (PRNU, DSNU, row/column offsets, hot pixels) is the same in
every frame and so absent from this measurement: it is compared with the model's temporal effects only.
The measurement pools the hold's frames, so it is compared with the model at the frames' mean metadata
(a temperature drifting inside the hold changes the dark-current noise from frame to frame); a change of the
camera's noise inside the hold cuts the window at it, and so does a step of the light (:mod:`.noise_change`).

A live driver's auto-exposure and auto-gain move a little from frame to frame even when the camera looks at a
still scene. The frames of a still camera stay one scene seen through another gain: each frame is the hold's
mean scaled about the black level (exposure and gain scale photo and dark signal alike), which is the light change
taken out before the differences; only the noise changes with the frame. So the hold follows such drift (each frame
within ``VIEW_STEP_GAIN_DB`` / ``VIEW_STEP_EXPOSURE_REL`` of the previous one: a larger step is a new view) and the
frames measured together are the latest whose gains span at most ``DRIFT_GAIN_DB`` and exposures a ratio of at most
``1 + DRIFT_EXPOSURE_REL`` (temperatures ``TEMPERATURE_TOL_C``): across such a window the model at the mean metadata
is the frames' mean noise variance to within 0.7 % (its read noise goes with the square of the gain).
"""
from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from noise_monitor.measure import block_temporal, global_shift
from noise_monitor.measure.temporal import HOLD_SHIFT_PX
from noise_monitor.physics import CameraMetadata

from .noise_change import Level, LevelReference, ModelAt, change_point, light_step

#: edge (px) of the downsampled frame the global motion is estimated on
MOTION_SIZE_PX = 256
#: metadata drift tolerated inside one hold of constant gain and exposure (``StillCamera(drift=False)``)
GAIN_TOL_DB, EXPOSURE_TOL_REL, TEMPERATURE_TOL_C = 0.05, 0.01, 3.0
#: the spread of gain (dB) and exposure (relative) of the frames measured together while auto-exposure drifts
DRIFT_GAIN_DB, DRIFT_EXPOSURE_REL = 1.0, 0.25
#: A new view starts when the gain moves by more than this (dB) or the exposure by more than this fraction
#: from one processed frame to the next (an auto-exposure step; slow drifts stay one view): the alarm's filter and
#: evidence restart, and so does the hold (frames of the previous view would lag the measurement behind the step)
VIEW_STEP_GAIN_DB, VIEW_STEP_EXPOSURE_REL = 0.5, 0.05
BLOCK = 8
#: the patches' mean (DN above black) below which a frame's light is not read (its shot noise is negligible and
#: its mean is noise): a window holding such a frame is not cut at a step of the light
MIN_LIGHT_DN = 1.0
#: once the window holds ``max_frames`` frames (a long still hold), it is measured every this many frames and the
#: last measurement stands between (adding one frame to 16 changes it little; on a still, textured 1280x1024 scene the
#: measurement took half of each frame's time and the node fell below 30 frames/s)
FULL_WINDOW_STRIDE = 4


@dataclass(frozen=True)
class TemporalMeasurement:
    """Per patch of the hold: temporal sigma (NaN without accepted blocks) and its standard error."""

    corners: list[tuple[int, int]]
    size: int
    sigma_dn: np.ndarray
    err_dn: np.ndarray
    mean_patches: np.ndarray  # (K, size, size) temporal mean of the hold: the scene without temporal noise
    frames: int
    accepted_fraction: float
    accepted: np.ndarray  # (K, (size // BLOCK)^2) the blocks measured, row-major in each patch
    motion_px: float  # the camera's rms displacement about the hold's mean pose (px): its vibration
    meta: CameraMetadata  # the measured frames' mean metadata (what the model is evaluated at)
    light_pct: float = 0.0  # the light's change from frame to frame taken out (rms over frames and rows, %)
    latest_patches: np.ndarray | None = None  # (K, size, size) the newest frame's patches
    light_rows: bool = False  # that change fitted row by row (LEDs dimmed by pulse-width modulation)


def _same_conditions(a: CameraMetadata, b: CameraMetadata, temperature_tol_c: float = TEMPERATURE_TOL_C,
                     gain_tol_db: float = GAIN_TOL_DB, exposure_tol_rel: float = EXPOSURE_TOL_REL) -> bool:
    """Whether ``b`` is the camera of ``a`` with gain, exposure and temperature within the tolerances."""
    return (a.replace(gain_db=0.0, exposure_time_s=1.0, sensor_temperature_c=0.0)
            == b.replace(gain_db=0.0, exposure_time_s=1.0, sensor_temperature_c=0.0)
            and abs(a.gain_db - b.gain_db) <= gain_tol_db
            and max(a.exposure_time_s, b.exposure_time_s) <= (1.0 + exposure_tol_rel) * min(a.exposure_time_s,
                                                                                            b.exposure_time_s)
            and abs(a.sensor_temperature_c - b.sensor_temperature_c) <= temperature_tol_c)


def _within_drift(metas: Sequence[CameraMetadata]) -> bool:
    """Whether frames of these metadata may be measured together while the gain and exposure drift."""
    gains, exposures, temperatures = ([getattr(m, f) for m in metas]
                                      for f in ("gain_db", "exposure_time_s", "sensor_temperature_c"))
    return (max(gains) - min(gains) <= DRIFT_GAIN_DB
            and max(exposures) <= (1.0 + DRIFT_EXPOSURE_REL) * min(exposures)
            and max(temperatures) - min(temperatures) <= TEMPERATURE_TOL_C)


class StillCamera:
    """Whether each frame continues a static hold: the conditions of the hold's first frame (within the
    tolerances above; the temperature's within ``temperature_tol_c``) and a global shift from the hold's first
    frame within ``HOLD_SHIFT_PX`` (a vibrating camera stays about its pose; a pan or a drift leaves it).
    ``drift``: the gain and exposure may drift through the hold, each frame's within ``VIEW_STEP_GAIN_DB`` /
    ``VIEW_STEP_EXPOSURE_REL`` of the previous frame's (a live driver's auto-exposure hunting; a larger step is a new
    view)."""

    def __init__(self, temperature_tol_c: float = TEMPERATURE_TOL_C, drift: bool = False) -> None:
        self.temperature_tol_c = temperature_tol_c
        self.drift = drift
        self.hold_meta: CameraMetadata | None = None  # the current hold's first frame's metadata (drift: the latest)
        self._ref: np.ndarray | None = None  # the hold's first frame, downsampled
        self._latest: np.ndarray | None = None
        self._scale = 1.0

    def reset(self) -> None:
        self.hold_meta, self._ref, self._latest = None, None, None

    def restart(self, meta: CameraMetadata) -> None:
        """The latest frame starts the next hold (whatever :meth:`continues` said: e.g. another image size)."""
        self.hold_meta, self._ref = meta, self._latest

    def _motion_image(self, image: np.ndarray) -> np.ndarray:
        h, w = image.shape
        self._scale = max(1.0, max(h, w) / MOTION_SIZE_PX)
        size = (max(8, round(w / self._scale)), max(8, round(h / self._scale)))
        return cv2.resize(np.asarray(image, dtype=np.float32), size, interpolation=cv2.INTER_AREA)  # no copy

    def continues(self, image: np.ndarray, meta: CameraMetadata) -> bool:
        """Whether this frame continues the current hold; one that does not starts the next hold."""
        self._latest = small = self._motion_image(image)
        still = False
        tolerances = (VIEW_STEP_GAIN_DB, VIEW_STEP_EXPOSURE_REL) if self.drift else (GAIN_TOL_DB, EXPOSURE_TOL_REL)
        if self._ref is not None and self._ref.shape == small.shape and self.hold_meta is not None \
                and _same_conditions(self.hold_meta, meta, self.temperature_tol_c, *tolerances):
            dx, dy, _ = global_shift(self._ref, small)
            still = math.hypot(dx, dy) * self._scale <= HOLD_SHIFT_PX
        if not still:
            self.restart(meta)
        elif self.drift:
            self.hold_meta = meta
        return still


@dataclass(frozen=True)
class _Held:
    """A frame of the hold: its patches, metadata and noise level (None before the hold's first measurement)."""

    patches: np.ndarray  # (K, s, s)
    meta: CameraMetadata
    level: Level | None
    light: float  # log of the patches' mean over the exposure and linear gain (the light; NaN in the dark)


class TemporalNoise:
    """Collects the patches of a static hold and measures their temporal noise (see module docstring).

    ``model``: for a measurement's temporal mean (K, s, s) and accepted blocks (K, N), the model's temporal sigma
    of those blocks as a function of the metadata; with it, a change of the camera's noise of at least
    ``change_dn`` (sigma, DN) inside the hold cuts the window at the change (:mod:`.noise_change`)."""

    def __init__(self, max_frames: int, min_frames: int,
                 model: Callable[[np.ndarray, np.ndarray], ModelAt] | None = None, change_dn: float = math.inf) -> None:
        self.max_frames, self.min_frames = max_frames, min_frames
        self.model, self.change_dn = model, change_dn
        self._frames: deque[_Held] = deque(maxlen=max_frames)
        self._corners: list[tuple[int, int]] = []
        self._size = 0
        self._still = StillCamera(drift=True)
        self.holds = 0  # static holds started (resets)
        self.changes = 0  # changes of the noise that cut a hold's window
        self.light_steps = 0  # steps of the light that cut a hold's window
        self._last: TemporalMeasurement | None = None  # the hold's latest measurement
        self._since = 0  # frames added since it
        self._reference: LevelReference | None = None  # what the frames' noise levels are read on
        self._reference_age = 0  # frames added since it was made

    def reset(self) -> None:
        self._frames.clear()
        self._corners = []
        self._last = self._reference = None
        self._still.reset()

    def _static(self, image: np.ndarray, meta: CameraMetadata, size: int) -> bool:
        """Whether this frame continues the current hold (and updates the motion reference); a new patch size
        starts a new hold."""
        if self._still.continues(image, meta) and size == self._size:
            return True
        self._still.restart(meta)
        return False

    def update(self, image: np.ndarray, meta: CameraMetadata, corners: list[tuple[int, int]],
               size: int) -> TemporalMeasurement | None:
        """Add a frame (its chosen patch corners start a new hold); the hold's measurement once it has
        ``min_frames`` frames, else None."""
        if self.max_frames < 2:
            return None
        if not self._static(image, meta, size):
            self._frames.clear()
            self._corners, self._size = list(corners), size
            self._last = self._reference = None
            self.holds += 1
        if not self._corners:
            return None
        latest = np.stack([image[y:y + size, x:x + size] for y, x in self._corners]).astype(np.float32)
        level = None
        if self._reference is not None and self._frames:
            previous = self._frames[-1]
            level = self._reference.level(latest, previous.patches, meta, previous.meta)
        self._frames.append(_Held(latest, meta, level, _light(latest, meta)))
        self._reference_age += 1
        while not _within_drift([f.meta for f in self._frames]):  # auto-exposure drifted: the oldest frames leave
            self._frames.popleft()
        stepped = light_step(np.array([f.light for f in self._frames]))
        if stepped and len(self._frames) - stepped >= max(2, self.min_frames):
            # the light stepped and its new window can be measured (until then the pooled one serves): the frames
            # before leave, and the levels are read again at the new light
            for _ in range(stepped):
                self._frames.popleft()
            for i, f in enumerate(self._frames):
                self._frames[i] = dataclasses.replace(f, level=None)
            self._last = self._reference = None
            self.light_steps += 1
        elif level is not None and not stepped:  # (levels read across a step of the light are not the noise's)
            cut = change_point([f.level for f in self._frames], self.change_dn)
            if cut:  # the noise changed: the frames before the change leave the window
                for _ in range(cut):
                    self._frames.popleft()
                # the first frame's level was read on its difference with the frame before the change
                self._frames[0] = dataclasses.replace(self._frames[0], level=None)
                self._last, self.changes = None, self.changes + 1
        k = len(self._frames)
        if k < max(2, self.min_frames):
            self._last = None
            return None
        self._since += 1
        if self._last is not None and k == self.max_frames and self._since < FULL_WINDOW_STRIDE:
            return dataclasses.replace(self._last, latest_patches=latest)
        self._last, self._since = self._measure(k), 0
        if self.model is not None and (self._reference is None or k >= 2 * self._reference.frames
                                       or self._reference_age >= self.max_frames):
            tm, first = self._last, self._reference is None
            self._reference = LevelReference.of(tm.mean_patches, tm.accepted, k, BLOCK,
                                                self.model(tm.mean_patches, tm.accepted), tm.light_rows)
            self._reference_age = 0
            if first and self._reference is not None:  # the hold's frames so far: a change right after them shows
                self._read_levels(self._reference)
        return self._last

    def _read_levels(self, reference: LevelReference) -> None:
        """The noise levels of the window's frames that have none, each on its difference with the frame before."""
        frames = self._frames
        for i in range(1, len(frames)):
            if frames[i].level is None:
                previous = frames[i - 1]
                frames[i] = dataclasses.replace(frames[i], level=reference.level(frames[i].patches, previous.patches,
                                                                                frames[i].meta, previous.meta))

    def _measure(self, k: int) -> TemporalMeasurement:
        """The measurement of the window's ``k`` frames."""
        size = self._size
        n_patches = len(self._corners)
        frames = np.stack([f.patches for f in self._frames])  # (k, K, s, s)
        stats = block_temporal(frames.reshape(k, n_patches * size, size), BLOCK, view_rows=size, row_light=True)
        per_patch = (size // BLOCK) ** 2
        acc = stats.accepted.reshape(n_patches, per_patch)
        var = stats.variance_dn2.reshape(n_patches, per_patch)
        err = stats.variance_err_dn2.reshape(n_patches, per_patch)
        n_acc = acc.sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            v = np.where(acc, var, 0.0).sum(axis=1) / n_acc
            v_err = np.sqrt(np.where(acc, err**2, 0.0).sum(axis=1)) / n_acc
            sigma = np.sqrt(np.maximum(v, 0.0))
            sigma_err = v_err / (2.0 * np.maximum(sigma, 1e-6))
        return TemporalMeasurement(list(self._corners), size, sigma, sigma_err, frames.mean(axis=0), k,
                                   float(stats.accepted.mean()), acc, stats.motion_px, mean_metadata(f.meta for f in self._frames),
                                   stats.light_pct, frames[-1], light_rows=stats.light_rows)


def _light(patches: np.ndarray, meta: CameraMetadata) -> float:
    """Log of the patches' mean (DN above black) over the exposure and linear gain: the light, up to a constant;
    NaN below ``MIN_LIGHT_DN``."""
    mean = float(patches.mean())
    return math.log(mean / (meta.exposure_time_s * meta.gain)) if mean >= MIN_LIGHT_DN else math.nan


def mean_metadata(metas: Iterable[CameraMetadata]) -> CameraMetadata:
    """The metadata of a hold's frames averaged over its operating conditions (gain, exposure, temperature)."""
    ms = list(metas)
    return ms[-1].replace(**{f: float(np.mean([getattr(m, f) for m in ms]))
                             for f in ("gain_db", "exposure_time_s", "sensor_temperature_c")})
