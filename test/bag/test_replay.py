"""Replay: every frame accounted, the node's topics in a readable MCAP, CSV, PNG, the JSON contract."""
from __future__ import annotations

import csv
import json
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest
import torch
from mcap.reader import make_reader

from msg_adapters import ERROR, STALE, WARN, reports_from_msg
from msg_adapters.diagnostics import jazzy_typestore
from msg_adapters.outputs import DIAGNOSTICS_TOPIC, HOLD_KEYS, IMAGE_TYPE, OUTPUT_TOPICS, debug_image_topic
from noise_monitor.bag import BagError
from noise_monitor.bag.messages import image_msg, metadata_msg
from noise_monitor.bag.replay import replay
from noise_monitor.bag.replay_cmd import print_summary
from noise_monitor.bag.results import SCENE_DEPENDENT_KEYS, truth_check
from noise_monitor.bag.simulate import load_truth, simulate_bag
from noise_monitor.bag.staging import write_text_atomic
from noise_monitor.bag.writer import BagWriter
from noise_monitor.cli import main
from noise_monitor.monitor import MonitorConfig
from noise_monitor.physics import load_profile

torch.set_num_threads(1)
CONFIG = MonitorConfig(patches_per_frame=4, alarm_min_frames=3, clear_min_frames=3)


@pytest.fixture(scope="module")
def estimator():
    from noise_monitor.estimator import load

    return load("full_meta", device="cpu")


@pytest.fixture(scope="module")
def noisy_bag(tmp_path_factory, estimator) -> Path:
    """An EV76C661 campaign at constant conditions with +N(0, 5 DN) image noise for frames 8-13."""
    ps = estimator.patch_size
    return simulate_bag(tmp_path_factory.mktemp("replay") / "noise.mcap", "ev76c661", "image_noise", frames=20,
                        width=3 * ps, height=2 * ps, seed=4, hold_s=0)


@pytest.fixture(scope="module")
def replayed(noisy_bag, estimator, tmp_path_factory) -> tuple[dict, Path]:
    out = tmp_path_factory.mktemp("out")
    return replay(noisy_bag, "ev76c661", out, estimator=estimator, config=CONFIG, progress=False), out


def test_summary_contract_and_accounting(replayed):
    s, _ = replayed
    assert s["frames_total"] == 20 and s["frames_processed"] + s["frames_skipped"] == 20
    assert s["frames_processed"] == 20 and s["skip_reasons"] == {} and s["temporal_noise_changes"] == 0
    for key in ("sigma_pn", "sigma_dcsn", "sigma_rn", "xi"):
        st = s[key]
        assert st["p5"] <= st["mean"] <= st["p95"] and st["n"] == 20
    assert s["sigma_pn"]["mean"] > 0 and s["sigma_rn"]["mean"] > 0
    assert s["topics_out"] == {**OUTPUT_TOPICS, debug_image_topic(): IMAGE_TYPE}
    assert s["realtime_factor"] > 0 and s["bag_duration_s"] == pytest.approx(19 / 5.0)


def test_unexpected_noise_episode_is_one_alarm_with_negative_xi(replayed, noisy_bag):
    s, _ = replayed
    truth = load_truth(noisy_bag)["episodes"][0]
    (ep,) = s["alarms"]
    assert ep["sign"] == "-" and ep["peak_xi_dn"] < -1.0
    assert "image noisier" in ep["cause"]
    assert truth["start_ns"] <= ep["start_ns"] <= truth["end_ns"]  # raised during the corruption
    for k in ("start_ns", "end_ns", "start_s", "end_s", "frames"):
        assert k in ep
    check = s["truth_check"]  # the simulated bag's sidecar is compared automatically
    assert (check["detected"], check["missed"], check["false_alarms"]) == (1, 0, 0)
    assert 0 <= check["episodes"][0]["delay_s"] <= (truth["end_ns"] - truth["start_ns"]) / 1e9


def test_a_noise_step_while_the_camera_holds_still_restarts_its_temporal_measurement(tmp_path, estimator):
    """The image-noise episode starts and ends inside still stretches of the camera: both changes cut the hold's
    window (summary ``temporal_noise_changes``) and the alarm comes on the episode's second frame (before: its third,
    the window pooling frames of both noises)."""
    ps = estimator.patch_size
    bag = simulate_bag(tmp_path / "step.mcap", "ev76c661", "image_noise", frames=40, width=3 * ps, height=2 * ps,
                       seed=5, fps=10.0)
    s = replay(bag, "ev76c661", None, estimator=estimator, config=CONFIG, progress=False, plot=False)
    assert s["temporal_noise_changes"] == 2
    assert s["truth_check"]["detected"] == 1 and s["truth_check"]["episodes"][0]["delay_s"] <= 0.1 + 1e-9


