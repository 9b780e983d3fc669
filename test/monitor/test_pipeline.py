"""Monitor pipeline: patch selection, filter + alarm state machine, staleness, outputs.

The estimator here is a test double honouring the estimator contract, built from the real physics
model (Immerkaer's noise estimate of each patch, split into sources by the model's proportions), so
the aggregation and alarm logic is tested independently of the trained network (test_node*.py uses
the real ``noise_monitor.estimator.load``).
"""
from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from msg_adapters import ERROR, OK, STALE, WARN, reports_from_msg
from msg_adapters.outputs import HOLD_KEYS, OUTPUT_TOPICS, number_of, output_topics, rclpy_messages, rosbags_messages
from noise_monitor.monitor import (
    CAUSE_IMAGE_NOISIER,
    CAUSE_MODEL_NOISIER,
    Frame,
    Monitor,
    MonitorConfig,
    XiAlarm,
    select_patches,
)
from noise_monitor.physics import NoiseModel, load_profile

_LAPLACE = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)
MODEL = NoiseModel()
META = load_profile("icx285").metadata(gain_db=18.0, exposure_time_s=0.01, sensor_temperature_c=40.0)


class PhysicsSplitEstimator:
    """Contract-compatible estimator: measured total noise split by the physics model's proportions."""

    patch_size = 64
    name = "physics-split (test double)"

    def predict(self, patches_dn: np.ndarray, metas) -> dict[str, np.ndarray]:
        measured = np.array([
            np.sqrt(np.pi / 2) / 6 * np.abs(cv2.filter2D(p, -1, _LAPLACE)[1:-1, 1:-1]).mean() for p in patches_dn
        ])
        pred = MODEL.predict(np.stack([cv2.blur(p, (5, 5)) for p in patches_dn]), metas)
        out = {k: pred[k] * measured / pred["total"] for k in ("pn", "dcsn", "rn")}
        return {**out, "total": measured, "xi": pred["total"] - measured}


def scene(h: int = 256, w: int = 256) -> np.ndarray:
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    return (120 + 60 * np.sin(2 * np.pi * x / w) * np.cos(1.4 * np.pi * y / h) + 20 * x / w).astype(np.float32)


def mono8(img: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(img), 0, 255).astype(np.float32)


def make_monitor(**cfg) -> Monitor:
    return Monitor(MonitorConfig(**cfg), PhysicsSplitEstimator(), MODEL, "cam", "icx285/cam")


def frames(rng, n, meta=META, extra_sigma=0.0, start=0):
    clean = scene()
    for i in range(start, start + n):
        noisy, truth = MODEL.simulate(clean, meta, rng)
        if extra_sigma:
            noisy = noisy + rng.normal(0.0, extra_sigma, noisy.shape).astype(np.float32)
        yield Frame(i * 33_000_000, mono8(noisy), meta), truth


# --- configuration -------------------------------------------------------------------------
def test_config_validation_and_yaml():
    cfg = MonitorConfig.from_yaml()  # the package's config/node.yaml
    assert cfg == MonitorConfig()  # the shipped file states the defaults
    with pytest.raises(ValueError, match="xi_hysteresis_dn"):
        MonitorConfig(xi_threshold_dn=1.0, xi_hysteresis_dn=1.5)
    with pytest.raises(ValueError, match="unknown monitor setting.*patchez"):
        MonitorConfig.from_mapping({"patchez": 3})
    with pytest.raises(ValueError, match="patches_per_frame must be an integer"):
        MonitorConfig(patches_per_frame=2.5)
    with pytest.raises(ValueError, match="xi_source"):
        MonitorConfig(xi_source="magic")
    with pytest.raises(ValueError, match="temporal_min_frames must be <= temporal_frames"):
        MonitorConfig(temporal_frames=8, temporal_min_frames=10)  # before: no temporal measurement, silently
    assert MonitorConfig(temporal_frames=0, temporal_min_frames=10).temporal_frames == 0  # off: nothing to compare


