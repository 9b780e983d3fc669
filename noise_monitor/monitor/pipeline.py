"""The per-frame pipeline shared by the live node and the bag replay.

patches -> estimator (batched) -> physics model for the same patches -> median per frame ->
exponential filter -> xi alarm state machine -> StatusReport / numeric outputs. A metadata step (gain or
exposure: a new view) restarts the filter (no lag of the previous view's xi) and the alarm's count; the alarm's
evidence, a sum over frames of their own xi beyond the threshold, carries on.
"""
from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from typing import Any, Protocol

import cv2
import numpy as np

from noise_monitor.estimator.inference import clear_decisions
from noise_monitor.measure.temporal import blocks_of
from noise_monitor.physics import CameraMetadata, EffectError, NoiseModel
from noise_monitor.physics.constants import PAPER_EFFECTS as SOURCES
from noise_monitor.physics.constants import SMOOTH_KERNEL

from .alarm import EmaFilter, XiAlarm
from .black_level import BlackLevelCheck, check_black_level
from .config import MonitorConfig
from .frame import Frame
from .frame import skip_reason as frame_skip_reason
from .model_patches import histogram_weights, level_positions, predict_levels, predict_patches, predict_total
from .noise_change import ModelAt
from .patches import PatchSelection, select_patches
from .status import ERROR, HOLD_EVENT_SEPARATOR, HOLD_EVENTS, OK, STALE, WARN, XI_MEASUREMENTS, StatusReport
from .temporal import BLOCK as TEMPORAL_BLOCK
from .temporal import VIEW_STEP_EXPOSURE_REL, VIEW_STEP_GAIN_DB, TemporalMeasurement, TemporalNoise

#: The skip reason of an image whose header stamp equals the previous image's: it would enter a still hold's frame
#: differences as a second frame with the same noise (duplicates read sigma_temporal 5 % low in a bag audit).
DUPLICATE_STAMP = ("duplicate image: the same header stamp as the previous image (a frame published or recorded "
                   "twice, or a driver that does not stamp its images)")
#: MonitorConfig fields that may change while the monitor runs (thresholds, alarm and filter settings).
RUNTIME_SETTABLE = ("xi_threshold_dn", "xi_hysteresis_dn", "alarm_min_frames", "alarm_evidence", "clear_min_frames",
                    "filter_alpha", "alarm_level")
#: Floor of a frame's xi standard error (DN): the model's own approximation of the simulated or real sensor
#: (the temporal measurement's statistical error alone can be a few hundredths of a DN).
XI_ERROR_FLOOR_DN = 0.05

ESTIMATOR_KEYS = SOURCES + ("total", "xi")


def patch_weights(est: dict[str, np.ndarray], use: np.ndarray) -> np.ndarray | None:
    """Weights of the used patches in the frame's medians of the measurement (sigma_image, xi): 1 / predicted
    error^2 (``sigma_image_error``, floored at ``XI_ERROR_FLOOR_DN`` so that no one patch takes the frame; a
    non-finite error weighs nothing), None (equal weights) without a predicted error or when no used patch has
    a finite one."""
    if "sigma_image_error" not in est:
        return None
    err = np.asarray(est["sigma_image_error"], dtype=np.float64).reshape(-1)[use]
    weights = np.where(np.isfinite(err), 1.0 / np.maximum(err, XI_ERROR_FLOOR_DN) ** 2, 0.0)
    return weights if weights.any() else None


def image_xi_error(est: dict[str, np.ndarray], use: np.ndarray, weights: np.ndarray | None, cap: float) -> float:
    """The standard error (DN) of a frame's single-image xi: the weighted median of its used patches' predicted
    errors (``sigma_image_error``; not divided by the root of their number: one scene's patches err alike),
    between ``XI_ERROR_FLOOR_DN`` and ``cap`` (``image_xi_error_dn``); ``cap`` without finite predicted errors."""
    if "sigma_image_error" not in est:
        return cap
    err = np.asarray(est["sigma_image_error"], dtype=np.float64).reshape(-1)[use]
    finite = np.isfinite(err)
    if not finite.any():
        return cap
    median = weighted_median(err[finite], None if weights is None else weights[finite])
    return float(min(max(median, XI_ERROR_FLOOR_DN), cap))