def test_a_step_of_the_light_while_the_camera_holds_still_is_counted_and_restarts_the_measurement(tmp_path, estimator,
                                                                                              lamp_bag):
    """A photograph held still at 10 Hz whose light steps up by 30 % at frame 12 (a lamp switched on): the replay
    counts one light step (summary and /diagnostics ``temporal_light_steps``), no change of the noise; once the new
    light has ``temporal_min_frames`` frames, the window holds its frames alone."""
    bag = lamp_bag
    out = tmp_path / "o"
    s = replay(bag, "ev76c661", out, estimator=estimator, config=CONFIG, progress=False, plot=False)
    assert s["frames_processed"] == 24 and s["temporal_light_steps"] == 1 and s["temporal_noise_changes"] == 0
    diag = [reports_from_msg(m)[0] for _, _, m in decoded(out / "replay.mcap", [DIAGNOSTICS_TOPIC])]
    assert diag[-1].values["temporal_light_steps"] == "1"
    with open(out / "replay.csv") as f:
        rows = list(csv.DictReader(f))
    held = [int(float(r["temporal_frames"] or 0)) for r in rows]
    assert min(held[11:15]) >= 8 and held[15] == 4 and held[-1] == 12  # then the new light's frames alone
    assert [i for i, r in enumerate(rows) if r["hold_event"]] == [15] and rows[15]["hold_event"] == "light stepped"
    drove = [r["xi_measurement"] for r in rows]
    assert s["xi_measurement"] == {k: drove.count(k) for k in ("image", "temporal", "bound")}
    assert s["xi_measurement"]["temporal"] >= 20  # from the 4th frame of the still camera
    temporal = [float(r["sigma_temporal"]) for r in rows if r["sigma_temporal"]]
    model = [float(r["sigma_temporal"]) + float(r["xi_temporal"]) for r in rows if r["sigma_temporal"]]
    assert s["sigma_temporal"]["n"] == s["sigma_temporal_model"]["n"] == len(temporal)
    assert s["sigma_temporal"]["mean"] == pytest.approx(np.mean(temporal), abs=1e-4)
    assert s["sigma_temporal_model"]["mean"] == pytest.approx(np.mean(model), abs=1e-3)


def test_doubled_thermal_noise_metadata_is_a_positive_xi_alarm(tmp_path, estimator):
    bag = simulate_bag(tmp_path / "w2.mcap", "ev76c661", "double_thermal_noise", frames=20,
                       width=3 * estimator.patch_size, height=2 * estimator.patch_size, seed=6, hold_s=0)
    s = replay(bag, "ev76c661", None, estimator=estimator, config=CONFIG, progress=False)
    assert [a["sign"] for a in s["alarms"]] == ["+"]
    assert "model predicts more noise" in s["alarms"][0]["cause"]
    assert s["truth_check"]["detected"] == 1 and s["truth_check"]["false_alarms"] == 0
    assert "outputs" not in s  # no out_dir: nothing written


def test_truth_check_counts_misses_wrong_signs_and_false_alarms():
    s = 1_000_000_000
    truth = [{"start_ns": 10 * s, "end_ns": 20 * s, "corrupted": ["a"], "xi_sign": "-"},
             {"start_ns": 40 * s, "end_ns": 50 * s, "corrupted": ["b"], "xi_sign": "+"}]
    alarms = [{"start_ns": 12 * s, "sign": "-"}, {"start_ns": 45 * s, "sign": "-"}, {"start_ns": 70 * s, "sign": "+"}]
    check = truth_check(alarms, truth)
    assert [e["detected"] for e in check["episodes"]] == [True, False]  # the second alarm has the wrong sign
    assert check["episodes"][0]["delay_s"] == 2.0
    assert (check["detected"], check["missed"], check["false_alarms"]) == (1, 1, 1)


