"""noise-monitor campaign: bit-exact per-frame results against replay, Ray = pool, bad input reported by
name, resume from the manifest, hung / crashing / memory-hungry bags, Ctrl-C, the report's trends."""
from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pa = pytest.importorskip("pyarrow")
import pyarrow.compute as pc  # noqa: E402
import pyarrow.parquet as pq  # noqa: E402

from noise_monitor.bag.replay import replay  # noqa: E402
from noise_monitor.bag.results import CONDITION_KEYS, FrameTable  # noqa: E402
from noise_monitor.bag.simulate import START_NS, simulate_bag  # noqa: E402
from noise_monitor.cli import main  # noqa: E402
from noise_monitor.fleet import run_campaign  # noqa: E402
from noise_monitor.fleet.report import trend  # noqa: E402
from noise_monitor.fleet.task import bag_dir  # noqa: E402
from noise_monitor.physics import load_profile  # noqa: E402
from noise_monitor.physics.metadata import CameraProfile  # noqa: E402

DAY_NS = 86400 * 10**9
#: Columns that measure time, not results (the processing time of a frame differs run to run).
TIMING = {"processing_ms"}
PLUGIN = '''
import os, signal, time
import numpy as np
from noise_monitor.physics.effects import Effect, Param

class Hang(Effect):
    name = "test_hang"
    distribution = "gaussian"
    params = (Param("seconds", "s", 600.0, (0.0, 1e5), fittable=False),)
    description = "sleeps: a bag that hangs its worker"
    signature = "hang"

    def sigma_dn(self, signal_dn, cond):
        time.sleep(self.seconds)
        return np.zeros(np.shape(signal_dn))

class Crash(Effect):
    name = "test_crash"
    distribution = "gaussian"
    params = ()
    description = "kills its process: a bag that crashes its worker"
    signature = "crash"

    def sigma_dn(self, signal_dn, cond):
        os.kill(os.getpid(), signal.SIGKILL)
'''