def weighted_median(values: np.ndarray, weights: np.ndarray | None) -> float:
    """The median of ``values``, weighted by ``weights`` (the lower weighted median), plain without weights."""
    if weights is None:
        return float(np.median(values))
    return float(np.quantile(values, 0.5, weights=weights, method="inverted_cdf"))


class Estimator(Protocol):
    """The estimator contract (``noise_monitor.estimator.load``)."""

    patch_size: int
    name: str

    def predict(self, patches_dn: np.ndarray, metas: CameraMetadata | list[CameraMetadata]) -> dict[str, np.ndarray]: ...


def _fmt(value: float) -> str:
    return f"{value:.6g}"


@dataclass
class FrameResult:
    """Outcome of one frame: estimates, model prediction, xi, alarm, and the status to publish."""

    stamp_ns: int
    name: str
    hardware_id: str
    level: int
    message: str
    processed: bool
    skip_reason: str | None = None
    sigma: dict[str, float] = field(default_factory=dict)  # estimator medians (DN): pn dcsn rn total xi image
    model: dict[str, float] = field(default_factory=dict)  # model medians (DN) per effect and total
    xi: float | None = None  # this frame's xi (per Monitor.xi_source)
    xi_filtered: float | None = None
    xi_model: float | None = None  # analytic sigma_model (this model, these patches) - estimated image noise
    xi_image: float | None = None  # the single-image measurement's xi (per Monitor.xi_source)
    xi_bound: float | None = None  # median over the patches of sigma_model - the image-only noise bound: xi >= it
    xi_bounded: bool = False  # no patch measurable or clear: the single image's xi is what the bound proves, max(xi_bound, 0)
    xi_temporal: float | None = None  # the model's temporal noise - the frame differences' (static holds)
    temporal_weight: float = 0.0  # share of xi_temporal in xi (inverse-variance weights)
    temporal_frames: int = 0  # frames of the current static hold measured
    temporal_motion_px: float | None = None  # the camera's vibration in that hold: rms displacement (px)
    temporal_light_pct: float | None = None  # the light's change in that hold (flicker, rolling-shutter bands), %
    hold_event: str | None = None  # why the hold's frame-difference measurement restarted here (HOLD_EVENTS)
    xi_error: float | None = None  # standard error of this frame's xi (DN): image, or fused with the temporal one
    alarm_evidence: float = 0.0  # the alarm's accumulated evidence (standard errors beyond the threshold)
    view_frames: int = 0  # processed frames of the current view (since the last gain / exposure step)
    filtered: dict[str, float] = field(default_factory=dict)
    alarm_active: bool = False
    alarm_state: str = "ok"
    cause: str | None = None
    patches: PatchSelection | None = None
    patch_xi: list[float] = field(default_factory=list)  # this frame's xi per patch (same source as ``xi``)
    patches_measurable: int | None = None  # patches the estimator could measure (None: no confidence output)
    processing_ms: float = 0.0
    black_level: BlackLevelCheck | None = None  # the stated black level against the image (None: none stated)
    counters: dict[str, int] = field(default_factory=dict)
    xi_threshold: float = 0.0  # the alarm threshold in force for this frame (DN; dashboards draw +-it around xi)

    def numeric(self) -> dict[str, float]:
        """Numbers of a processed frame (for plots, CSV and the numeric topics); empty when skipped."""
        if not self.processed:
            return {}
        assert self.xi is not None and self.xi_filtered is not None and self.xi_model is not None
        assert self.patches is not None  # processed frames carry all of them
        out = {f"sigma_{k}": self.sigma[k] for k in SOURCES + ("total",)}
        out["xi"] = float(self.xi)
        out["xi_filtered"] = float(self.xi_filtered)
        out["xi_estimator"] = self.sigma["xi"]
        out["sigma_image"] = self.sigma["image"]
        out["xi_model"] = float(self.xi_model)
        out["xi_image"] = float(self.xi_image if self.xi_image is not None else self.xi)
        if self.xi_bound is not None:
            out["xi_bound"] = float(self.xi_bound)
        if self.xi_temporal is not None:
            out["xi_temporal"] = float(self.xi_temporal)
            out["sigma_temporal"] = self.sigma["temporal"]
            if self.temporal_motion_px is not None:
                out["temporal_motion_px"] = float(self.temporal_motion_px)
            if self.temporal_light_pct is not None:
                out["temporal_light_pct"] = float(self.temporal_light_pct)
        out["temporal_weight"] = self.temporal_weight
        out["temporal_frames"] = float(self.temporal_frames)
        if self.xi_error is not None:
            out["xi_error"] = float(self.xi_error)
        out["alarm_evidence"] = float(self.alarm_evidence)
        out["view_frames"] = float(self.view_frames)
        out["sigma_model"] = self.model["total"]
        out.update({f"sigma_model_{k}": v for k, v in self.model.items() if k != "total"})
        out.update({f"sigma_{k}_filtered": self.filtered[k] for k in SOURCES + ("total",)})
        out["alarm"] = float(self.alarm_active)
        out["xi_threshold"] = float(self.xi_threshold)
        out["patches"] = float(len(self.patches.corners))
        if self.patches_measurable is not None:
            out["patches_measurable"] = float(self.patches_measurable)
        out["processing_ms"] = self.processing_ms
        if self.black_level is not None:
            out["black_level_dn"] = self.black_level.black_level_dn
            out["pixels_below_black_pct"] = self.black_level.below_pct
        return out

    def values(self) -> dict[str, str]:
        """Diagnostic key/values: numbers as numeric strings, plus the frame counters."""
        vals = {k: _fmt(v) for k, v in self.numeric().items()}
        if self.processed:
            vals["xi_measurement"] = self.xi_measurement
        if self.hold_event:
            vals["hold_event"] = self.hold_event
        vals.update({k: str(v) for k, v in self.counters.items()})
        return vals

    @property
    def xi_measurement(self) -> str:
        """Which measurement drove xi: the frame differences of a static hold (``temporal``), the single
        image's reading (``image``) or, where texture hides the noise in every patch, what the image proves
        (``bound``)."""
        image, temporal, bound = XI_MEASUREMENTS
        if self.temporal_weight >= 0.5:
            return temporal
        return bound if self.xi_bounded else image

    def report(self) -> StatusReport:
        return StatusReport(self.level, self.name, self.message, self.hardware_id, self.values())


