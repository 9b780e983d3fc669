"""Playback into live rclpy topics, and the live node on a played bag vs the offline replay."""
from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest
import rclpy
import torch
from rclpy.executors import SingleThreadedExecutor

from msg_adapters import metadata_from_diagnostics
from noise_monitor.bag.play import play
from noise_monitor.bag.reader import open_bag
from noise_monitor.bag.simulate import simulate_bag

torch.set_num_threads(1)


@pytest.fixture
def ros():
    """An rclpy context with a spinning executor; yields a function adding a node to it."""
    rclpy.init()
    executor = SingleThreadedExecutor()
    thread = threading.Thread(target=executor.spin, daemon=True)
    nodes = []

    def add(node):
        nodes.append(node)
        executor.add_node(node)
        return node

    thread.start()
    yield add
    executor.shutdown()
    for n in nodes:
        n.destroy_node()
    rclpy.shutdown()
    thread.join(timeout=5)


def _wait(cond, timeout: float = 20.0) -> bool:
    end = time.monotonic() + timeout
    while not cond() and time.monotonic() < end:
        time.sleep(0.02)
    return cond()


def _stamp(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def test_play_publishes_the_bag_bit_exact_with_its_stamps(tmp_path, ros):
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import Image

    bag = simulate_bag(tmp_path / "p.mcap", "icx285", "gain_sweep", frames=5, width=32, height=24, hold_s=0)
    listener = ros(rclpy.create_node("listener"))
    images, metas = [], []
    listener.create_subscription(Image, "/camera/image_raw", images.append, 10)
    listener.create_subscription(DiagnosticArray, "/camera/metadata", metas.append, 10)
    stats = play(bag, rate=10.0, wait_subscribers_s=20.0, progress=False)
    assert _wait(lambda: len(images) == 5 and len(metas) == 5)
    assert stats.published == {"/camera/camera_info": 5, "/camera/metadata": 5, "/camera/image_raw": 5}
    assert stats.loops == 1 and stats.unsupported == {}
    assert stats.wall_time_s >= stats.bag_duration_s / 10.0 - 1e-3  # original timing, 10x faster
    with open_bag(bag) as reader:
        frames = list(reader.frames())
    for f, img, meta in zip(frames, images, metas):
        assert _stamp(img) == f.stamp_ns == _stamp(meta)
        assert np.array_equal(np.asarray(img.data, np.uint8).reshape(24, 32), f.image_dn.astype(np.uint8))
        assert metadata_from_diagnostics(meta)["gain_db"] == pytest.approx(f.metadata.gain_db)


def test_play_publishes_the_bags_clock(tmp_path, ros):
    """``--clock``: the bag's time on /clock, at the clock rate while waiting and before every message (a node with
    use_sim_time sees each message at its own log time); never backwards; rates outside [0, 1000] Hz refused."""
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import Image

    bag = simulate_bag(tmp_path / "c.mcap", "icx285", "gain_sweep", frames=5, width=32, height=24, hold_s=0, fps=5.0)
    listener = ros(rclpy.create_node("clock_listener"))
    clocks, images = [], []
    listener.create_subscription(Clock, "/clock", lambda m: clocks.append(m.clock.sec * 10**9 + m.clock.nanosec), 100)
    listener.create_subscription(Image, "/camera/image_raw", images.append, 10)
    play(bag, rate=2.0, wait_subscribers_s=20.0, wait_topics=["/camera/image_raw", "/clock"], progress=False,
         clock_hz=50.0)
    assert _wait(lambda: len(images) == 5)
    with open_bag(bag) as reader:
        stamps = [f.log_time_ns for f in reader.frames()]
    assert clocks == sorted(clocks) and set(stamps) <= set(clocks)
    assert clocks[0] >= stamps[0] - 1 and clocks[-1] == stamps[-1]
    between = [c for c in clocks if stamps[0] < c < stamps[1]]  # 0.2 s of bag at rate 2 and 50 Hz: ~4 ticks
    assert 2 <= len(between) <= 8
    with pytest.raises(ValueError, match="clock_hz must be in"):
        play(bag, clock_hz=-1.0)


def test_play_loops_until_stopped_and_rejects_bad_input(tmp_path, ros):
    from sensor_msgs.msg import Image

    bag = simulate_bag(tmp_path / "l.mcap", "icx285", "static", frames=3, width=16, height=16)
    listener = ros(rclpy.create_node("loop_listener"))
    images = []
    listener.create_subscription(Image, "/camera/image_raw", images.append, 10)
    stats = play(bag, rate=20.0, loop=True, wait_subscribers_s=20.0, wait_topics=["/camera/image_raw"], progress=False,
                 should_stop=lambda: len(images) >= 7)
    assert stats.loops >= 2 and stats.published["/camera/image_raw"] >= 7
    with pytest.raises(ValueError, match=r"rate must be in \[0.001, 1000\], got 0"):
        play(bag, rate=0.0)
    with pytest.raises(ValueError, match="not in bag"):
        play(bag, topics=["/nope"], progress=False)


FIELDS = ("sigma_pn", "sigma_dcsn", "sigma_rn", "sigma_total", "xi")


def test_live_node_on_played_bag_agrees_with_offline_replay(tmp_path, ros):
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.parameter import Parameter

    from noise_monitor.bag.replay import replay
    from noise_monitor.estimator import load
    from noise_monitor.monitor import MonitorConfig
    from noise_monitor.node import node_class
    from noise_monitor.physics import load_profile

    estimator = load("full_meta", device="cpu")
    ps = estimator.patch_size
    bag = simulate_bag(tmp_path / "n.mcap", "ev76c661", "image_noise", frames=12, width=2 * ps, height=2 * ps,
                       seed=5, hold_s=0)
    monitor_cfg = {"patches_per_frame": 4, "alarm_min_frames": 2, "clear_min_frames": 2}
    offline = replay(bag, "ev76c661", tmp_path / "replay", estimator=estimator, config=MonitorConfig(**monitor_cfg),
                     progress=False, plot=False)
    node = ros(node_class()(estimator=estimator, parameter_overrides=[
        Parameter(k, value=v) for k, v in {"image_topic": "/camera/image_raw", "metadata_topic": "/camera/metadata",
                                           "camera_info_topic": "/camera/camera_info", "profile": "ev76c661",
                                           "threads": 1, **monitor_cfg}.items()]))
    meta = load_profile("ev76c661").metadata(gain_db=6.0, exposure_time_s=0.02, sensor_temperature_c=35.0)
    node.monitor.model.predict(np.full((8, 8), 100.0), meta)  # warm the node's model tables like the replay's
    live: dict[int, dict[str, str]] = {}
    listener = ros(rclpy.create_node("diag_listener"))
    listener.create_subscription(DiagnosticArray, f"{node.get_fully_qualified_name()}/frame", lambda m: live.update(
        {_stamp(m): {kv.key: kv.value for kv in m.status[0].values}}), 50)  # every frame's status
    stats = play(bag, rate=0.5, wait_subscribers_s=20.0, progress=False)
    assert stats.published["/camera/image_raw"] == 12
    stamps = [r["stamp_ns"] for r in _csv_rows(tmp_path / "replay" / "replay.csv")]
    assert _wait(lambda: stamps[-1] in live)  # the newest frame is always evaluated (1-slot queue)
    counters = node.monitor.counters
    evaluated = [s for s in stamps if s in live and "sigma_pn" in live[s]]
    assert len(evaluated) == counters["frames_processed"] >= 6  # at most a few dropped while busy
    offline_rows = {r["stamp_ns"]: r for r in _csv_rows(tmp_path / "replay" / "replay.csv")}
    for s in evaluated:  # same pipeline, same input: per-frame values agree to the printed precision
        for key in FIELDS:
            assert float(live[s][key]) == pytest.approx(float(offline_rows[s][key]), rel=1e-4, abs=1e-4), (s, key)
    if counters["frames_dropped"] == 0:  # identical sequence: filtered xi and alarm episodes agree too
        for s in stamps:
            assert float(live[s]["xi_filtered"]) == pytest.approx(float(offline_rows[s]["xi_filtered"]), abs=1e-4)
        assert node.monitor.alarm.state.episodes == len(offline["alarms"])


def _csv_rows(path: Path) -> list[dict]:
    import csv

    with open(path) as fh:
        return [{**r, "stamp_ns": int(r["stamp_ns"])} for r in csv.DictReader(fh)]