def _sim(path: Path, hw: str, day: int, seed: int, profile: str | CameraProfile = "ev76c661",
         scenario: str = "static", frames: int = 6) -> Path:
    return simulate_bag(path, profile, scenario, frames=frames, width=128, height=128, seed=seed, hardware_id=hw,
                        start_ns=START_NS + day * DAY_NS)


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Good bags of two cameras, bad inputs, and the profile map / plug-in for hung and crashing bags."""
    root = tmp_path_factory.mktemp("fleet")
    good = root / "good"
    good.mkdir()
    for i in range(3):
        _sim(good / f"a{i}.mcap", "robot1/front", 7 * i, seed=i)
    _sim(good / "b0.mcap", "robot2/front", 3, seed=10, scenario="image_noise", frames=40)
    bad = root / "bad"
    bad.mkdir()
    (bad / "empty.mcap").write_bytes(b"")
    data = (good / "a0.mcap").read_bytes()
    (bad / "damaged.mcap").write_bytes(data[: len(data) // 2])
    shutil.copy(good / "a1.mcap", bad / "copy_of_a1.mcap")
    _sim(bad / "stranger.mcap", "robot9/rear", 1, seed=20)  # not in the profile map
    (bad / "notes.txt").write_text("not a bag")
    plugin = root / "effects.py"
    plugin.write_text(PLUGIN)
    prof = load_profile("ev76c661")
    for name, effects in (("hang", {"test_hang": {"seconds": 600.0}}), ("crash", {"test_crash": {}})):
        (root / f"{name}.yaml").write_text(CameraProfile(name, prof.values, effects).to_yaml())
    trouble = root / "trouble"
    trouble.mkdir()
    _sim(trouble / "hang.mcap", "robot7/hang", 2, seed=30)
    _sim(trouble / "crash.mcap", "robot8/crash", 2, seed=31)
    (root / "map.yaml").write_text("cameras:\n  robot1/*: ev76c661\n  robot2/front: ev76c661\n"
                                   "  robot7/hang: hang.yaml\n  robot8/crash: crash.yaml\n")
    return {"root": root, "good": good, "bad": bad, "trouble": trouble, "map": root / "map.yaml", "plugin": plugin}


@pytest.fixture(scope="module")
def pool_run(fleet: dict[str, Path], tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, Path]:
    out = tmp_path_factory.mktemp("pool_run")
    inputs = [fleet["good"], fleet["bad"], fleet["trouble"], fleet["root"] / "missing_bag.mcap",
              fleet["bad"] / "notes.txt"]
    c = run_campaign(inputs, out, profile_map=fleet["map"], plugins=[fleet["plugin"]], backend="pool", workers=2,
                     timeout_s=25.0, progress=False)
    return c, out


def _frames(out: Path, bag: str) -> pa.Table:
    t = pq.read_table(out / "frames.parquet")
    return t.filter(pc.equal(t["bag"], bag))


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return np.array_equal(np.asarray(a, np.float32).view(np.uint32), np.asarray(b, np.float32).view(np.uint32))


def test_per_frame_results_bit_exact_with_replay(pool_run: tuple[dict, Path]) -> None:
    c, out = pool_run
    assert len(c["bags"]) == 4
    for b in c["bags"]:
        table = FrameTable()
        summary = replay(b["path"], "ev76c661", None, progress=False, table=table)
        got = _frames(out, b["path"])
        assert got.num_rows == len(table) == b["frames_total"]
        assert got["index"].to_pylist() == table.column("index").tolist()
        assert got["processed"].to_pylist() == table.column("processed").tolist()
        assert got["skip_reason"].to_pylist() == table.texts("skip_reason")
        assert got["xi_measurement"].to_pylist() == table.texts("xi_measurement")
        assert set(got["xi_measurement"].to_pylist()) <= {"image", "temporal", "bound", None}
        keys = [k for k in (*CONDITION_KEYS, *table.number_keys) if k not in TIMING]
        assert "xi" in keys and "sigma_dcsn" in keys
        for k in keys:
            assert _same_bits(got[k].to_numpy(), table.numbers(k)), k
        for k in ("xi", "sigma_pn", "sigma_dcsn", "sigma_rn", "sigma_image"):
            assert b["stats"][k] == summary[k]
        assert b["alarm_episodes"] == len(summary["alarms"])


def test_bad_inputs_reported_by_name_and_rest_completes(pool_run: tuple[dict, Path], fleet: dict[str, Path]) -> None:
    c, _ = pool_run
    reasons = {Path(p["path"]).name: p["reason"] for p in (*c["failed"], *c["duplicates"], *c["problems"])}
    assert "empty" in reasons["empty.mcap"]
    assert "damaged" in reasons["damaged.mcap"] or "cannot read" in reasons["damaged.mcap"]
    assert reasons["copy_of_a1.mcap"].startswith(f"duplicate of {(fleet['good'] / 'a1.mcap').resolve()}")
    assert "robot9/rear" in reasons["stranger.mcap"] and "not in the profile map" in reasons["stranger.mcap"]
    assert "not a bag" in reasons["notes.txt"]
    assert "does not exist" in reasons["missing_bag.mcap"]
    assert "timed out after 25 s" in reasons["hang.mcap"]
    assert "killed by SIGKILL" in reasons["crash.mcap"]
    t = c["totals"]
    assert (t["bags_found"], t["bags_evaluated"], t["bags_failed"], t["bags_duplicate"], t["inputs_rejected"]) == \
        (10, 4, 5, 1, 2)
    assert t["frames_total"] == 3 * 6 + 40 and t["cameras"] == 2
    # a camera whose every bag failed is named (until 2026-12-04 it was missing from every camera list); those of
    # workers killed (hang, crash) are not known to the driver
    assert c["cameras_not_evaluated"] == [{"hardware_id": "robot9/rear", "bags_failed": 1,
                                           "reason": reasons["stranger.mcap"]}]


def test_report_outputs_and_alarm_times(pool_run: tuple[dict, Path]) -> None:
    c, out = pool_run
    on_disk = json.loads((out / "campaign.json").read_text())
    assert on_disk["totals"] == c["totals"]
    assert pq.read_table(out / "frames.parquet").num_rows == c["totals"]["frames_total"] == c["frames_in_table"]
    html = (out / "report.html").read_text()
    assert "data:image/png;base64," in html and "robot1/front" in html and "empty.mcap" in html
    noisy = next(cam for cam in c["cameras"] if cam["hardware_id"] == "robot2/front")
    assert noisy["alarm_episodes"] >= 1 and noisy["health_limited_by"] in ("alarm", "xi_bias")
    assert c["cameras"][0]["hardware_id"] == "robot2/front"  # the camera with unexpected noise ranks worst
    # its episode starts and ends while the camera holds still: both changes are counted and named
    assert noisy["temporal_noise_changes"] == c["totals"]["temporal_noise_changes"] == 2
    assert any("the noise changed suddenly 2 time(s)" in f for f in noisy["findings"])
    ep = c["alarm_episodes"][0]
    assert ep["start_utc"].startswith("2023-11-17T") and ep["start_utc"].endswith("Z")  # START_NS + 3 days, UTC


def test_steps_of_the_light_are_counted_per_bag_camera_and_campaign(lamp_bag: Path, tmp_path: Path) -> None:
    c = run_campaign([lamp_bag], tmp_path / "out", profile="ev76c661", backend="pool", workers=1, progress=False)
    (cam,) = c["cameras"]
    assert c["bags"][0]["temporal_light_steps"] == cam["temporal_light_steps"] == c["totals"]["temporal_light_steps"] == 1
    assert cam["temporal_noise_changes"] == 0
    assert any("the light stepped 1 time(s) while the camera held still" in f for f in cam["findings"])
    stats = c["bags"][0]["stats"]  # the still views' frame differences beside their model, per bag
    assert stats["sigma_temporal"]["n"] == stats["sigma_temporal_model"]["n"] >= 20
    assert abs(stats["sigma_temporal"]["mean"] - stats["sigma_temporal_model"]["mean"]) < 0.1


def test_resume_skips_finished_bags_and_survives_a_torn_manifest(pool_run: tuple[dict, Path],
                                                                  fleet: dict[str, Path]) -> None:
    c, out = pool_run
    with open(out / "manifest.jsonl", "a") as fh:
        fh.write('{"path": "/torn', )  # a driver killed mid-write
    again = run_campaign([fleet["good"]], out, profile_map=fleet["map"], plugins=[fleet["plugin"]], backend="pool",
                         workers=2, progress=False)
    assert again["run"]["bags_run"] == 0 and again["run"]["bags_resumed"] == 4
    assert [b["stats"] for b in again["bags"]] == [b["stats"] for b in c["bags"] if "/good/" in b["path"]]
    lines = (out / "manifest.jsonl").read_text().splitlines()
    assert sum(1 for ln in lines if ln.startswith('{"path": "/torn')) == 1


def test_runs_with_other_settings_keep_their_own_results(fleet: dict[str, Path], tmp_path: Path) -> None:
    """One --out, three runs: default params, a threshold of 5 DN, the defaults again (resumed), then with
    --bag-outputs. Each settings' bags have their own folder, so the resumed run's campaign.json, frames.parquet and
    the bags' summaries agree (until 2026-11-29 the folder was the bag's alone: the resume merged the other run's
    files under the 1.0 DN summary; the default node.yaml, bundled profiles and weights were not in the settings
    key, and --bag-outputs on a finished campaign wrote nothing)."""
    bags = [fleet["good"] / "a0.mcap", fleet["good"] / "b0.mcap"]
    params = tmp_path / "node.yaml"
    params.write_text("/**:\n  ros__parameters:\n    xi_threshold_dn: 5.0\n")
    kw = {"profile": "ev76c661", "backend": "pool", "workers": 2, "progress": False}
    first = run_campaign(bags, tmp_path / "out", **kw)
    other = run_campaign(bags, tmp_path / "out", params=str(params), **kw)
    again = run_campaign(bags, tmp_path / "out", **kw)
    assert first["settings"]["key"] != other["settings"]["key"]
    assert again["run"]["bags_resumed"] == 2 and again["settings"]["key"] == first["settings"]["key"]
    alarms = sum(pq.read_table(tmp_path / "out" / "frames.parquet")["alarm"].to_pylist())
    assert alarms == sum(b["frames_in_alarm"] for b in again["bags"]) == sum(b["frames_in_alarm"] for b in first["bags"])
    assert sum(b["frames_in_alarm"] for b in other["bags"]) < alarms  # at 5 DN fewer frames alarm
    outputs = run_campaign(bags, tmp_path / "out", bag_outputs=True, **kw)
    assert outputs["run"]["bags_run"] == 2
    for b in outputs["bags"]:
        assert (bag_dir(tmp_path / "out", b["sha256"], outputs["settings"]["key"]) / "replay.csv").is_file()


def test_frames_lost_and_skip_reasons_reach_the_campaign(tmp_path: Path) -> None:
    """A recording with frames 3, 4 and 9 missing (lost before the recorder) and one image of an unusable encoding: the
    campaign's bag, camera and totals count them as the replay does (frames_lost, skip_reasons), and the report
    names them (until 2026-11-29 frames_lost stopped at the bag's summary.json and the report had no skip reasons)."""
    import dataclasses
    from html import escape

    from noise_monitor.bag.reader import open_bag
    from noise_monitor.bag.writer import BagWriter

    src = _sim(tmp_path / "src.mcap", "robot5/front", 0, seed=3, frames=14)
    bag = tmp_path / "gaps.mcap"
    with open_bag(src) as reader, BagWriter(bag) as w:
        images = metas = 0
        for topic, log_time, msg in reader.messages(sorted(reader.topics)):
            if topic == reader.image_topic:
                images += 1
                if images - 1 in (3, 4, 9):
                    continue
                if images - 1 == 12:
                    msg = dataclasses.replace(msg, encoding="nv21")
            if topic == reader.metadata_topic:
                metas += 1
                if metas - 1 in (3, 4, 9):
                    continue
            w.write(topic, msg, log_time)
    ref = replay(bag, "ev76c661", None, progress=False, plot=False)
    assert ref["frames_lost"] == 3 and ref["frames_skipped"] == 1
    c = run_campaign([bag], tmp_path / "out", profile="ev76c661", backend="pool", workers=1, progress=False)
    b, cam, t = c["bags"][0], c["cameras"][0], c["totals"]
    assert b["frames_lost"] == cam["frames_lost"] == t["frames_lost"] == 3
    assert b["skip_reasons"] == cam["skip_reasons"] == t["skip_reasons"] == ref["skip_reasons"]
    html = (tmp_path / "out" / "report.html").read_text()
    assert "3 missing from the recordings by their stamps" in html and "Frames skipped, by reason" in html
    assert escape(next(iter(ref["skip_reasons"]))) in html


def test_a_stereo_bag_is_evaluated_camera_by_camera(tmp_path: Path) -> None:
    """One recording with /left and /right cameras: without a choice it is reported (the replay's reason names
    --image-topic, which campaign now takes: before 2026-11-29 it had no such option and the bag's frames were
    lost); with --image-topic each camera's frames are evaluated as its own replay gives them."""
    from noise_monitor.bag.reader import open_bag
    from noise_monitor.bag.writer import BagWriter

    parts = [simulate_bag(tmp_path / f"{side}.mcap", "ev76c661", "static", frames=5, width=96, height=96, seed=i,
                          hardware_id=f"robot6/{side}", namespace=f"/{side}") for i, side in enumerate(("left", "right"))]
    stereo = tmp_path / "stereo.mcap"
    with BagWriter(stereo) as w:
        for part in parts:
            with open_bag(part) as reader:
                for topic, log_time, msg in reader.messages(sorted(reader.topics)):
                    w.write(topic, msg, log_time)
    kw = {"profile": "ev76c661", "backend": "pool", "workers": 1, "progress": False}
    both = run_campaign([stereo], tmp_path / "both", **kw)
    assert both["totals"]["bags_failed"] == 1 and "--image-topic" in both["failed"][0]["reason"]
    for side in ("left", "right"):
        c = run_campaign([stereo], tmp_path / side, image_topic=f"/{side}/image_raw", **kw)
        ref = replay(tmp_path / f"{side}.mcap", "ev76c661", None, progress=False, plot=False)
        assert c["bags"][0]["hardware_id"] == f"robot6/{side}" and c["totals"]["frames_processed"] == 5
        assert c["bags"][0]["stats"]["xi"] == ref["xi"]


def test_ray_gives_the_pool_results(pool_run: tuple[dict, Path], fleet: dict[str, Path], tmp_path: Path) -> None:
    pytest.importorskip("ray")
    c = run_campaign([fleet["good"]], tmp_path, profile_map=fleet["map"], backend="ray", workers=2, progress=False)
    assert c["run"]["backend"] == "ray" and c["totals"]["bags_evaluated"] == 4
    ref = pq.read_table(pool_run[1] / "frames.parquet").sort_by([("bag", "ascending"), ("index", "ascending")])
    got = pq.read_table(tmp_path / "frames.parquet").sort_by([("bag", "ascending"), ("index", "ascending")])
    assert got.num_rows == ref.num_rows == 3 * 6 + 40
    for k in got.column_names:
        if k in TIMING:
            continue
        if pa.types.is_floating(got.schema.field(k).type):
            assert _same_bits(got[k].to_numpy(), ref[k].to_numpy()), k
        else:
            assert got[k].to_pylist() == ref[k].to_pylist(), k


def test_unreachable_ray_and_worker_memory_limit_reported(fleet: dict[str, Path], tmp_path: Path) -> None:
    c = run_campaign([fleet["good"] / "a0.mcap"], tmp_path, profile="ev76c661", backend="ray",
                     ray_address="127.0.0.1:9", workers=1, memory_limit_mb=1.0, progress=False)
    # the backend's trouble is no rejected input (until 2026-12-04 the address was listed among them as a bag path)
    assert c["problems"] == [] and c["totals"]["inputs_rejected"] == 0
    note = c["run"]["backend_note"]
    assert note.startswith("Ray at 127.0.0.1:9") and "unreachable" in note and "local process pool" in note
    assert c["run"]["backend"] == "pool"
    assert c["failed"][0]["reason"].startswith("worker memory limit exceeded: resident")


def test_trend_at_equal_conditions() -> None:
    """A slope hidden behind a temperature that varies with time is recovered at equal temperature."""
    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(0, 8, 30)) * 7 * DAY_NS
    temp = 30 + 2.0 * t / (7 * DAY_NS) + rng.normal(0, 3, 30)  # warming up over the weeks
    y = 1.0 + 0.05 * t / (7 * DAY_NS) + 0.04 * (temp - 30) + rng.normal(0, 0.01, 30)
    tr = trend(t, y, {"sensor_temperature_c": temp, "gain_db": np.full(30, 12.0)})
    assert tr["adjusted_for"] == ["sensor_temperature_c"] and tr["significant"]
    assert abs(tr["slope_dn_per_week"] - 0.05) < 4 * tr["stderr_dn_per_week"] + 0.005
    naive = trend(t, y, {})
    assert naive["slope_dn_per_week"] > 0.1  # without the temperature the warming reads as drift
    flat = trend(t, 1.0 + rng.normal(0, 0.01, 30), {"sensor_temperature_c": temp})
    assert not flat["significant"]


