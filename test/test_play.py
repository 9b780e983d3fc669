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


def test_play_loops_until_stopped_and_rejects_bad_input(tmp_path, ros):
    from sensor_msgs.msg import Image

    bag = simulate_bag(tmp_path / "l.mcap", "icx285", "static", frames=3, width=16, height=16)
    listener = ros(rclpy.create_node("loop_listener"))
    images = []
    listener.create_subscription(Image, "/camera/image_raw", images.append, 10)
    stats = play(bag, rate=20.0, loop=True, wait_subscribers_s=20.0, wait_topics=["/camera/image_raw"], progress=False,
                 should_stop=lambda: len(images) >= 7)
    assert stats.loops >= 2 and stats.published["/camera/image_raw"] >= 7
    with pytest.raises(ValueError, match="rate must be > 0"):
        play(bag, rate=0.0)
    with pytest.raises(ValueError, match="not in bag"):
        play(bag, topics=["/nope"], progress=False)