# --- patch selection -----------------------------------------------------------------------
def test_patches_avoid_saturated_black_and_flat_regions_and_spread(rng):
    img = mono8(scene(512, 512) + rng.normal(0, 2.0, (512, 512)))
    img[:128, :] = 255.0  # saturated band
    img[384:, :256] = 0.0  # black corner
    img[384:, 256:] = 200.0  # flat plateau (clipped below 255)
    cfg = MonitorConfig(patches_per_frame=6)
    sel = select_patches(img, 64, cfg)
    assert len(sel.corners) == 6
    assert sel.rejected["saturated"] >= 16 and sel.rejected["black"] >= 8 and sel.rejected["flat"] >= 8
    for y, x in sel.corners:
        patch = img[y : y + 64, x : x + 64]
        assert 128 <= y and y + 64 <= 384 and 0 < patch.min() and patch.max() < 255
    pts = np.array(sel.corners, float)
    dists = np.linalg.norm(pts[:, None] - pts[None], axis=-1)[np.triu_indices(6, 1)]
    assert dists.min() >= 64  # no two chosen patches overlap
    assert np.ptp(pts[:, 1]) >= 256  # they spread across the frame's width


def test_patches_prefer_smooth_regions(rng):
    img = mono8(np.full((256, 512), 120.0) + rng.normal(0, 2.0, (256, 512)))
    img[:, 256:] += np.where((np.arange(256) // 4) % 2 == 0, 40.0, -40.0)[None, :]  # stripes on the right
    sel = select_patches(img, 64, MonitorConfig(patches_per_frame=4, smooth_fraction=0.5))
    assert all(x + 64 <= 256 for _, x in sel.corners)


def test_no_usable_patches_is_a_warning_naming_the_reason():
    mon = make_monitor()
    res = mon.process(Frame(0, np.full((256, 256), 255.0, np.float32), META))
    assert res.level == WARN and not res.processed and "saturated" in res.message
    assert res.numeric() == {}


def test_an_image_with_the_previous_ones_stamp_is_skipped_as_a_duplicate(rng):
    """A frame published or recorded twice would enter a still hold's frame differences as a second frame with the
    same noise (sigma_temporal 5 % low in a bag audit, 2026-12-04); a driver that does not stamp its images is told."""
    from noise_monitor.monitor.pipeline import DUPLICATE_STAMP

    mon = make_monitor()
    image = mono8(MODEL.simulate(scene(), META, rng)[0])
    first, again, later = (mon.process(Frame(s, image, META)) for s in (5, 5, 6))
    assert first.processed and later.processed
    assert not again.processed and again.skip_reason == DUPLICATE_STAMP and again.level == WARN
    assert mon.counters["frames_skipped"] == 1 and mon.counters["frames_received"] == 3


def test_an_alarm_at_metadata_outside_the_training_ranges_says_so(rng):
    """Until 2026-12-04 the alarm's message replaced the training-range warning: an alarm raised on an extrapolated
    estimate (gain 30 dB, beyond the estimator's training) read like any other."""
    hot = replace(META, gain_db=30.0)
    calm = make_monitor().process(next(frames(rng, 1, meta=hot))[0])
    assert calm.level == WARN and calm.message.startswith("metadata outside the estimator's training ranges: gain_db")
    mon = make_monitor()
    results = [mon.process(frame) for frame, _ in frames(rng, 12, meta=hot, extra_sigma=8.0)]
    alarmed = [r for r in results if r.message.startswith("xi alarm")]
    assert alarmed and all(r.message.endswith("; metadata outside the estimator's training ranges: gain_db")
                           for r in alarmed)


# --- alarm state machine -------------------------------------------------------------------
def test_alarm_needs_min_frames_and_clears_with_hysteresis():
    alarm = XiAlarm(threshold=1.0, hysteresis=0.3, min_frames=3, clear_frames=2)
    states = [alarm.update(x).name for x in (1.5, 1.5, 0.5, 1.5, 1.5, 1.5)]
    assert states == ["pending", "pending", "ok", "pending", "pending", "alarm"]
    assert alarm.state.cause == CAUSE_MODEL_NOISIER
    # between clear level (0.7) and threshold: stays active (no flapping)
    assert [alarm.update(x).active for x in (0.9, 0.8, 0.95, 0.9)] == [True] * 4
    assert alarm.update(-1.6).cause == CAUSE_IMAGE_NOISIER  # sign change updates the cause
    assert [alarm.update(x).active for x in (0.5, 0.2)] == [True, False]
    assert alarm.state.episodes == 1 and alarm.state.cause is None


def test_alarm_does_not_flap_on_noisy_xi_near_threshold(rng):
    mon = make_monitor()
    alarm = XiAlarm(1.0, 0.3, 5, 10)
    xi = 0.6 + rng.normal(0.0, 0.5, 400)  # frame-level xi scattering across the threshold
    xf = mon.filter.update({"xi": xi[0]})["xi"]
    active = []
    for v in xi:
        xf = mon.filter.update({"xi": float(v)})["xi"]
        active.append(alarm.update(xf).active)
    assert sum(np.diff(np.asarray(active, int)) != 0) <= 2


def test_alarm_evidence_raises_a_short_view_and_ignores_a_bias_inside_the_threshold(rng):
    """The CUSUM raises where the count rule (5 frames) cannot: a 2-frame view far beyond the threshold, a
    3-frame view just beyond it; a xi biased to 0.9 DN with per-frame scatter never raises."""
    far = XiAlarm(1.0, 0.3, 5, 10, evidence=3.0)
    assert [far.update(-1.5, xi=-2.1, error=0.3).active for _ in range(2)] == [True, True]  # (2.1 - 1) / 0.3 >= 3
    assert far.state.cause == CAUSE_IMAGE_NOISIER
    near = XiAlarm(1.0, 0.3, 5, 10, evidence=3.0)
    assert [near.update(-1.1, xi=-1.35, error=0.3).name for _ in range(3)] == ["pending", "pending", "alarm"]
    count_only = XiAlarm(1.0, 0.3, 5, 10)  # the old rule: 5 consecutive filtered frames
    assert not any(count_only.update(-1.1, xi=-1.35, error=0.3).active for _ in range(4))
    biased = XiAlarm(1.0, 0.3, 5, 10, evidence=3.0)
    xi = 0.9 + rng.normal(0.0, 0.1, 2000)
    xf = 0.9
    for v in xi:
        xf += 0.3 * (v - xf)
        assert not biased.update(xf, xi=float(v), error=0.3).active
    # a new view (restart) keeps the evidence: a sweep of 2-frame views just beyond the threshold raises ...
    swept = XiAlarm(1.0, 0.3, 5, 10, evidence=3.0)
    for _ in range(2):
        swept.update(1.2, xi=1.4, error=0.3)  # 2 x 1.33: pending
    swept.restart()
    assert swept.update(1.2, xi=1.4, error=0.3).name == "alarm"
    # ... and only on a frame whose own xi is beyond it: a view inside the threshold drains it
    drained = XiAlarm(1.0, 0.3, 5, 10, evidence=3.0)
    for _ in range(2):
        drained.update(1.2, xi=1.4, error=0.3)
    drained.restart()
    assert [drained.update(0.95, xi=0.95, error=0.3).name for _ in range(3)] == ["pending"] * 3
    assert drained.state.evidence == pytest.approx(2 * 0.4 / 0.3 - 3 * 0.05 / 0.3)


def test_a_metadata_step_starts_a_new_view_judged_on_its_own_frames(rng):
    """Clean view at 12 dB, then a view at true 24 dB stated 18 dB (6 dB low): the filter restarts at the step
    (no carry-over of the previous view's xi) and the alarm rises within 2 frames of the new view; the count
    rule alone (alarm_evidence 0) needs 5."""
    low = META.replace(gain_db=12.0)
    for cfg, within in (({}, 2), ({"alarm_evidence": 0.0}, 5)):
        mon = make_monitor(**cfg)
        for frame, _ in frames(rng, 6, meta=low):
            assert not mon.process(frame).alarm_active
        true_meta = META.replace(gain_db=24.0)
        for n, (frame, _) in enumerate(frames(rng, 8, meta=true_meta, start=6), 1):
            frame.metadata = META.replace(gain_db=18.0)
            res = mon.process(frame)
            assert res.view_frames == n
            if n == 1:
                assert res.xi_filtered == res.xi < -1.5  # restarted: the previous view's xi ~0 is not carried
            if res.alarm_active:
                break
        assert res.alarm_active and n <= within and res.cause == CAUSE_IMAGE_NOISIER, (cfg, n)


# --- the pipeline on simulated frames ------------------------------------------------------
def test_clean_frames_stay_ok_and_sigmas_track_truth(rng):
    mon = make_monitor()
    for frame, truth in frames(rng, 40):
        res = mon.process(frame)
        assert res.level == OK and not res.alarm_active, res.message
    for k in ("pn", "rn", "total"):
        assert res.filtered[k] == pytest.approx(truth[k], rel=0.1)
    assert abs(res.xi_filtered) < 0.5
    assert res.counters["frames_processed"] == 40
    vals = res.report().values
    assert float(vals["sigma_rn"]) == pytest.approx(res.sigma["rn"], rel=1e-4)
    assert vals["frames_received"] == "40" and set(vals) >= {"sigma_pn", "sigma_dcsn", "xi", "sigma_model"}


def test_extra_image_noise_raises_image_noisier_alarm(rng):
    mon = make_monitor()
    for frame, _ in frames(rng, 10):
        mon.process(frame)
    for n, (frame, _) in enumerate(frames(rng, 20, extra_sigma=5.0, start=10), 1):
        res = mon.process(frame)
        if res.alarm_active:
            break
    assert res.alarm_active and n <= 10 and res.level == ERROR
    assert res.cause == CAUSE_IMAGE_NOISIER and CAUSE_IMAGE_NOISIER in res.message
    expected = res.model["total"] - np.sqrt(res.model["total"] ** 2 + 25.0)
    assert res.xi == pytest.approx(expected, abs=0.6)  # the frame's xi (the evidence raises before the filter settles)


def test_doubled_thermal_white_noise_metadata_raises_model_noisier_alarm(rng):
    mon = make_monitor()
    meta = META.replace(gain_db=24.0)  # readout noise is a visible share of the total at high gain
    wrong = meta.replace(thermal_white_noise_v_per_sqrt_hz=2 * meta.thermal_white_noise_v_per_sqrt_hz)
    for n, (frame, _) in enumerate(frames(rng, 20, meta=meta), 1):
        frame.metadata = wrong  # the image is generated with META, the metadata claims twice the noise
        res = mon.process(frame)
        if res.alarm_active:
            break
    assert res.alarm_active and n <= 10 and res.cause == CAUSE_MODEL_NOISIER and res.xi_filtered > 0


def test_metadata_missing_stale_invalid_give_warnings(rng):
    mon = make_monitor()
    img = next(frames(rng, 1))[0].image_dn
    res = mon.process(Frame(0, img, None, missing=["gain_db", "exposure_time_s"]))
    assert res.level == WARN and "metadata missing: gain_db, exposure_time_s" in res.message
    res = mon.process(Frame(1, img, META, metadata_age_s=3.5))
    assert res.level == WARN and "metadata stale: 3.50 s" in res.message
    res = mon.process(Frame(2, img, None, metadata_error="gain_db = 99 dB is outside the allowed range"))
    assert res.level == WARN and "gain_db = 99" in res.message
    assert mon.counters["frames_skipped"] == 3 and mon.counters["frames_processed"] == 0


def test_idle_report_goes_stale(rng):
    mon = make_monitor(image_timeout_s=1.0)
    assert mon.idle_report(0).level == STALE
    frame = next(frames(rng, 1))[0]
    mon.process(frame, received_ns=10_000_000_000)
    assert mon.idle_report(10_500_000_000).level == OK
    stale = mon.idle_report(11_600_000_000)
    assert stale.level == STALE and "no image for 1.6 s" in stale.message
    assert stale.hardware_id == "icx285/cam" and stale.name == "noise_monitor: cam"


def test_idle_report_while_the_first_frame_is_evaluated():
    """An image received, its evaluation not finished (the node's worker busy with the first frame): until 2026-12-04
    STALE "no image for 0.3 s (timeout 1 s)", contradicting itself."""
    mon = make_monitor(image_timeout_s=1.0)
    mon.last_received_ns = 10_000_000_000  # as process() sets it on entry
    first = mon.idle_report(10_300_000_000)
    assert first.level == OK and first.message == "image received 0.3 s ago, its evaluation not finished yet"
    assert mon.idle_report(11_600_000_000).level == STALE


# --- outputs -------------------------------------------------------------------------------
def test_outputs_same_topics_and_values_for_rclpy_and_rosbags(rng):
    mon = make_monitor()
    first = mon.process(next(frames(rng, 1, start=31))[0])
    res = replace(first, xi_temporal=-0.03, sigma={**first.sigma, "temporal": 2.5})  # as a still hold's frame
    a, b = rclpy_messages(res, frame_id="cam_optical"), rosbags_messages(res, frame_id="cam_optical")
    per_frame = set(OUTPUT_TOPICS) - {"/diagnostics"}  # /diagnostics is the period summary, not per frame
    assert set(a) == set(b) == per_frame
    hold = {f"/noise_monitor/{k}" for k in HOLD_KEYS}  # the frame differences' numbers: a still hold's frames only
    assert set(rclpy_messages(first)) == set(rosbags_messages(first)) == per_frame - hold
    assert number_of(a["/noise_monitor/sigma_temporal"]) == 2.5 and number_of(b["/noise_monitor/xi_temporal"]) == -0.03
    for topic in per_frame:
        for msg in (a[topic], b[topic]):  # stamped with the image's header
            assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == divmod(res.stamp_ns, 10**9)
            assert msg.header.frame_id == "cam_optical"
        if topic == "/noise_monitor/frame":
            assert reports_from_msg(a[topic]) == reports_from_msg(b[topic]) == [res.report()]
        else:
            assert number_of(a[topic]) == number_of(b[topic]) and a[topic].vector.y == b[topic].vector.z == 0.0
    assert number_of(a["/noise_monitor/sigma_rn"]) == res.sigma["rn"]
    assert number_of(a["/noise_monitor/sigma_image"]) == res.sigma["image"]
    assert number_of(a["/noise_monitor/xi_threshold"]) == mon.config.xi_threshold_dn
    skipped = mon.process(Frame(5, np.zeros((256, 256), np.float32), None, missing=["gain_db"]))
    assert set(rclpy_messages(skipped)) == {"/noise_monitor/frame"}  # a skipped frame: its status, no numbers
    assert reports_from_msg(rclpy_messages(skipped)["/noise_monitor/frame"])[0].level == WARN
    idle = rosbags_messages(mon.idle_report(10**12), stamp_ns=10**12)
    assert set(idle) == {"/diagnostics"} and reports_from_msg(idle["/diagnostics"])[0].level == STALE
    assert {"/cam_monitor/xi", "/cam_monitor/frame"} <= set(output_topics("cam_monitor"))


@pytest.mark.parametrize("mode,extra", [("joint", ["prnu"]), ("sequential", None)])
def test_fast_patch_prediction_equals_model_predict(rng, mode, extra):
    from noise_monitor.monitor.model_patches import predict_patches

    model = NoiseModel(extra=extra)
    maps = np.clip(rng.normal(128, 70, (3, 32, 32)), -5, 260).astype(np.float32)  # includes clipping
    slow, fast = model.predict(maps, META, mode=mode), predict_patches(model, maps, META, mode)
    assert set(slow) == set(fast)
    for k in slow:
        np.testing.assert_allclose(fast[k], slow[k], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("mode,extra", [("joint", ["prnu"]), ("sequential", None)])
def test_prediction_at_single_intensities_equals_the_patch_prediction(rng, mode, extra):
    """The temporal noise levels' model: one table lookup per intensity, as for a map of that one intensity."""
    from noise_monitor.monitor.model_patches import level_positions, predict_levels, predict_patches

    model = NoiseModel(extra=extra)
    levels = np.r_[rng.uniform(0.0, 255.0, 40), 0.0, 255.0, -3.0, 260.0]  # the last two clipped to the range
    maps = np.clip(levels, 0.0, 255.0)[:, None, None] * np.ones((1, 2, 2))
    fast = predict_levels(model, level_positions(levels), META, mode)
    np.testing.assert_allclose(fast, predict_patches(model, maps, META, mode)["total"], rtol=1e-9, atol=1e-12)


def test_estimator_nan_and_failing_model_effect_are_warnings(rng):
    from noise_monitor.physics import Effect

    class NanEstimator(PhysicsSplitEstimator):
        def predict(self, patches_dn, metas):
            out = super().predict(patches_dn, metas)
            out["rn"] = out["rn"] * np.nan
            return out

    frame = next(frames(rng, 1))[0]
    res = Monitor(MonitorConfig(), NanEstimator(), MODEL, "cam", "hw").process(frame)
    assert res.level == WARN and "returned NaN/inf for rn" in res.message

    class Broken(Effect):
        name = "broken_for_test"
        distribution = "gaussian"

        def sigma_dn(self, signal, cond):
            raise RuntimeError("sensor table missing")

    mon = Monitor(MonitorConfig(), PhysicsSplitEstimator(), NoiseModel(extra=[Broken()]), "cam", "hw")
    res = mon.process(frame)
    assert res.level == WARN and "evaluation failed" in res.message and "broken_for_test" in res.message


def test_auto_xi_source_uses_the_model_when_the_profile_adds_effects(rng):
    prnu = NoiseModel(extra={"prnu": {"sigma_pct": 3.0}})
    assert make_monitor().xi_source == "estimator"
    for src, expected in (("auto", "model"), ("estimator", "estimator")):
        mon = Monitor(MonitorConfig(xi_source=src), PhysicsSplitEstimator(), prnu, "cam", "hw")
        assert mon.xi_source == expected
    mon = Monitor(MonitorConfig(), PhysicsSplitEstimator(), prnu, "cam", "hw")
    for i in range(15):  # a camera with the PRNU its profile declares: no alarm
        noisy, _ = prnu.simulate(scene(), META, rng)
        res = mon.process(Frame(i, mono8(noisy), META))
    assert res.level == OK and abs(res.xi_filtered) < 0.5 and res.model["prnu"] > 2.0


def weighted(values: np.ndarray, w: np.ndarray) -> float:
    """The lower weighted median, written out: the first sorted value where the cumulative weight reaches half."""
    order = np.argsort(values)
    cum = np.cumsum(w[order])
    return float(values[order][np.searchsorted(cum, 0.5 * cum[-1])])


def test_frame_medians_rest_on_the_precise_patches():
    """The frame's median weighs each patch by 1 / predicted error^2: three textured patches read 2 DN high at
    0.3 DN do not outvote two flat ones read right at 0.05 DN; the error floor (0.05 DN) keeps one patch from
    taking the frame; a non-finite error weighs nothing; without predicted errors the plain median."""
    from noise_monitor.monitor.pipeline import patch_weights, weighted_median

    xi = np.array([0.0, 0.1, 2.0, 2.1, 2.2])
    err = np.array([0.05, 0.05, 0.3, 0.3, 0.3])
    use = np.ones(5, bool)
    assert np.median(xi) == 2.0 and weighted_median(xi, patch_weights({"sigma_image_error": err}, use)) == 0.1
    w = patch_weights({"sigma_image_error": np.array([1e-6, 0.05, 0.05])}, np.ones(3, bool))
    assert w is not None and np.allclose(w, 400.0)  # floored: the first patch no longer outweighs both others
    assert weighted_median(np.array([0.0, 1.0, 1.0]), w) == 1.0
    w = patch_weights({"sigma_image_error": np.array([np.nan, 0.1, 0.1])}, np.ones(3, bool))
    assert w is not None and w[0] == 0.0 and weighted_median(np.array([-9.0, 1.0, 2.0]), w) == 1.0
    assert patch_weights({"sigma_image_error": np.array([np.nan, np.inf])}, np.ones(2, bool)) is None
    assert patch_weights({}, use) is None and weighted_median(xi, None) == 2.0
    assert patch_weights({"sigma_image_error": err}, np.array([1, 1, 0, 0, 0], bool)).shape == (2,)
    rng = np.random.default_rng(3)
    for _ in range(200):
        v, ww = rng.normal(size=7), rng.uniform(0.1, 5.0, 7)
        assert weighted_median(v, ww) == weighted(v, ww)


def test_a_frames_single_image_xi_error_is_its_patches_predicted_error():
    """The frame's xi error (the alarm's evidence unit, the weight against the temporal xi) is the weighted median of
    its used patches' predicted errors, not divided by their number (one scene's patches err alike), floored at
    0.05 DN and capped at ``image_xi_error_dn``; without (finite) predicted errors, the cap."""
    from noise_monitor.monitor.pipeline import XI_ERROR_FLOOR_DN, image_xi_error, patch_weights

    use = np.ones(5, bool)
    flat = {"sigma_image_error": np.array([0.08, 0.09, 0.1, 0.5, 0.6])}
    assert image_xi_error(flat, use, None, 0.3) == 0.1
    assert image_xi_error(flat, use, patch_weights(flat, use), 0.3) == 0.09  # the precise patches weigh more
    assert image_xi_error(flat, np.array([0, 0, 0, 1, 1], bool), None, 0.3) == 0.3  # textured: capped
    assert image_xi_error({"sigma_image_error": np.full(5, 0.01)}, use, None, 0.3) == XI_ERROR_FLOOR_DN
    assert image_xi_error({"sigma_image_error": np.full(5, np.nan)}, use, None, 0.3) == 0.3
    assert image_xi_error({}, use, None, 0.25) == 0.25


def test_medians_over_the_patches_the_estimator_can_measure(rng):
    """With the shipped estimator's confidence output the frame's sigma_image and xi are medians over its
    measurable patches and the declined ones whose own alarm decision is clear, weighted by 1 / predicted
    error^2, its per-source sigmas plain medians over them; a frame of fine texture everywhere with no clear
    patch falls back to every patch for the sigmas and to the image-only bound for xi."""
    from noise_monitor.estimator import load
    from noise_monitor.estimator.inference import clear_decisions

    est = load("full_meta", device="cpu", model=MODEL)
    mon = Monitor(MonitorConfig(min_patches=4), est, MODEL, "cam", "icx285/cam")
    clean = scene()
    fine = 40.0 * cv2.GaussianBlur(rng.standard_normal((256, 256)).astype(np.float32), (0, 0), 0.8)  # pixel-scale texture
    x = np.mgrid[0:256, 0:256][1]
    for stamp, (content, some_declined) in enumerate(((clean + fine * (x >= 64), True), (clean + fine, False))):
        noisy, _ = MODEL.simulate(np.clip(content, 5, 250).astype(np.float32), META, rng)
        res = mon.process(Frame(stamp, mono8(noisy), META))
        assert res.processed, res.skip_reason
        out = est.predict(res.patches.extract(mono8(noisy)), META)
        ok = out["measurable"]
        assert res.numeric()["patches_measurable"] == ok.sum() == res.patches_measurable
        use = ok | clear_decisions(out, mon.config.xi_threshold_dn)
        read = use.any()
        use = use if read else np.ones_like(ok)
        w = 1.0 / np.maximum(out["sigma_image_error"][use], 0.05) ** 2
        assert res.sigma["image"] == pytest.approx(weighted(out["sigma_image"][use], w), rel=1e-5)
        assert res.sigma["pn"] == pytest.approx(float(np.median(out["pn"][use])), rel=1e-5)
        if read:
            assert res.xi_image == pytest.approx(weighted(out["xi"][use], w), abs=1e-5)
        else:  # texture everywhere: the image proves only a lower bound of xi
            assert res.xi_image == pytest.approx(max(float(np.median(out["xi_lower"])), 0.0), abs=1e-5)
        assert (0 < ok.sum() < len(ok)) if some_declined else not ok.any()


@pytest.mark.parametrize("stated_gain_db", [18.0, 30.0])
def test_texture_everywhere_proves_only_a_lower_bound_of_xi(stated_gain_db):
    """A camera panning over pixel-scale texture: every patch declined. The patches whose own alarm decision is
    clear given their predicted error decide; without one, the frame's median reading decides only when its
    alarm decision is clear given the median predicted error; otherwise the image proves only xi >= xi_bound
    (texture adds pixel-scale energy, never removes noise). With the true gain no frame alarms (a reading off
    by more than the threshold raised alarms before the bound); with a gain stated 12 dB high (the model far
    noisier than the image) every frame alarms, from the bound or from a clear reading."""
    from noise_monitor.estimator import load
    from noise_monitor.estimator.inference import clear_decisions

    rng = np.random.default_rng(8)
    est = load("full_meta", device="cpu", model=MODEL)
    mon = Monitor(MonitorConfig(min_patches=4), est, MODEL, "cam", "icx285/cam")
    stated = load_profile("icx285").metadata(gain_db=stated_gain_db, exposure_time_s=0.01, sensor_temperature_c=40.0)
    true_meta = load_profile("icx285").metadata(gain_db=18.0, exposure_time_s=0.01, sensor_temperature_c=40.0)
    results = []
    for k in range(10):  # new texture every frame: no static hold
        fine = 40.0 * cv2.GaussianBlur(rng.standard_normal((256, 256)).astype(np.float32), (0, 0), 0.8)
        noisy, _ = MODEL.simulate(np.clip(100.0 + fine, 5, 250).astype(np.float32), true_meta, rng)
        res = mon.process(Frame(k * 100_000_000, mono8(noisy), stated))
        out = est.predict(res.patches.extract(mono8(noisy)), stated)
        frame = {key: np.array([np.median(out[key])]) for key in ("xi", "sigma_image_error", "sigma_image")}
        clear_patches = clear_decisions(out, mon.config.xi_threshold_dn)
        clear = bool(clear_decisions(frame, mon.config.xi_threshold_dn)[0])
        assert res.processed and res.patches_measurable == 0 and res.temporal_weight == 0.0
        assert res.xi_bound is not None and "xi_bound" in res.numeric()
        if clear_patches.any():
            w = 1.0 / np.maximum(out["sigma_image_error"][clear_patches], 0.05) ** 2
            assert res.xi_measurement == "image"
            assert res.xi == pytest.approx(weighted(out["xi"][clear_patches], w), abs=1e-5)
        elif clear:
            assert res.xi_measurement == "image" and res.xi == pytest.approx(float(frame["xi"][0]), abs=1e-5)
        else:
            assert res.xi_measurement == "bound" and res.values()["xi_measurement"] == "bound"
            assert res.xi == pytest.approx(max(res.xi_bound, 0.0)) and "the image proves only xi >=" in res.message
        results.append(res)
    true_xi = float(MODEL.predict(100.0, stated)["total"] - MODEL.predict(100.0, true_meta)["total"])
    if stated_gain_db == 18.0:
        assert not any(r.alarm_active for r in results)
    else:
        assert all(1.0 < r.xi_bound <= true_xi + 0.2 for r in results), (true_xi, [r.xi_bound for r in results])
        assert all(r.alarm_active and r.cause == CAUSE_MODEL_NOISIER for r in results[1:])