def test_ageing_sensor_found_and_ranked(tmp_path: Path) -> None:
    """Dark current growing over four weeks at equal temperature: the DCSN trend is found, the camera ranks last."""
    prof = load_profile("ev76c661")
    for week in range(4):
        aged = CameraProfile(prof.name, {**prof.values,
                                         "dark_signal_fom_na_cm2": prof.values["dark_signal_fom_na_cm2"] * (1 + week / 2)})
        _sim(tmp_path / "bags" / f"old{week}.mcap", "robot3/old", 7 * week, seed=40 + week, profile=aged, frames=4)
        _sim(tmp_path / "bags" / f"new{week}.mcap", "robot4/new", 7 * week, seed=50 + week, frames=4)
    c = run_campaign([tmp_path / "bags"], tmp_path / "out", profile="ev76c661", backend="pool", workers=2,
                     progress=False)
    old, new = (next(x for x in c["cameras"] if x["hardware_id"] == hw) for hw in ("robot3/old", "robot4/new"))
    assert old["trends"]["sigma_dcsn"]["significant"] and old["trends"]["sigma_dcsn"]["slope_dn_per_week"] > 0.1
    assert not new["trends"]["sigma_dcsn"]["significant"]
    assert old["health_limited_by"] == "dcsn_growth" and old["rank"] < new["rank"]
    assert any("ageing sensor" in f for f in old["findings"])


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])  # Ctrl-C; systemd / Kubernetes stopping it
def test_ctrl_c_leaves_a_consistent_manifest_and_resumes(fleet: dict[str, Path], tmp_path: Path, sig: int) -> None:
    """(SIGTERM until 2026-11-29: no campaign.json written.)"""
    bags = tmp_path / "bags"
    bags.mkdir()
    for i in range(8):
        shutil.copy(fleet["good"] / f"a{i % 3}.mcap", bags / f"c{i}.mcap")  # 3 contents: 5 duplicates
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "noise_monitor.cli", "campaign", str(bags), "--out", str(out), "--profile",
           "ev76c661", "--pool", "--workers", "1", "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,  # Ctrl-C reaches it
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    manifest = out / "manifest.jsonl"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not (manifest.is_file() and manifest.read_text().count("\n") >= 6):
        time.sleep(0.05)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "re-run the same command to resume" in err
    entries = [json.loads(ln) for ln in manifest.read_text().splitlines()]
    assert 2 <= len(entries) < 8
    assert sum("duplicate_of" in e for e in entries) == 5  # recorded before any replay, never replayed
    for e in entries:  # every recorded bag has its complete outputs (a duplicate: its content's)
        assert e["status"] == "ok"
        if "duplicate_of" in e:
            continue
        d = bag_dir(out, e["sha256"], e["settings"])
        assert pq.read_table(d / "frames.parquet").num_rows == e["frames"]
        assert json.loads((d / "summary.json").read_text())["frames_total"] == e["frames"]
    assert json.loads((out / "campaign.json").read_text())["interrupted"] is True
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    c = json.loads((out / "campaign.json").read_text())
    assert c["run"]["bags_resumed"] == len(entries) and c["run"]["bags_run"] == 8 - len(entries)
    assert c["totals"]["bags_evaluated"] + c["totals"]["bags_duplicate"] == 8


