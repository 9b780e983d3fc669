"""Reliability round two (issue 16): data loss and hangs in replay, frames_lost from bogus stamps, one-line
exit 2 for every user error, plug-ins that exit or shadow built-ins, unbounded strings from bags, and
one parameter validation for node and replay. Hostile inputs are generated here, small and fast.
"""
from __future__ import annotations

import csv
import json
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
import torch
from mcap.reader import make_reader

from msg_adapters.outputs import DIAGNOSTICS_TOPIC
from noise_monitor.bag import BagError
from noise_monitor.bag.messages import header, image_msg, metadata_msg
from noise_monitor.bag.reader import open_bag
from noise_monitor.bag.replay import MAX_IDLE_REPORTS_PER_GAP, replay
from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.bag.writer import BagWriter, typestore
from noise_monitor.cli import main
from noise_monitor.monitor import GapCounter, MonitorConfig
from noise_monitor.monitor.runtime import resolve_parameters
from noise_monitor.physics import load_profile
from noise_monitor.physics.effects import registry

torch.set_num_threads(1)
PROFILE = load_profile("icx285")
META = PROFILE.metadata(gain_db=12.0, exposure_time_s=0.01, sensor_temperature_c=30.0)
CONFIG = MonitorConfig(patches_per_frame=2)
T0 = 1_700_000_000 * 10**9
REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def estimator():
    from noise_monitor.estimator import load

    return load("full_meta", device="cpu")


@pytest.fixture(scope="module")
def small_bag(tmp_path_factory) -> Path:
    return simulate_bag(tmp_path_factory.mktemp("b") / "small.mcap", "icx285", "static", frames=4, width=64,
                        height=64, hold_s=0.0)


def textured(size: int, seed: int = 0) -> np.ndarray:
    y, x = np.mgrid[0:size, 0:size]
    clean = 60 + 100 * (x + y) / (2 * size)
    return np.clip(np.rint(clean + np.random.default_rng(seed).normal(0, 2.0, clean.shape)), 0, 255).astype(np.uint8)


