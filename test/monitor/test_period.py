"""The /diagnostics period summary (noise_monitor.monitor.period) on the real pipeline, without ROS."""
from __future__ import annotations

import numpy as np
import pytest

from noise_monitor.monitor import Frame
from noise_monitor.monitor.period import PeriodSummary, skip_category
from noise_monitor.monitor.status import ERROR, OK, STALE, WARN

from .test_pipeline import frames, make_monitor

S = 1_000_000_000


def test_summary_of_a_period_with_evaluated_and_skipped_frames(rng):
    mon = make_monitor()
    period = PeriodSummary(0)
    results = [mon.process(f) for f, _ in frames(rng, 6)]
    results.append(mon.process(Frame(7 * 33_000_000, np.zeros((256, 256), np.float32), None, missing=["gain_db"])))
    results.append(mon.reject(8 * 33_000_000, "image unusable: compressed image format 'jpeg' is lossy"))
    mon.count_dropped(3)
    mon.count_lost(2)
    for r in results:
        period.add(r)
    rep = period.report(mon, S)
    v = rep.values
    assert rep.level == WARN and rep.message.startswith("frame not evaluated: image unusable")  # the latest WARN
    assert "latest:" not in rep.message  # the latest frame is the worst one
    assert (v["period_frames"], v["period_processed"], v["period_skipped"]) == ("8", "6", "2")
    assert (v["period_dropped"], v["period_lost"], v["period_s"]) == ("3", "2", "1")
    assert v["skipped: metadata missing"] == "1" and v["skipped: image unusable"] == "1"
    xi = [r.xi for r in results if r.processed]
    assert float(v["xi_min"]) == pytest.approx(min(xi), rel=1e-5)
    assert float(v["xi_max"]) == pytest.approx(max(xi), rel=1e-5)
    assert float(v["xi_mean"]) == pytest.approx(np.mean(xi), rel=1e-5)
    last = results[5]  # the contract's values: the latest evaluated frame's filtered ones
    for k in ("pn", "dcsn", "rn", "total"):
        assert float(v[f"sigma_{k}"]) == pytest.approx(last.filtered[k], rel=1e-5)
    assert float(v["xi"]) == float(v["xi_filtered"]) == pytest.approx(last.xi_filtered, rel=1e-5, abs=1e-9)
    assert float(v["sigma_model"]) == pytest.approx(last.model["total"], rel=1e-5)
    assert (v["alarm"], v["alarm_raised"], v["frames_processed"], v["frames_received"]) == ("0", "0", "6", "8")
    # the next period starts empty; its counts are its own (the cumulative counters go on)
    for f, _ in frames(rng, 2, start=9):
        period.add(mon.process(f))
    rep2 = period.report(mon, 2 * S)
    assert rep2.level == OK and rep2.values["period_frames"] == "2" and rep2.values["period_dropped"] == "0"
    assert "skipped: metadata missing" not in rep2.values and rep2.values["frames_received"] == "10"


def test_an_alarm_raised_and_cleared_inside_the_period_is_its_worst_level(rng):
    mon = make_monitor(alarm_min_frames=3, clear_min_frames=3, filter_alpha=1.0)
    period = PeriodSummary(0)
    for f, _ in frames(rng, 3):
        period.add(mon.process(f))
    assert period.report(mon, S).level == OK
    noisy = [mon.process(f) for f, _ in frames(rng, 6, extra_sigma=5.0, start=3)]
    clean = [mon.process(f) for f, _ in frames(rng, 12, start=9)]
    assert any(r.alarm_active for r in noisy) and not clean[-1].alarm_active  # raised, then cleared
    for r in noisy + clean:
        period.add(r)
    rep = period.report(mon, 2 * S)
    assert rep.level == ERROR and "xi alarm" in rep.message and "; latest: noise matches the model" in rep.message
    assert rep.values["alarm"] == "0" and rep.values["alarm_raised"] == "1" and rep.values["alarm_episodes"] == "1"
    assert int(rep.values["period_alarm_frames"]) == sum(r.alarm_active for r in noisy + clean)
    xi = [r.xi for r in noisy + clean]  # the per-frame xi of both the noisy and the clean frames
    assert float(rep.values["xi_min"]) == pytest.approx(min(xi), rel=1e-5) and min(xi) < -1.0
    assert float(rep.values["xi_max"]) == pytest.approx(max(xi), rel=1e-5) and max(xi) > -0.5
    assert rep.values["period_frames"] == "18"


def test_an_empty_period_reports_the_idle_status(rng):
    mon = make_monitor(image_timeout_s=1.0)
    period = PeriodSummary(0)
    rep = period.report(mon, S)
    assert rep.level == STALE and rep.message == "no image received yet"
    assert rep.values["period_frames"] == "0" and "xi" not in rep.values and "xi_min" not in rep.values
    frame = next(frames(rng, 1))[0]
    period.add(mon.process(frame, received_ns=S))
    period.report(mon, int(1.2 * S))
    quiet = period.report(mon, int(1.5 * S))  # no frame in this period, the last one 0.5 s old: its status
    assert quiet.level == OK and quiet.values["period_frames"] == "0" and "sigma_rn" in quiet.values
    stale = period.report(mon, int(2.6 * S))
    assert stale.level == STALE and "no image for 1.6 s" in stale.message and stale.values["image_age_s"] == "1.6"


def test_skip_categories_drop_the_particulars():
    assert skip_category("metadata missing: gain_db, exposure_time_s") == "metadata missing"
    assert skip_category("3 usable patches (need 4): 5 too dark") == "N usable patches (need N)"
    assert skip_category("image 10x12 is smaller than the patch size 64") == "image NxN is smaller than the patch size N"
    assert skip_category("") == "unknown"