class Monitor:
    """Stateful per-camera monitor: call :meth:`process` per frame, :meth:`idle_report` from a timer."""

    def __init__(self, config: MonitorConfig, estimator: Estimator, model: NoiseModel, camera_name: str,
                 hardware_id: str) -> None:
        self.config = config
        self.estimator = estimator
        self.model = model
        self.name = f"noise_monitor: {camera_name}"
        self.hardware_id = hardware_id
        self.patch_size = config.patch_size or int(estimator.patch_size)
        # the estimator's xi knows the paper's sources only: with more effects in the model, compare to the model
        extra_effects = set(model.names) - set(SOURCES)
        self.xi_source = config.xi_source if config.xi_source != "auto" else ("model" if extra_effects else "estimator")
        self.filter = EmaFilter(config.filter_alpha)
        # frame differences hold the temporal noise only: compare them with the model's temporal effects
        fixed = [e for e in model.effects if not e.temporal]
        self.temporal_model = NoiseModel([e for e in model.effects if e.temporal], interpolate=model.interpolate) if fixed else model
        # a change of the noise by half the alarm threshold inside a static hold restarts its window
        self.temporal = TemporalNoise(config.temporal_frames, config.temporal_min_frames,
                                      lambda patches, accepted: self._temporal_model(patches, accepted, coarse=True),
                                      config.xi_threshold_dn / 2.0)
        self.alarm = XiAlarm(config.xi_threshold_dn, config.xi_hysteresis_dn, config.alarm_min_frames,
                             config.clear_min_frames, config.alarm_evidence)
        self._view_meta: CameraMetadata | None = None  # the previous processed frame's metadata
        self.view_frames = 0
        self.counters = {"frames_received": 0, "frames_processed": 0, "frames_skipped": 0, "frames_dropped": 0,
                         "frames_lost": 0, "stamp_intervals_implausible": 0, "temporal_noise_changes": 0,
                         "temporal_light_steps": 0}
        self.last_received_ns: int | None = None
        self._last_stamp_ns: int | None = None  # of the previous frame, evaluated or not
        self.last_result: FrameResult | None = None

    def reconfigure(self, **changes: Any) -> MonitorConfig:
        """Change settings of :data:`RUNTIME_SETTABLE` at run time, validated as a whole by MonitorConfig
        (ValueError with the reason); the alarm and the filter keep their state."""
        fixed = sorted(set(changes) - set(RUNTIME_SETTABLE))
        if fixed:
            raise ValueError(f"{', '.join(fixed)} cannot change at run time (settable: {', '.join(RUNTIME_SETTABLE)})")
        cfg = dataclasses.replace(self.config, **changes)
        self.config = cfg
        self.filter.alpha = cfg.filter_alpha
        self.alarm.threshold = cfg.xi_threshold_dn
        self.alarm.clear_level = cfg.xi_threshold_dn - cfg.xi_hysteresis_dn
        self.alarm.min_frames, self.alarm.clear_frames = cfg.alarm_min_frames, cfg.clear_min_frames
        self.alarm.evidence = cfg.alarm_evidence
        self.temporal.change_dn = cfg.xi_threshold_dn / 2.0
        return cfg

    # --- bookkeeping -----------------------------------------------------------------------
    def count_dropped(self, n: int = 1) -> None:
        """Frames the caller dropped before processing (e.g. the node's worker was busy)."""
        self.counters["frames_dropped"] += n

    def count_lost(self, n: int, implausible: int = 0) -> None:
        """Frames that never reached the caller (inferred from header-stamp gaps), and stamp intervals too
        short to be a camera's frame period (a bogus clock: reported, not counted as losses)."""
        self.counters["frames_lost"] += n
        self.counters["stamp_intervals_implausible"] += implausible

    def _result(self, frame: Frame, level: int, message: str, **kw: Any) -> FrameResult:
        res = FrameResult(frame.stamp_ns, self.name, self.hardware_id, level, message,
                          counters=dict(self.counters), xi_threshold=self.config.xi_threshold_dn, **kw)
        self.last_result = res
        return res

    def _skip(self, frame: Frame, reason: str) -> FrameResult:
        self.counters["frames_skipped"] += 1
        level, message = WARN, f"frame not evaluated: {reason}"
        state = self.alarm.state
        if state.active:
            level = max(level, self._alarm_level())
            message += f"; xi alarm still active: {state.cause}"
        return self._result(frame, level, message, processed=False, skip_reason=reason,
                            alarm_active=state.active, alarm_state=state.name, cause=state.cause)

    def reject(self, stamp_ns: int, reason: str, received_ns: int | None = None, counted: bool = False) -> FrameResult:
        """Count and report an input that never became a Frame (e.g. an unsupported image encoding), or one whose
        evaluation failed (``counted``: :meth:`process` had counted it)."""
        self.counters["frames_received"] += not counted
        self.last_received_ns = stamp_ns if received_ns is None else received_ns
        return self._skip(Frame(stamp_ns, None, None), reason)

    def _alarm_level(self) -> int:
        return ERROR if self.config.alarm_level == "ERROR" else WARN

    # --- the pipeline ----------------------------------------------------------------------
    def skip_reason(self, frame: Frame) -> str | None:
        """Why a frame cannot be evaluated (unusable image, metadata problems, too small), else None."""
        return frame_skip_reason(frame, self.config.metadata_timeout_s, self.patch_size)

    def process(self, frame: Frame, received_ns: int | None = None) -> FrameResult:
        """Evaluate one frame. ``received_ns``: arrival time on the clock used by :meth:`idle_report`
        (default: the frame stamp)."""
        t0 = time.perf_counter()
        self.counters["frames_received"] += 1
        self.last_received_ns = frame.stamp_ns if received_ns is None else received_ns
        duplicate, self._last_stamp_ns = frame.stamp_ns == self._last_stamp_ns, frame.stamp_ns
        reason = DUPLICATE_STAMP if duplicate else self.skip_reason(frame)
        if reason:
            return self._skip(frame, reason)
        cfg = self.config
        meta = frame.metadata
        assert meta is not None and frame.image_dn is not None  # skip_reason checked both
        selection = select_patches(frame.image_dn, self.patch_size, cfg, frame.black_level_dn)
        if len(selection.corners) < cfg.min_patches:
            return self._skip(frame, f"{len(selection.corners)} usable patches (need {cfg.min_patches}): "
                                     f"{selection.describe_rejections()}")
        patches = selection.extract(frame.image_dn)
        if frame.black_level_dn:  # the noise a pedestal keeps below black: read clipped, as the model clips it
            np.maximum(patches, 0.0, out=patches)
        est = self.estimator.predict(patches, meta)
        per_patch = {k: np.asarray(est[k], dtype=np.float64).reshape(-1) for k in ESTIMATOR_KEYS}
        bad = [k for k, v in per_patch.items() if not np.all(np.isfinite(v))]
        if bad:
            return self._skip(frame, f"estimator {self.estimator.name} returned NaN/inf for {', '.join(bad)}")
        smooth = np.stack([cv2.blur(p, (SMOOTH_KERNEL, SMOOTH_KERNEL)) for p in patches])
        try:
            model_pp = predict_patches(self.model, smooth, meta, cfg.model_mode)
        except EffectError as exc:  # e.g. a plug-in effect of the profile failing for this metadata
            return self._skip(frame, f"evaluation failed: {exc}")
        ok = np.asarray(est["measurable"], dtype=bool).reshape(-1) if "measurable" in est else np.ones(len(patches), bool)
        use, bounded_only = self._patches_to_use(est, ok)
        # the model's per-source sigmas are plain medians (the physics gives them at every patch's intensity:
        # weights would move them with the patch selection, not with the camera); the measurement and xi
        # rest on the patches it reads most precisely
        weights = patch_weights(est, use)
        sigma = {k: float(np.median(v[use])) for k, v in per_patch.items() if k != "xi"}
        sigma["xi"] = weighted_median(per_patch["xi"][use], weights)
        model = {k: float(np.median(v[use])) for k, v in model_pp.items()}
        # the estimator's measurement of the noise in the image (contract: total; Full-Meta: sigma_image)
        image_pp = np.asarray(est.get("sigma_image", est["total"]), dtype=np.float64).reshape(-1)
        sigma["image"] = weighted_median(image_pp[use], weights)
        xi_model = weighted_median((model_pp["total"] - image_pp)[use], weights)
        xi_image = sigma["xi"] if self.xi_source == "estimator" else xi_model
        xi_bound = self._xi_bound(est, per_patch["total"] if self.xi_source == "estimator" else model_pp["total"])
        bounded = False
        if xi_bound is not None and bounded_only:
            # texture hides the noise in every patch: the image proves only xi >= xi_bound (content adds
            # pixel-scale energy, never removes noise), so "image noisier" is left to the static holds
            bounded, xi_image = True, max(xi_bound, 0.0)
        # the bound is no measurement: its error stays the configured one
        err_i = cfg.image_xi_error_dn if bounded else image_xi_error(est, use, weights, cfg.image_xi_error_dn)
        xi, xi_t, weight, held, xi_err, motion, light = xi_image, None, 0.0, 0, err_i, None, None
        tm = self.temporal.update(frame.image_dn, meta, selection.corners, self.patch_size)
        changed = self.temporal.changes > self.counters["temporal_noise_changes"]
        light_stepped = self.temporal.light_steps > self.counters["temporal_light_steps"]
        self.counters["temporal_noise_changes"] = self.temporal.changes
        self.counters["temporal_light_steps"] = self.temporal.light_steps
        if tm is not None:
            held = tm.frames
            found = self._xi_temporal(tm, sigma, meta)
            if found is not None:
                xi_t, err_t = found
                motion, light = tm.motion_px, tm.light_pct
                w_t, w_i = 1.0 / max(err_t, 1e-3) ** 2, 1.0 / err_i**2
                weight = w_t / (w_t + w_i)
                xi = weight * xi_t + (1.0 - weight) * xi_image
                xi_err = 1.0 / np.sqrt(w_t + w_i)
        xi_err = max(float(xi_err), XI_ERROR_FLOOR_DN)
        patch_xi = per_patch["xi"] if self.xi_source == "estimator" else model_pp["total"] - image_pp
        if self._new_view(meta):
            self.filter.reset()
            self.alarm.restart()
        filtered = self.filter.update({**{k: sigma[k] for k in SOURCES + ("total",)}, "xi": xi})
        xi_f = filtered.pop("xi")
        state = self.alarm.update(xi_f, xi, xi_err)
        self.counters["frames_processed"] += 1
        level, message = self._status(xi, xi_f, meta)
        # every source but the signal's shot noise: what the image shows at black
        dark = math.sqrt(max(model["total"] ** 2 - model.get("pn", 0.0) ** 2, 0.0))
        black = check_black_level(frame.image_dn, frame.black_level_dn, dark, frame.black_level_source)
        if black is not None and black.contradicted:
            level, message = max(level, WARN), f"{message}; {black.message()}"
        if bounded and weight < 0.5:
            message += f"; no patch measurable (texture hides the noise): the image proves only xi >= {xi_bound:+.2f} DN"
        events = [e for e, happened in zip(HOLD_EVENTS, (changed, light_stepped)) if happened]
        for event in events:
            message += f"; the {event} inside the still view: its frame-difference measurement restarts here"
        return self._result(
            frame, level, message, processed=True, sigma=sigma, model=model, xi=xi, xi_filtered=xi_f,
            xi_model=xi_model, xi_image=xi_image, xi_bound=xi_bound, xi_bounded=bounded, xi_temporal=xi_t, temporal_weight=weight, temporal_frames=held,
            temporal_motion_px=motion, temporal_light_pct=light, hold_event=HOLD_EVENT_SEPARATOR.join(events) or None,
            xi_error=xi_err, alarm_evidence=state.evidence, view_frames=self.view_frames,
            filtered=filtered, alarm_active=state.active, alarm_state=state.name,
            cause=state.cause, patches=selection, patch_xi=[float(v) for v in patch_xi],
            patches_measurable=int(ok.sum()) if "measurable" in est else None, black_level=black,
            processing_ms=(time.perf_counter() - t0) * 1e3,
        )

    def _patches_to_use(self, est: dict[str, np.ndarray], ok: np.ndarray) -> tuple[np.ndarray, bool]:
        """(patches the frame's medians use, whether xi rests on the image-only bound alone).

        The patches the estimator can measure (its confidence output) and the declined ones whose own alarm
        decision is clear given their predicted error (``inference.clear_decisions``: a noisy patch read to
        0.6 DN with xi = -4 DN alarms whatever its error); without either, every patch (``patches_measurable``
        = 0 tells): the frame's median reading then decides when its alarm decision is clear given the median
        predicted error (a high noise level's larger error in DN); otherwise texture hides the noise: xi is
        what the image proves (:meth:`_xi_bound`)."""
        if "sigma_image_error" not in est or "sigma_image_upper" not in est:
            return (ok if ok.any() else np.ones_like(ok)), False
        patch = {k: np.asarray(est[k], dtype=np.float64).reshape(-1) for k in ("xi", "sigma_image_error", "sigma_image")}
        use = ok | clear_decisions(patch, self.config.xi_threshold_dn)
        if use.any():
            return use, False
        frame = {k: np.array([np.median(v)]) for k, v in patch.items()}
        return np.ones_like(ok), not bool(clear_decisions(frame, self.config.xi_threshold_dn)[0])

    @staticmethod
    def _xi_bound(est: dict[str, np.ndarray], sigma_model: np.ndarray) -> float | None:
        """Median over the patches of sigma_model - the estimator's image-only upper bound of the noise
        (``sigma_image_upper``): the frame's xi is at least this whatever the scene. None without a bound."""
        if "sigma_image_upper" not in est:
            return None
        lower = sigma_model - np.asarray(est["sigma_image_upper"], dtype=np.float64).reshape(-1)
        lower = lower[np.isfinite(lower)]  # a patch clipped everywhere has no bound
        return float(np.median(lower)) if lower.size else None

    def _new_view(self, meta: CameraMetadata) -> bool:
        """Whether this processed frame starts a new view: a gain or exposure step from the previous one."""
        prev, self._view_meta = self._view_meta, meta
        step = prev is None or (abs(meta.gain_db - prev.gain_db) > VIEW_STEP_GAIN_DB
                                or abs(meta.exposure_time_s - prev.exposure_time_s)
                                > VIEW_STEP_EXPOSURE_REL * prev.exposure_time_s)
        self.view_frames = 1 if step else self.view_frames + 1
        return step

    def _temporal_model(self, patches: np.ndarray, accepted: np.ndarray, coarse: bool = False) -> ModelAt:
        """The model's temporal noise (K,) over the ``accepted`` blocks (K, N) of ``patches`` (K, s, s; smoothed
        first) as a function of the metadata (NaN for a patch without accepted blocks). ``coarse``: each block at
        its mean intensity (for the ratios of one scene's noise between metadata sets: a table lookup per block)."""
        smooth = np.stack([cv2.blur(p, (SMOOTH_KERNEL, SMOOTH_KERNEL)) for p in patches])
        blocks = blocks_of(smooth, TEMPORAL_BLOCK)  # (patches, blocks, pixels)
        model, mode, n = self.temporal_model, self.config.model_mode, accepted.sum(axis=1)
        per_block: Callable[[CameraMetadata], np.ndarray]
        if coarse:
            per_block = partial(predict_levels, model, level_positions(blocks.mean(axis=2)), mode=mode)
        else:
            weights = histogram_weights(blocks.reshape(-1, TEMPORAL_BLOCK, TEMPORAL_BLOCK))
            per_block = partial(predict_total, model, weights, mode=mode)

        def at(meta: CameraMetadata) -> np.ndarray:
            var = np.sum(accepted * per_block(meta).reshape(blocks.shape[:2]) ** 2, axis=1)
            return np.sqrt(np.divide(var, n, out=np.full(var.shape, np.nan), where=n > 0))
        return at

    def _xi_temporal(self, tm: TemporalMeasurement, sigma: dict[str, float],
                     meta: CameraMetadata) -> tuple[float, float] | None:
        """(xi of the static hold's temporal measurement for the frame of ``meta``, its standard error), None
        without accepted blocks.

        The model is evaluated on the hold's temporal mean (the scene without its temporal noise) at the
        hold frames' mean metadata (the measurement pools those frames), on the blocks measured: where only
        some pass the pure-noise test (a vibrating camera keeps the flat ones) their intensities are not the
        patch's. When the frames' gain or exposure differ (a drifting auto-exposure), the camera's departure from
        the model is taken to scale with the noise: the pooled xi is scaled to this frame, by its own model on its
        own patches over the pooled model."""
        ok = np.isfinite(tm.sigma_dn)
        if not ok.any():
            return None
        acc = tm.accepted[ok]
        model_t = self._temporal_model(tm.mean_patches[ok], acc)(tm.meta)
        d = model_t - tm.sigma_dn[ok]
        if tm.latest_patches is not None and not (math.isclose(meta.gain_db, tm.meta.gain_db, abs_tol=1e-9) and
                                                  math.isclose(meta.exposure_time_s, tm.meta.exposure_time_s)):
            d = d * self._temporal_model(tm.latest_patches[ok], acc)(meta) / np.maximum(model_t, 1e-9)
        n = int(ok.sum())
        spread = float(np.std(d)) if n > 1 else 0.0
        err = 1.2533 * max(float(np.sqrt(np.mean(tm.err_dn[ok] ** 2))), spread) / np.sqrt(n)  # of a median
        sigma["temporal"] = float(np.median(tm.sigma_dn[ok]))
        return float(np.median(d)), err

    def _status(self, xi: float, xi_f: float, meta: CameraMetadata) -> tuple[int, str]:
        cfg, state = self.config, self.alarm.state
        detail = f"xi {xi:+.2f} DN, filtered {xi_f:+.2f} DN, threshold {cfg.xi_threshold_dn:g} DN"
        outside = meta.outside_paper_ranges()
        ranges = f"metadata outside the estimator's training ranges: {', '.join(outside)}"
        if state.active:  # an alarm at such metadata says so: the estimate behind it is an extrapolation
            return self._alarm_level(), f"xi alarm: {state.cause} ({detail}){'; ' + ranges if outside else ''}"
        if outside:
            return WARN, f"{ranges} ({detail})"
        if state.name == "pending":
            return OK, (f"noise matches the model so far; |xi| above threshold for {state.above} frame(s), evidence "
                        f"{state.evidence:.1f} of {cfg.alarm_evidence:g} ({detail})")
        return OK, f"noise matches the model ({detail})"

    def clock_jumped(self, now_ns: int) -> None:
        """The caller's clock jumped (sim time started or looped): the last image counts as received now."""
        if self.last_received_ns is not None:
            self.last_received_ns = now_ns

    def idle_report(self, now_ns: int) -> StatusReport:
        """Status when no new frame was processed: STALE after ``image_timeout_s`` without images,
        otherwise the last frame's status (OK while the first frame received is still being evaluated)."""
        timeout = self.config.image_timeout_s
        if self.last_received_ns is None:
            return StatusReport(STALE, self.name, "no image received yet", self.hardware_id, dict(
                {k: str(v) for k, v in self.counters.items()}))
        age = (now_ns - self.last_received_ns) / 1e9
        values = {**{k: str(v) for k, v in self.counters.items()}, "image_age_s": _fmt(age)}
        if age > timeout:
            return StatusReport(STALE, self.name, f"no image for {age:.1f} s (timeout {timeout:g} s)",
                                self.hardware_id, values)
        if self.last_result is None:  # until 2026-12-04 STALE, "no image for 0.3 s (timeout 2 s)"
            return StatusReport(OK, self.name, f"image received {age:.1f} s ago, its evaluation not finished yet",
                                self.hardware_id, values)
        return self.last_result.report()