@contextmanager
def deadline(seconds: int):
    """Fail instead of hanging (the behaviour before the fix was an endless loop)."""
    def expire(*_):
        raise TimeoutError(f"did not finish within {seconds} s")

    old = signal.signal(signal.SIGALRM, expire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def one_error_line(err: str, command: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip() and "%|" not in ln]
    assert len(lines) == 1 and lines[0].startswith(f"noise-monitor {command}: error: "), err
    assert "Traceback" not in err
    return lines[0]


def params_file(path: Path, **values) -> Path:
    body = "".join(f"    {k}: {v}\n" for k, v in values.items())
    path.write_text(f"noise_monitor:\n  ros__parameters:\n{body}")
    return path


# --- 4. replay never ends ---------------------------------------------------------------------------
def test_log_time_jump_from_1970_is_capped_not_a_billion_idle_reports(tmp_path, estimator):
    """A robot without a real-time clock: first frames in 1970, then the clock jumps to 2023."""
    size = estimator.patch_size
    stamps = [10**9, 10**9 + 10**8, T0, T0 + 10**8]
    bag = tmp_path / "rtc.mcap"
    with BagWriter(bag) as w:
        for i, s in enumerate(stamps):
            w.write("/camera/metadata", metadata_msg(META, s, "t"), s)
            w.write("/camera/image_raw", image_msg(textured(size, i), s), s)
    with deadline(120):
        s = replay(bag, PROFILE, tmp_path / "o", estimator=estimator, config=CONFIG, progress=False, plot=False)
    assert s["frames_total"] == 4 and s["frames_processed"] == 4 and s["idle_gaps_capped"] == 1
    with open(tmp_path / "o" / "replay.mcap", "rb") as fh:
        n = sum(1 for _ in make_reader(fh).iter_messages(topics=[DIAGNOSTICS_TOPIC]))
    assert n == MAX_IDLE_REPORTS_PER_GAP + 1  # the capped gap (the first period's summary included) + the last period


@pytest.mark.parametrize("rate", ["0", "-1", "1e-320", "1.0e+400", "1e6", ".nan"])
def test_replay_validates_diagnostics_rate_as_the_node_does(tmp_path, small_bag, capsys, rate):
    params = params_file(tmp_path / "p.yaml", diagnostics_rate_hz=rate)
    with deadline(60):
        code = main(["replay", str(small_bag), "--params", str(params), "--out", str(tmp_path / "o"), "--no-plot"])
    assert code == 2
    assert "parameter diagnostics_rate_hz must be" in one_error_line(capsys.readouterr().err, "replay")
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


# --- 5. the input is never an output ------------------------------------------------------------------
def test_replay_refuses_to_overwrite_its_input_bag(tmp_path, small_bag, capsys):
    out = tmp_path / "out"
    out.mkdir()
    bag = shutil.copy(small_bag, out / "replay.mcap")
    before = Path(bag).read_bytes()
    assert main(["replay", str(bag), "--out", str(out), "--no-plot"]) == 2
    assert "is the input" in one_error_line(capsys.readouterr().err, "replay")
    assert Path(bag).read_bytes() == before
    assert main(["replay", str(small_bag), "--out", str(tmp_path / "o2"), "--json", str(small_bag)]) == 2
    assert "is the input" in one_error_line(capsys.readouterr().err, "replay")
    folder = simulate_bag(tmp_path / "folder_bag", "icx285", "static", frames=2, width=64, height=64, hold_s=0.0)
    with pytest.raises(BagError, match="is the input bag folder"):
        replay(folder, PROFILE, folder, config=CONFIG, progress=False)


# --- 6./7. a run's outputs appear together or not at all -------------------------------------------------
class FailingEstimator:
    """The real estimator until frame ``n``, then ``exc`` (a crash, or Ctrl-C)."""

    def __init__(self, inner, n: int, exc: BaseException) -> None:
        self.inner, self.n, self.exc, self.calls = inner, n, exc, 0
        self.name, self.patch_size = inner.name, inner.patch_size

    def predict(self, patches, metas):
        self.calls += 1
        if self.calls > self.n:
            raise self.exc
        return self.inner.predict(patches, metas)


@pytest.mark.parametrize("exc", [RuntimeError("device lost"), KeyboardInterrupt()])
def test_failed_replay_leaves_the_previous_outputs_untouched(tmp_path, small_bag, estimator, exc):
    out = tmp_path / "out"
    replay(small_bag, PROFILE, out, estimator=estimator, config=CONFIG, progress=False)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert sorted(before) == ["replay.csv", "replay.mcap", "replay.png", "summary.json"]
    with pytest.raises(type(exc)):
        replay(small_bag, PROFILE, out, estimator=FailingEstimator(estimator, 2, exc), config=CONFIG, progress=False)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before  # no temporary files, nothing replaced


def test_outputs_of_the_previous_run_that_this_run_does_not_write_are_removed(tmp_path, small_bag, estimator):
    out = tmp_path / "out"
    replay(small_bag, PROFILE, out, estimator=estimator, config=CONFIG, progress=False)
    s = replay(small_bag, PROFILE, out, estimator=estimator, config=CONFIG, progress=False, plot=False)
    assert sorted(p.name for p in out.iterdir()) == ["replay.csv", "replay.mcap", "summary.json"]
    assert "png" not in s["outputs"]


def test_sigterm_during_replay_leaves_no_temporary_files(tmp_path):
    bag = simulate_bag(tmp_path / "long.mcap", "icx285", "static", frames=400, width=128, height=128, hold_s=0.0)
    out = tmp_path / "out"
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "noise_monitor.cli", "replay", str(bag), "--out", str(out),
                             "--no-plot", "--threads", "1"], cwd=REPO, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    try:
        t_end = time.monotonic() + 120
        while not list(out.glob(".staging-*/.bagwrite-*")) and time.monotonic() < t_end and proc.poll() is None:
            time.sleep(0.05)
        assert proc.poll() is None, "the replay ended before it could be terminated"
        time.sleep(0.3)  # inside the frame loop, MCAP half written
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 128 + signal.SIGTERM and "Traceback" not in err, err
    assert not out.exists()  # no partial MCAP folder, no staging folder, no outputs: not even the folder it made