def test_cli_unusable_campaign_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "map.yaml").write_text("cameras: [1, 2]\n")
    for extra, why in ((["--profile", "no_such_camera"], "no_such_camera"),
                       (["--profiles", str(tmp_path / "map.yaml")], "map.yaml")):
        assert main(["campaign", str(tmp_path), "--out", str(tmp_path / "out"), "--pool", *extra]) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("noise-monitor campaign: error:") and why in lines[0]


def test_simulate_bag_cli_sets_camera_id_and_start(tmp_path: Path) -> None:
    from noise_monitor.bag.reader import open_bag
    from noise_monitor.fleet.task import camera_id

    bag = tmp_path / "x.mcap"
    assert main(["simulate-bag", str(bag), "--profile", "ev76c661", "--scenario", "static", "--frames", "2",
                 "--width", "64", "--height", "64", "--hardware-id", "robot5/left", "--start",
                 "2026-05-01T08:00:00Z"]) == 0
    assert camera_id(bag) == "robot5/left"
    with open_bag(bag) as reader:
        assert reader.start_ns == 1_777_622_400 * 10**9
    assert main(["simulate-bag", str(bag), "--profile", "ev76c661", "--scenario", "static", "--start", "May"]) == 2


def test_merge_fills_what_an_older_part_lacks(tmp_path: Path) -> None:
    """A part written before a column existed (a resumed campaign): texts null, numbers NaN, rows kept."""
    import pyarrow as pa

    from noise_monitor.fleet.frames import merge

    new = pa.table({"index": pa.array([0, 1], pa.int64()), "xi_measurement": pa.array(["image", "bound"]),
                    "xi": pa.array([0.1, 0.2], pa.float32())})
    old = pa.table({"index": pa.array([0], pa.int64()), "sigma_extra": pa.array([1.5], pa.float32())})
    pq.write_table(new, tmp_path / "new.parquet")
    pq.write_table(old, tmp_path / "old.parquet")
    assert merge([(tmp_path / "new.parquet", "a.mcap"), (tmp_path / "old.parquet", "b.mcap")], tmp_path / "m.parquet") == 3
    m = pq.read_table(tmp_path / "m.parquet")
    assert m["bag"].to_pylist() == ["a.mcap", "a.mcap", "b.mcap"]
    assert m["xi_measurement"].to_pylist() == ["image", "bound", None]
    assert np.isnan(m["xi"].to_numpy()[2]) and np.isnan(m["sigma_extra"].to_numpy()[:2]).all()
    only_old = merge([(tmp_path / "old.parquet", "b.mcap")], tmp_path / "o.parquet")  # no part has the column
    assert only_old == 1 and "xi_measurement" not in pq.read_table(tmp_path / "o.parquet").column_names