def test_mcap_has_exactly_the_node_topics_and_is_readable_by_the_mcap_library(replayed):
    s, out = replayed
    counts: dict[str, int] = {}
    schemas: dict[str, str] = {}
    with open(out / "replay.mcap", "rb") as fh:
        reader = make_reader(fh)
        for schema, channel, _ in reader.iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            schemas[channel.topic] = schema.name
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
    assert summary is not None  # every topic's channel, also of topics no frame had (a still hold's)
    assert {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()} == \
        {**OUTPUT_TOPICS, debug_image_topic(): IMAGE_TYPE}
    assert schemas.items() <= {**OUTPUT_TOPICS, debug_image_topic(): IMAGE_TYPE}.items()
    assert counts[debug_image_topic()] == 4  # debug_image_rate_hz 1 in bag time: 20 frames at 5 Hz span 3.8 s
    hold = {f"/noise_monitor/{k}" for k in HOLD_KEYS}  # a still hold's frames only
    assert all(counts[t] == 20 for t in OUTPUT_TOPICS if t != DIAGNOSTICS_TOPIC and t not in hold)  # every frame
    with open(out / "replay.csv") as f:
        held = sum(r["sigma_temporal"] != "" for r in csv.DictReader(f))
    assert all(counts.get(t, 0) == held for t in hold)
    assert counts[DIAGNOSTICS_TOPIC] == 4  # 3.8 s at 1 Hz: 3 full periods and the last partial one


def decoded(path: Path, topics: list[str]) -> list[tuple[str, int, object]]:
    """(topic, header stamp ns, message) of ``topics`` in an MCAP, in file order."""
    out = []
    with open(path, "rb") as fh:
        for schema, channel, m in make_reader(fh).iter_messages(topics=topics):
            msg = jazzy_typestore().deserialize_cdr(m.data, schema.name)
            out.append((channel.topic, msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec, msg))
    return out


def test_diagnostics_summarise_each_second_of_bag_time(replayed):
    """/diagnostics at 1 Hz of bag time: per period the worst level, the frames and xi min/mean/max of the
    per-frame ~/frame statuses in it, the latest filtered values; per frame the image's header."""
    s, out = replayed
    per_frame = {}
    for topic, stamp, msg in decoded(out / "replay.mcap", ["/noise_monitor/frame", "/noise_monitor/xi"]):
        if topic.endswith("/xi"):
            assert msg.header.frame_id == "camera" and stamp in per_frame  # the image's header
            continue
        (r,) = reports_from_msg(msg)
        per_frame[stamp] = r
    stamps = sorted(per_frame)
    summaries = [(t, reports_from_msg(m)[0]) for _, t, m in decoded(out / "replay.mcap", [DIAGNOSTICS_TOPIC])]
    assert [t - stamps[0] for t, _ in summaries] == [10**9, 2 * 10**9, 3 * 10**9, stamps[-1] - stamps[0]]
    start, seen_error = stamps[0], False
    for n, (t, rep) in enumerate(summaries):
        last = n == len(summaries) - 1
        inside = [per_frame[x] for x in stamps if start <= x < t or (last and x == t)]
        xi = [float(r.values["xi"]) for r in inside]
        v = rep.values
        assert int(v["period_frames"]) == int(v["period_processed"]) == len(inside) == 5
        assert float(v["xi_min"]) == pytest.approx(min(xi), rel=1e-4)
        assert float(v["xi_max"]) == pytest.approx(max(xi), rel=1e-4)
        assert float(v["xi_mean"]) == pytest.approx(np.mean(xi), rel=1e-4, abs=1e-5)
        assert rep.level == max(r.level for r in inside)
        assert v["xi"] == inside[-1].values["xi_filtered"] and v["sigma_rn"] == inside[-1].values["sigma_rn_filtered"]
        assert v["alarm_raised"] == ("1" if any(r.values["alarm"] == "1" for r in inside) else "0")
        seen_error |= rep.level == ERROR
        start = t
    assert seen_error and s["alarms"]  # the alarm episode shows in its periods