def test_output_into_a_closed_pipe_stops_quietly():
    """`noise-monitor effects | head -1`: the reader gone, the command stops without a traceback or an error line,
    with the shell's status of a SIGPIPE (until 2026-12-04: 'error: [Errno 32] Broken pipe', exit 2)."""
    read_end, write_end = os.pipe()
    os.close(read_end)  # no reader: the first write fails
    try:
        proc = subprocess.run([sys.executable, "-m", "noise_monitor.cli", "effects"], cwd=REPO, stdout=write_end,
                              stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(write_end)
    assert proc.returncode == 128 + signal.SIGPIPE and proc.stderr == "", proc.stderr


# --- 8. frames_lost from stamp gaps ------------------------------------------------------------------
def test_stamps_1ns_apart_are_implausible_not_two_billion_lost_frames():
    gaps = GapCounter()
    stamps = [T0 + i for i in range(20)] + [T0 + 19 + 2 * 10**8, T0 + 19 + 4 * 10**8]  # 1 ns apart, then 0.2 s
    lost = [gaps.observe(s) for s in stamps]
    assert sum(lost) == 0 and gaps.implausible >= 1
    real = GapCounter()  # a 30 Hz camera losing 2 frames is still counted
    assert sum(real.observe(T0 + k * 33_333_333) for k in [*range(10), 12]) + real.flush() == 2
    assert real.implausible == 0
    with pytest.raises(ValueError, match="expected_rate_hz"):
        GapCounter(expected_rate_hz=1e12)


# --- 9. every user error: exit 2 and one line ------------------------------------------------------------
@pytest.mark.parametrize("value", ["1.0e+400", "1e400"])
def test_patches_per_frame_overflow_is_exit_2(tmp_path, small_bag, capsys, value):
    params = params_file(tmp_path / "p.yaml", patches_per_frame=value)
    assert main(["replay", str(small_bag), "--params", str(params), "--out", str(tmp_path / "o")]) == 2
    assert "parameter patches_per_frame must be of type int, got inf" in one_error_line(capsys.readouterr().err,
                                                                                         "replay")
    with pytest.raises(ValueError, match="patches_per_frame must be an integer, got inf"):
        MonitorConfig(patches_per_frame=float("inf"))  # the lab builds configs without the parameter table


@pytest.mark.parametrize("line,needle", [
    ("full_well_e: 1e400", "full_well_e is not finite"),
    ("bit_depth: [8]", "bit_depth must be an integer"),
    ("effects: {prnu: 5}", "effect 'prnu' has 5"),
    ("effects: {prnu: {percent: [1]}}", "must be a finite number"),
    ("name: [a, b]", "'name' must be a text"),
    ("gain_db: [1", "not valid YAML"),
])
def test_bad_camera_profiles_are_exit_2_with_one_line(tmp_path, small_bag, capsys, line, needle):
    prof = tmp_path / "cam.yaml"
    prof.write_text(PROFILE.to_yaml().replace("name: ICX285", "name: cam") + line + "\n")
    assert main(["replay", str(small_bag), "--profile", str(prof), "--out", str(tmp_path / "o")]) == 2
    assert needle in one_error_line(capsys.readouterr().err, "replay")


def test_a_profile_path_that_names_no_file_is_no_bundled_profile(tmp_path, small_bag, capsys):
    """A mistyped profile path is an error, never the bundled profile of its stem (before: ``/no/dir/generic.yaml``
    ran as ``generic``); a profile file is read whatever its suffix; a bare name is a bundled profile."""
    for typo in ("/no/such/dir/generic.yaml", "typo_dir/ICX285.yml"):
        assert main(["replay", str(small_bag), "--profile", typo, "--out", str(tmp_path / "o")]) == 2
        assert f"camera profile file '{typo}' not found" in one_error_line(capsys.readouterr().err, "replay")
    assert main(["replay", str(small_bag), "--profile", "nosuchcam", "--out", str(tmp_path / "o")]) == 2
    assert "icx285" in one_error_line(capsys.readouterr().err, "replay")  # the bundled names are listed
    saved = tmp_path / "cam.json"
    saved.write_text(PROFILE.to_yaml())
    assert load_profile(saved).name == PROFILE.name
    assert load_profile("ICX285").name == PROFILE.name


def test_sqlite3_row_with_null_data_is_a_named_skip_and_a_play_error(tmp_path, capsys):
    bag = simulate_bag(tmp_path / "sq", "icx285", "static", frames=3, width=64, height=64, hold_s=0.0,
                       storage="sqlite3")
    con = sqlite3.connect(next(bag.glob("*.db3")))
    # a hand-made (or damaged) database without rosbag2's NOT NULL constraint on the data column
    con.executescript("create table m2 as select * from messages; drop table messages; "
                      "alter table m2 rename to messages;")
    con.execute("update messages set data = NULL where id = (select m.id from messages m join topics t on "
                "m.topic_id = t.id where t.name = '/camera/image_raw' order by m.timestamp limit 1 offset 1)")
    con.commit()
    con.close()
    with open_bag(bag) as r:
        frames = list(r.frames(PROFILE))
    assert [f.skip_reason is None for f in frames] == [True, False, True]
    assert "no data (NULL)" in frames[1].skip_reason
    assert main(["play", str(bag), "--rate", "1000"]) == 2
    assert "has no data (NULL)" in one_error_line(capsys.readouterr().err, "play")


@pytest.mark.parametrize("argv,command,needle", [
    (["play", "{bag}", "--rate", "1e-300"], "play", "rate must be in [0.001, 1000]"),
    (["play", "{bag}", "--rate", "nan"], "play", "rate must be in"),
    # before 2026-12-04: accepted, and no /clock published
    (["play", "{bag}", "--clock", "0"], "play", "--clock must be > 0 Hz, got 0 (leave it out for no /clock)"),
    (["simulate-bag", "{tmp}/x.mcap", "--profile", "icx285", "--scenario", "static", "--width", "1000000",
      "--height", "1000000"], "simulate-bag", "width must be in [8, 8192] pixels"),
    (["simulate-bag", "{tmp}/x.mcap", "--profile", "icx285", "--scenario", "static", "--fps", "inf"],
     "simulate-bag", "fps must be in"),
    (["replay", "{bag}", "--bit-depth", "99", "--out", "{tmp}/o"], "replay", "bit_depth must be in 0..16"),
    # before: numpy's 'expected non-negative integer', naming no option
    (["simulate-bag", "{tmp}/x.mcap", "--profile", "icx285", "--scenario", "static", "--seed", "-1"],
     "simulate-bag", "seed must be a non-negative integer, got -1"),
])
def test_bad_arguments_are_exit_2_with_one_line(tmp_path, small_bag, capsys, argv, command, needle):
    argv = [a.format(bag=small_bag, tmp=tmp_path) for a in argv]
    assert main(argv) == 2
    assert needle in one_error_line(capsys.readouterr().err, command)
    assert not (tmp_path / "x.mcap").exists()


@pytest.mark.parametrize("bad", [{"bit_depth": 99}, {"diagnostics_rate_hz": 0.0}, {"diagnostics_rate_hz": 1e-320},
                                 {"diagnostics_rate_hz": 1e12}, {"color": "x" * 10**6}, {"threads": -1},
                                 {"black_level_dn": -2.0}, {"black_level_dn": 255.0}])
def test_node_and_replay_parameters_have_one_validation(bad):
    """The node declares and the replay reads the same parameters, checked by one function."""
    with pytest.raises(ValueError, match=f"parameter {next(iter(bad))}") as err:
        resolve_parameters(bad)
    assert len(str(err.value)) < 1000


def test_a_patch_size_the_estimator_refuses_is_refused_by_the_configuration():
    """Before, patch_size 8-15 passed the configuration and failed at the first frame in the estimator."""
    with pytest.raises(ValueError, match="patch_size must be 0 .estimator's. or >= 16"):
        MonitorConfig(patch_size=8)
    assert MonitorConfig(patch_size=16).patch_size == 16


def test_memory_error_has_a_reason(monkeypatch, capsys):
    from noise_monitor.bag import simulate_cmd

    def exhausted(*args, **kwargs):
        raise MemoryError()

    monkeypatch.setattr(simulate_cmd, "simulate_bag", exhausted)
    assert main(["simulate-bag", "x.mcap", "--profile", "icx285", "--scenario", "static"]) == 2
    assert "out of memory" in one_error_line(capsys.readouterr().err, "simulate-bag")


class Forbidden:
    """Not an allowed global for torch's weights-only unpickler."""


def test_torch_unpickling_error_is_one_line(tmp_path, small_bag, capsys):
    weights = tmp_path / "bad.pt"
    torch.save({"variant": "full_meta", "obj": Forbidden()}, weights)
    assert main(["replay", str(small_bag), "--weights", str(weights), "--out", str(tmp_path / "o")]) == 2
    assert "is not a readable checkpoint" in one_error_line(capsys.readouterr().err, "replay")


# --- 10. plug-ins --------------------------------------------------------------------------------------
EXITING = '''
import sys
from noise_monitor.physics.effects import Effect


class ExitingEffect(Effect):
    name = "exits_in_sigma"
    distribution = "gaussian"

    def sigma_dn(self, signal_dn, cond):
        sys.exit(0)
'''
SHADOWING = '''
import numpy as np
from noise_monitor.physics.effects import Effect


class MyReadNoise(Effect):
    name = "rn"
    distribution = "gaussian"
    description = "my own read noise"

    def sigma_dn(self, signal_dn, cond):
        return np.full(np.shape(signal_dn), 1.0)
'''


@pytest.fixture
def isolated_registry(monkeypatch):
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))