def test_a_link_to_a_bag_is_a_duplicate_and_a_path_named_twice_counts_once(tmp_path: Path) -> None:
    """(Until 2026-11-29 a symlink to a bag found before was merged silently.)"""
    from noise_monitor.fleet.bags import find_bags

    bag = tmp_path / "a.mcap"
    bag.write_bytes(b"x")
    (tmp_path / "link.mcap").symlink_to(bag)
    bags, problems = find_bags([bag, tmp_path, bag])
    assert bags == [bag]
    assert [(Path(p.path).name, p.reason) for p in problems] == [
        ("link.mcap", f"duplicate of {bag} (the same file, linked): counted once")]
    ros1 = tmp_path / "ros1" / "field.bag"  # ROS 1 bags are campaign bags too
    ros1.parent.mkdir()
    ros1.write_bytes(b"x")
    assert find_bags([ros1.parent]) == ([ros1], []) and find_bags([ros1]) == ([ros1], [])


def test_a_copy_of_a_bag_is_replayed_once(fleet: dict[str, Path], tmp_path: Path) -> None:
    """Two copies of one bag beside another: the content is replayed once and the copy named its duplicate, and a
    copy added to the finished campaign is recorded without a replay. (Until 2026-11-29 both copies were replayed
    into the same folder: the one that finished last wrote its path into the shared summary.json.)"""
    bags = tmp_path / "bags"
    bags.mkdir()
    for name, source in (("a.mcap", "a0.mcap"), ("b.mcap", "b0.mcap"), ("c_copy_of_a.mcap", "a0.mcap")):
        shutil.copy(fleet["good"] / source, bags / name)
    kw = {"profile": "ev76c661", "backend": "pool", "workers": 2, "progress": False}
    out = tmp_path / "out"
    c = run_campaign([bags], out, **kw)
    assert c["run"]["bags_run"] == 2 and c["totals"]["bags_duplicate"] == 1
    first = str((bags / "a.mcap").resolve())
    assert [d["reason"].split(" (")[0] for d in c["duplicates"]] == [f"duplicate of {first}"]
    row = next(b for b in c["bags"] if b["path"] == first)
    assert json.loads((bag_dir(out, row["sha256"], c["settings"]["key"]) / "summary.json").read_text())["bag"] == first
    shutil.copy(fleet["good"] / "b0.mcap", bags / "d_copy_of_b.mcap")
    again = run_campaign([bags], out, **kw)
    assert again["run"]["bags_run"] == 0 and again["run"]["bags_resumed"] == 3
    assert again["totals"]["bags_duplicate"] == 2 and again["totals"]["bags_evaluated"] == 2