def test_csv_png_and_json_files(replayed):
    s, out = replayed
    with open(out / "replay.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 20
    assert {"sigma_pn", "sigma_dcsn", "sigma_rn", "xi", "xi_filtered", "skip_reason", "gain_db"} <= set(rows[0])
    # the columns a scene may or may not give end every replay's header, in one order (before: only when some frame
    # had them, where that frame came: headers differed between bags)
    assert tuple(rows[0])[-len(SCENE_DEPENDENT_KEYS):] == SCENE_DEPENDENT_KEYS
    assert [int(r["alarm"]) for r in rows].count(1) == s["alarms"][0]["frames"]
    png = (out / "replay.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20_000
    assert json.loads((out / "summary.json").read_text())["frames_total"] == 20


def test_json_written_atomically_has_a_plain_files_mode(tmp_path):
    """``replay --json`` goes through a temporary file and a rename, yet gets the mode of any file the user writes
    (before: mkstemp's private 0600)."""
    write_text_atomic(tmp_path / "s.json", "{}")
    (tmp_path / "plain.txt").write_text("")
    assert (tmp_path / "s.json").stat().st_mode & 0o777 == (tmp_path / "plain.txt").stat().st_mode & 0o777


def _bag_with_problems(path: Path, size: int) -> None:
    """6 frames: no metadata yet, ok, non-numeric metadata, bad encoding, stale metadata after a 5 s gap, ok."""
    prof = load_profile("icx285")
    meta = prof.metadata(gain_db=12.0, exposure_time_s=0.01, sensor_temperature_c=30.0)
    img = np.clip(np.random.default_rng(0).normal(120, 3, (size, size)), 0, 255).astype(np.uint8)
    stamps = [1_000_000_000 * s for s in (1, 2, 3, 4, 9, 10)]
    with BagWriter(path) as w:
        for i, t in enumerate(stamps):
            if i not in (0, 4):
                m = metadata_msg(meta, t, "test")
                if i == 2:
                    m.status[0].values[0].value = "loud"
                w.write("/camera/metadata", m, t)
            msg = image_msg(img, t)
            if i == 3:
                msg.encoding = "yuv_unknown"
            w.write("/camera/image_raw", msg, t)


def test_every_frame_accounted_with_reasons_and_stale_gap(tmp_path, estimator):
    bag = tmp_path / "problems.mcap"
    _bag_with_problems(bag, 2 * estimator.patch_size)
    s = replay(bag, None, tmp_path / "o", estimator=estimator, config=CONFIG, progress=False, plot=False)
    assert (s["frames_total"], s["frames_processed"], s["frames_skipped"]) == (6, 2, 4)
    reasons = {d["index"]: d["reason"] for d in s["skipped"]}
    assert reasons[0].startswith("metadata missing: gain_db")
    assert reasons[2].startswith("metadata invalid") and "gain_db" in reasons[2]
    assert reasons[3].startswith("image unusable: unsupported image encoding")
    assert reasons[4].startswith("metadata stale: 5.00 s")
    assert sum(s["skip_reasons"].values()) == 4 and s["levels"]["WARN"] == 4
    diag = [(t // 10**9, reports_from_msg(m)[0]) for _, t, m in decoded(tmp_path / "o" / "replay.mcap", [DIAGNOSTICS_TOPIC])]
    # 1 Hz summaries over the frames at 1, 2, 3, 4, 9 and 10 s, STALE after image_timeout_s = 2 s in the gap
    assert [t for t, _ in diag] == [2, 3, 4, 5, 6, 7, 8, 9, 10, 10]
    assert [r.level for _, r in diag] == [WARN, 0, WARN, WARN, WARN, STALE, STALE, STALE, WARN, 0]
    assert [r.values["period_frames"] for _, r in diag] == ["1", "1", "1", "1", "0", "0", "0", "0", "1", "1"]
    assert diag[0][1].values["skipped: metadata missing"] == "1" and "no image for 3.0 s" in diag[5][1].message


def test_frames_missing_from_the_recording_are_counted_as_the_node_counts_them(tmp_path, estimator):
    """A 5 Hz recording with frames 12-14 lost before it (a busy recorder): the replay counts them from the stamp
    gap as the node does, in the summary and on /diagnostics (before: 0 everywhere; a gap beyond a second is a
    paused stream, reported STALE, not losses)."""
    prof = load_profile("icx285")
    meta = prof.metadata(gain_db=12.0, exposure_time_s=0.01, sensor_temperature_c=30.0)
    size = 2 * estimator.patch_size
    rng = np.random.default_rng(1)
    bag = tmp_path / "gap.mcap"
    with BagWriter(bag) as w:
        for i in [*range(12), *range(15, 25)]:
            t = 1_000_000_000 + i * 200_000_000
            w.write("/camera/metadata", metadata_msg(meta, t, "test"), t)
            w.write("/camera/image_raw", image_msg(np.clip(rng.normal(120, 3, (size, size)), 0, 255).astype(np.uint8), t), t)
    s = replay(bag, None, tmp_path / "o", estimator=estimator, config=CONFIG, progress=False, plot=False)
    assert s["frames_total"] == 22 and s["frames_lost"] == 3
    diag = [reports_from_msg(m)[0] for _, _, m in decoded(tmp_path / "o" / "replay.mcap", [DIAGNOSTICS_TOPIC])]
    assert diag[-1].values["frames_lost"] == "3" and sum(int(r.values["period_lost"]) for r in diag) == 3


def test_replay_command_and_errors(tmp_path, noisy_bag, capsys):
    out, js = tmp_path / "cmd", tmp_path / "s.json"
    params = tmp_path / "params.yaml"
    params.write_text("/**:\n  ros__parameters:\n    patches_per_frame: 4\n    alarm_min_frames: 3\n"
                      "    clear_min_frames: 3\n")
    assert main(["replay", str(noisy_bag), "--profile", "ev76c661", "--out", str(out), "--json", str(js),
                 "--params", str(params), "--no-plot"]) == 0
    text = capsys.readouterr().out
    assert "alarm episodes: 1" in text and "PN" in text and "image noisier" in text
    assert "xi measured from the single image on 20 frame(s), from a still view's frame differences on 0" in text
    assert json.loads(js.read_text())["frames_processed"] == 20 and not (out / "replay.png").exists()
    assert main(["replay", str(tmp_path / "missing.mcap")]) == 2
    assert "does not exist" in capsys.readouterr().err
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(noisy_bag.read_bytes()[:5000])
    assert main(["replay", str(broken), "--profile", "ev76c661", "--out", str(tmp_path / "b")]) == 2
    assert "cannot read bag" in capsys.readouterr().err
    # refused before any work: an empty --out, a --json that is a folder (until 2026-12-04: after the whole replay)
    assert main(["replay", str(noisy_bag), "--profile", "ev76c661", "--out", ""]) == 2
    assert "--out is empty" in capsys.readouterr().err
    assert main(["replay", str(noisy_bag), "--out", str(tmp_path / "j"), "--json", str(tmp_path)]) == 2
    assert "is a folder" in capsys.readouterr().err and not (tmp_path / "j").exists()


def test_the_default_output_folder_keeps_the_bags_whole_name():
    """``run.day1.mcap`` and ``run.day2.mcap`` went to one out/run, the second replacing the first (until 2026-12-04)."""
    from noise_monitor.bag.replay_cmd import default_out

    assert default_out("field/run.day1.mcap") == Path("out/run.day1") != default_out("field/run.day2.mcap")
    assert default_out("field/run_2026.12.04/") == Path("out/run_2026.12.04")  # a rosbag2 folder
    assert default_out("a.DB3") == Path("out/a") and default_out(".mcap") == Path("out/.mcap")


def test_frame_table_columns_episodes_and_csv(tmp_path):
    """Columns across a storage-block boundary, late keys, skipped frames, an episode at the end."""
    from noise_monitor.bag.results import (
        BLOCK_ROWS,
        FrameTable,
        alarm_episodes,
        skip_reasons,
        source_summaries,
        write_csv,
    )

    table, n = FrameTable(), BLOCK_ROWS + 10
    for i in range(n):
        skipped = i % 1000 == 3
        alarm = i >= n - 7
        numbers = {} if skipped else {"xi": -2.0 if alarm else 0.01 * (i % 7), "xi_filtered": -1.5 if alarm else 0.0,
                                      **({"sigma_model_prnu": 0.5} if i > 2000 else {})}
        table.append(index=i, stamp_ns=10**9 + i * 10**8, processed=not skipped, level=2 if alarm else 0,
                     alarm_active=alarm, alarm_state="active" if alarm else "ok", cause="xi < 0" if alarm else None,
                     skip_reason=(("metadata missing" if i < 3000 else f"metadata stale: {i / 7:.2f} s (timeout 2 s)")
                                  if skipped else None), numbers=numbers,
                     conditions={"gain_db": 6.0, "exposure_time_s": 0.01, "sensor_temperature_c": 30.0},
                     xi_measurement=None if skipped else ("temporal" if i % 2 else "image"))
    assert len(table) == n and table.column("time_s")[-1] == pytest.approx((n - 1) * 0.1)
    # reasons alike but for their numbers are one (until 2026-12-04 one key per frame on a bag's other clock)
    assert skip_reasons(table) == {"metadata missing": 3, "metadata stale: N s (timeout 2 s)": 2}
    prnu = table.numbers("sigma_model_prnu")
    assert np.isnan(prnu[:2001]).all() and np.all(prnu[2001:][table.column("processed")[2001:]] == 0.5)
    (ep,) = alarm_episodes(table)
    assert (ep["start_index"], ep["end_index"], ep["frames"], ep["sign"], ep["cause"], ep["active_at_end"]) == \
        (n - 7, n - 1, 7, "-", "xi < 0", True)
    xi = source_summaries(table)["xi"]
    assert xi["n"] == n - 5
    write_csv(table, tmp_path / "t.csv")
    with open(tmp_path / "t.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["index"]) for r in rows] == list(range(n))
    assert rows[3]["skip_reason"] == "metadata missing" and rows[3]["xi"] == "" and rows[3]["gain_db"] == "6"
    assert rows[3]["xi_measurement"] == "" and (rows[4]["xi_measurement"], rows[5]["xi_measurement"]) == ("image", "temporal")
    assert rows[-1]["alarm"] == "1" and float(rows[-1]["xi"]) == -2.0 and rows[4100]["sigma_model_prnu"] == "0.5"


def test_the_plot_shows_the_still_views_measurement_what_drove_xi_and_where_it_restarted():
    """The frame differences' noise and the model on their blocks (sigma_temporal + xi_temporal) with gaps outside
    the holds, each frame's xi coloured by the measurement that drove it, a line where a hold's measurement
    restarted."""
    from noise_monitor.bag.plot import HOLD_EVENT_STYLES, TEMPORAL_LABELS, XI_MEASUREMENT_STYLES, replay_figure
    from noise_monitor.bag.results import FrameTable

    table, n = FrameTable(), 30
    held = np.arange(n) >= 10
    events = {20: "light stepped", 25: "noise changed, light stepped"}
    for i in range(n):
        numbers = {"xi": 0.01 * i, "xi_filtered": 0.0, "sigma_total": 5.0, "sigma_model": 5.0, "sigma_image": 5.1}
        if held[i]:
            numbers.update(sigma_temporal=4.0 + 0.01 * i, xi_temporal=0.1)
        table.append(index=i, stamp_ns=10**9 + i * 10**8, processed=True, level=0, alarm_active=False,
                     alarm_state="ok", cause=None, skip_reason=None, numbers=numbers, conditions={},
                     xi_measurement="temporal" if i >= 12 else "image", hold_event=events.get(i))
    fig = replay_figure(table, [], "t", 1.0)
    ax_s, ax_x = fig.axes[:2]
    lines = {ln.get_label(): ln for ln in ax_s.lines + ax_x.lines}
    measured, model = (np.asarray(lines[k].get_ydata(), float) for k in TEMPORAL_LABELS)
    assert np.isnan(measured[:10]).all() and np.allclose(measured[10:], 4.0 + 0.01 * np.arange(10, n))
    assert np.allclose(model[10:] - measured[10:], 0.1) and np.isnan(model[:10]).all()
    t = table.column("time_s")
    assert np.allclose(lines[XI_MEASUREMENT_STYLES["temporal"][0]].get_xdata(), t[12:])
    assert np.allclose(lines[XI_MEASUREMENT_STYLES["image"][0]].get_ydata(), 0.01 * np.arange(12))
    assert XI_MEASUREMENT_STYLES["bound"][0] not in lines
    for event, style in HOLD_EVENT_STYLES.items():
        at = [ln.get_xdata()[0] for ln in ax_x.lines if ln.get_linestyle() == style and ln.get_color() == "darkcyan"]
        assert np.allclose(at, [t[i] for i, e in events.items() if event in e])
    plt.close(fig)


def test_a_failed_replay_leaves_no_empty_output_folder(tmp_path, capsys):
    """A bag that cannot be read: exit 2, and the output folder the run would have made is not left behind empty."""
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"\x89MCAP0\r\n" + b"\x00" * 100)
    assert main(["replay", str(bad), "--profile", "icx285", "--out", str(tmp_path / "new" / "out")]) == 2
    assert "bad.mcap" in capsys.readouterr().err
    assert not (tmp_path / "new" / "out").exists()


def test_camera_constants_of_the_bag_that_win_over_the_profile_are_named(tmp_path, estimator):
    """A bag whose metadata carry every field (as the simulator writes them) replayed with another camera's profile:
    the message's constants win, as in the node, and the summary names them (before: it named the profile only)."""
    bag = simulate_bag(tmp_path / "icx.mcap", "icx285", "static", frames=4, width=128, height=128, seed=2)
    other = replay(bag, "ev76c661", tmp_path / "o1", estimator=estimator, config=CONFIG, progress=False, plot=False)
    icx, ev = load_profile("icx285").values, load_profile("ev76c661").values
    assert other["metadata_overrides"]["full_well_e"] == {"profile": ev["full_well_e"], "bag": icx["full_well_e"]}
    assert other["metadata_overrides"]["sensor_type"]["bag"] == "ccd"
    same = replay(bag, "icx285", tmp_path / "o2", estimator=estimator, config=CONFIG, progress=False, plot=False)
    assert same["metadata_overrides"] == {}


def test_replay_params_file_of_a_robot(tmp_path, estimator, capsys):
    """``replay --params`` with a robot's params file: the monitor's settings taken from the sections that name it,
    every-node keys of other nodes named on the console and in the summary (``params_ignored``), not refused."""
    bag = simulate_bag(tmp_path / "r.mcap", "icx285", "gain_sweep", frames=4, width=96, height=64, hold_s=0)
    params = tmp_path / "robot.yaml"
    params.write_text("camera_driver:\n  ros__parameters:\n    exposure_auto: 1\n"
                      "/**:\n  ros__parameters:\n    frame_prefix: robot1/\n    use_sim_time: true\n"
                      "noise_monitor:\n  ros__parameters:\n    xi_threshold_dn: 2.5\n")
    out = replay(bag, "icx285", None, config=params, estimator=estimator, progress=False, plot=False)
    assert out["frames_processed"] == 4 and out["config"]["xi_threshold_dn"] == 2.5
    assert out["params_ignored"] == ["frame_prefix"]
    assert main(["replay", str(bag), "--profile", "icx285", "--params", str(params), "--no-plot"]) == 0
    assert "note: parameter(s) frame_prefix of the params file's every-node section" in capsys.readouterr().out


def test_replay_names_the_camera_by_its_drivers_id(tmp_path, estimator):
    """As the node does: the metadata's hardware_id (the driver's device id) names the camera unless the
    hardware_id parameter is set (until 2026-11-29 replay said '<PROFILE>/camera', the node and campaign the id)."""
    bag = simulate_bag(tmp_path / "r.mcap", "icx285", "gain_sweep", frames=3, width=96, height=64, hold_s=0,
                       hardware_id="robot1/front")
    kw = {"estimator": estimator, "progress": False, "plot": False}
    assert replay(bag, "icx285", None, **kw)["hardware_id"] == "robot1/front"
    assert replay(bag, "icx285", None, hardware_id="left-front", **kw)["hardware_id"] == "left-front"


def test_a_stale_index_listing_fewer_images_than_the_storage_holds(tmp_path, estimator, capsys):
    """A recording whose metadata.yaml was written before its last images (a recorder stopped hard, a bag edited):
    every image in the storage is replayed and the summary says how many lie beyond the index (until 2026-12-04 the
    whole bag was replayed, then refused: "read 6 images but its index lists 3", no outputs). An index listing more
    than the storage holds is still refused: images are missing."""
    import yaml

    bag = simulate_bag(tmp_path / "stale", "icx285", "static", frames=6, width=96, height=64, hold_s=0.0)
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())
    for topic in meta["rosbag2_bagfile_information"]["topics_with_message_count"]:
        if topic["topic_metadata"]["name"].endswith("image_raw"):
            topic["message_count"] = 3
    (bag / "metadata.yaml").write_text(yaml.safe_dump(meta))
    s = replay(bag, "icx285", tmp_path / "out", estimator=estimator, progress=False, plot=False)
    assert (s["frames_total"], s["frames_processed"], s["frames_beyond_index"]) == (6, 6, 3)
    print_summary(s)
    assert "index (metadata.yaml) lists 3 images; all 6 in its storage were replayed" in capsys.readouterr().out
    for topic in meta["rosbag2_bagfile_information"]["topics_with_message_count"]:
        topic["message_count"] = 9
    (bag / "metadata.yaml").write_text(yaml.safe_dump(meta))
    with pytest.raises(BagError, match="damaged: read 6 of the 9 messages"):
        replay(bag, "icx285", tmp_path / "out2", estimator=estimator, progress=False, plot=False)