def test_plugin_calling_sys_exit_is_contained(tmp_path, capsys, isolated_registry):
    plugin = tmp_path / "exiting.py"
    plugin.write_text(EXITING)
    code = main(["simulate-bag", str(tmp_path / "s.mcap"), "--profile", "icx285", "--scenario", "static",
                 "--frames", "2", "--width", "64", "--height", "64", "--effect-plugin", str(plugin),
                 "--effect", "exits_in_sigma"])
    assert code == 2
    assert "effect 'exits_in_sigma' called sys.exit(0)" in one_error_line(capsys.readouterr().err, "simulate-bag")
    at_import = tmp_path / "exits_at_import.py"
    at_import.write_text("import sys\nsys.exit(0)\n")
    assert main(["effects", "--effect-plugin", str(at_import)]) == 2
    assert "called sys.exit(0) while importing" in one_error_line(capsys.readouterr().err, "effects")


def test_plugin_calling_sys_exit_in_analyze_is_exit_2(tmp_path, capsys, isolated_registry):
    bag = simulate_bag(tmp_path / "lab.mcap", "icx285", "lab", frames=8, width=96, height=64, hold_s=0.0)
    plugin = tmp_path / "exiting.py"
    plugin.write_text(EXITING)
    code = main(["analyze", str(bag), "--profile", "icx285", "--effect-plugin", str(plugin), "--add-effect",
                 "exits_in_sigma:", "--no-estimator", "--quiet"])
    assert code == 2
    assert "called sys.exit(0)" in one_error_line(capsys.readouterr().err, "analyze")