def test_an_output_folder_inside_the_inputs_is_not_searched(fleet: dict[str, Path], tmp_path: Path) -> None:
    """``campaign rec --out rec/campaign_out --bag-outputs`` twice: until 2026-12-04 the second run found the first's
    per-bag replays (MCAPs of the monitor's outputs) as bags and ranked a phantom camera, every frame "metadata
    missing"."""
    rec = tmp_path / "rec"
    rec.mkdir()
    for name in ("a0.mcap", "a1.mcap"):
        shutil.copy(fleet["good"] / name, rec / name)
    kw = {"profile": "ev76c661", "backend": "pool", "workers": 1, "progress": False, "bag_outputs": True}
    first = run_campaign([rec], rec / "campaign_out", **kw)
    again = run_campaign([rec], rec / "campaign_out", **kw)
    assert first["totals"]["bags_found"] == again["totals"]["bags_found"] == 2
    assert again["run"]["bags_resumed"] == 2 and again["totals"]["cameras"] == 1


def test_metadata_that_overrides_the_profile_is_named_per_camera(fleet: dict[str, Path], tmp_path: Path) -> None:
    """An ev76c661 bag (its metadata states the camera's constants) replayed under the icx285 profile: the bag's
    values win, as in replay and the node; until 2026-12-04 campaign.json and the report said nothing of it (the
    camera listed under "ICX285" with the numbers of the bag's own camera)."""
    c = run_campaign([fleet["good"] / "a0.mcap"], tmp_path / "out", profile="icx285", backend="pool", workers=1,
                     progress=False)
    cam = c["cameras"][0]
    assert cam["metadata_overrides"]["full_well_e"] == {"profile": 14000.0, "bag": 8400.0}
    assert any(f.startswith("the bags' metadata set camera constants over the profile's") and
               "full_well_e 8400.0 (profile 14000.0)" in f for f in cam["findings"])
    assert "full_well_e 8400.0 (profile 14000.0)" in (tmp_path / "out" / "report.html").read_text()


def test_ctrl_c_while_the_table_is_merged_leaves_campaign_json(fleet: dict[str, Path], tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """An interrupt while the per-frame table is merged (the bags all replayed): until 2026-12-04 no campaign.json was
    written (or an older one stayed, saying not interrupted) and frames.parquet.tmp was left behind."""
    kw = {"profile": "ev76c661", "backend": "pool", "workers": 1, "progress": False}
    bags = [fleet["good"] / "a0.mcap", fleet["good"] / "a1.mcap"]
    run_campaign(bags[:1], tmp_path / "out", **kw)  # an earlier campaign.json in the folder
    read = pq.read_table
    calls = []

    def interrupted(*args: object, **kwargs: object) -> object:
        calls.append(args)
        if len(calls) == 2:  # Ctrl-C after the first part is written
            raise KeyboardInterrupt
        return read(*args, **kwargs)

    monkeypatch.setattr(pq, "read_table", interrupted)
    with pytest.raises(KeyboardInterrupt, match="campaign interrupted: 2 of 2 bags finished"):
        run_campaign(bags, tmp_path / "out", **kw)
    monkeypatch.undo()
    c = json.loads((tmp_path / "out" / "campaign.json").read_text())
    assert c["interrupted"] and c["totals"]["bags_evaluated"] == 2 and "parquet" not in c["outputs"]
    assert not list((tmp_path / "out").glob("*.tmp")) and not list((tmp_path / "out").glob(".frames.parquet.*"))
    again = run_campaign(bags, tmp_path / "out", **kw)  # the resume writes the table and report
    assert not again["interrupted"] and again["frames_in_table"] == sum(b["frames_total"] for b in again["bags"])