def test_plugin_named_like_a_builtin_needs_the_override_flag(tmp_path, capsys, isolated_registry):
    plugin = tmp_path / "my_rn.py"
    plugin.write_text(SHADOWING)
    assert main(["effects", "--effect-plugin", str(plugin)]) == 2
    line = one_error_line(capsys.readouterr().err, "effects")
    assert "has the name of a built-in effect" in line and "--replace-builtin-effects" in line
    assert registry.effect_class("rn").__module__ != "noise_monitor_plugin_my_rn"
    assert main(["effects", "--effect-plugin", str(plugin), "--replace-builtin-effects"]) == 0
    assert "my own read noise" in capsys.readouterr().out
    assert registry.effect_class("rn").__name__ == "MyReadNoise"


# --- 11. unbounded strings from the bag ------------------------------------------------------------------
def test_megabyte_strings_from_a_bag_are_clipped_everywhere(tmp_path, estimator):
    size = estimator.patch_size
    t = typestore().types
    huge = "x" * 1_000_000
    bag = tmp_path / "strings.mcap"
    with BagWriter(bag) as w:
        for i in range(3):
            stamp = T0 + i * 10**8
            values = [t["diagnostic_msgs/msg/KeyValue"](key=k, value=str(v)) for k, v in META.as_dict().items()]
            if i == 1:
                values[0] = t["diagnostic_msgs/msg/KeyValue"](key="gain_db", value=huge)
            status = t["diagnostic_msgs/msg/DiagnosticStatus"](level=0, name="m", message="", hardware_id="h",
                                                               values=values)
            w.write("/camera/metadata", t["diagnostic_msgs/msg/DiagnosticArray"](header=header(stamp),
                                                                                  status=[status]), stamp)
            img = image_msg(textured(size, i), stamp)
            if i == 2:
                img.encoding = huge
            w.write("/camera/image_raw", img, stamp)
    out = tmp_path / "o"
    s = replay(bag, PROFILE, out, estimator=estimator, config=CONFIG, progress=False)
    assert s["frames_total"] == 3 and s["frames_processed"] == 1
    assert (out / "summary.json").stat().st_size < 50_000
    reasons = json.loads((out / "summary.json").read_text())["skip_reasons"]
    assert len(reasons) == 2 and all("more characters]" in r and len(r) < 1000 for r in reasons), reasons
    with open(out / "replay.csv", newline="") as fh:  # the csv module's field limit is 131072
        rows = list(csv.DictReader(fh))
    assert len(rows) == 3 and all(len(r["skip_reason"]) < 1000 for r in rows)
    with open(out / "replay.mcap", "rb") as fh:
        msgs = [m for _, _, m in make_reader(fh).iter_messages(topics=[DIAGNOSTICS_TOPIC])]
    assert all(m.data.__len__() < 5000 for m in msgs)
