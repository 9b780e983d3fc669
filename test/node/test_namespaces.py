"""Relative topic names over rclpy: two monitors in camera namespaces /cam1 and /cam2 with the default
parameters (image, metadata, camera_info, temperature) subscribe to their own camera's topics, publish
under their own ``~/`` and report apart on /diagnostics."""
from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
import torch

from msg_adapters import reports_from_msg
from noise_monitor.physics import NoiseModel, load_profile

torch.set_num_threads(1)
rclpy = pytest.importorskip("rclpy")

from builtin_interfaces.msg import Time  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from sensor_msgs.msg import Image  # noqa: E402

from noise_monitor.estimator import load  # noqa: E402
from noise_monitor.node import NoiseMonitorNode  # noqa: E402

TIMEOUT_S = 30.0
DYNAMIC = {"gain_db": 12.0, "exposure_time_s": 0.01, "sensor_temperature_c": 35.0}
SIZE = 192


def spin_until(executor: SingleThreadedExecutor, done: Callable[[], bool], timeout: float = TIMEOUT_S) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.02)
        if done():
            return True
    return False


def frame(stamp_ns: int, rng: np.random.Generator) -> tuple[Image, DiagnosticArray]:
    y, x = np.mgrid[0:SIZE, 0:SIZE].astype(np.float32)
    clean = 110 + 50 * np.sin(2 * np.pi * x / SIZE) * np.cos(np.pi * y / SIZE)
    noisy, _ = NoiseModel().simulate(clean, load_profile("icx285").metadata(**DYNAMIC), rng)
    img = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
    stamp = Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
    image = Image(height=SIZE, width=SIZE, encoding="mono8", step=SIZE, data=img.tobytes())
    image.header.stamp, image.header.frame_id = stamp, "cam1_optical"
    meta = DiagnosticArray(status=[DiagnosticStatus(name="camera", values=[
        KeyValue(key=k, value=repr(v)) for k, v in DYNAMIC.items()])])
    meta.header.stamp = stamp
    return image, meta


def test_two_camera_namespaces_do_not_collide():
    context = rclpy.Context()
    rclpy.init(context=context)
    estimator = load("full_meta", device="cpu")
    params = [Parameter("profile", value="icx285"), Parameter("patches_per_frame", value=2),
              Parameter("diagnostics_rate_hz", value=5.0), Parameter("device", value="cpu")]
    nodes = [NoiseMonitorNode(namespace=ns, parameter_overrides=params, context=context, estimator=estimator)
             for ns in ("/cam1", "/cam2")]
    probe = rclpy.create_node("namespace_probe", context=context)
    executor = SingleThreadedExecutor(context=context)
    try:
        for n in (*nodes, probe):
            executor.add_node(n)
        frames: dict[str, list[Any]] = {"/cam1": [], "/cam2": []}
        diagnostics: list[Any] = []
        for ns in frames:
            probe.create_subscription(DiagnosticArray, f"{ns}/noise_monitor/frame",
                                      lambda m, ns=ns: frames[ns].append(m), 10)
        probe.create_subscription(DiagnosticArray, "/diagnostics", lambda m: diagnostics.extend(reports_from_msg(m)), 50)
        pub_img = probe.create_publisher(Image, "/cam1/image", qos_profile_sensor_data)
        pub_meta = probe.create_publisher(DiagnosticArray, "/cam1/metadata", 10)
        # the relative defaults resolve in each namespace; nothing listens at the root
        for ns in ("/cam1", "/cam2"):
            for topic in ("image", "metadata", "camera_info", "temperature"):
                assert spin_until(executor, lambda t=f"{ns}/{topic}": probe.count_subscribers(t) == 1), (ns, topic)
            assert probe.count_publishers(f"{ns}/noise_monitor/sigma_rn") == 1
        for topic in ("/image", "/metadata", "/camera/image_raw"):
            assert probe.count_subscribers(topic) == 0, topic
        rng = np.random.default_rng(3)
        for i in range(3):  # only camera 1 sends frames
            image, meta = frame(10**12 + i * 33_333_333, rng)
            pub_meta.publish(meta)
            pub_img.publish(image)
            assert spin_until(executor, lambda n=i + 1: len(frames["/cam1"]) >= n)
        status = reports_from_msg(frames["/cam1"][-1])[0]
        assert status.name == "noise_monitor: cam1" and status.hardware_id == "ICX285/cam1" and "sigma_rn" in status.values
        assert frames["/cam1"][-1].header.frame_id == "cam1_optical"
        assert nodes[1].monitor.counters["frames_received"] == 0 and not frames["/cam2"]
        # /diagnostics: each camera under its own name; camera 2 is STALE (no image yet), camera 1 is not
        n0 = len(diagnostics)
        assert spin_until(executor, lambda: {r.name for r in diagnostics[n0:]} == {"noise_monitor: cam1",
                                                                                   "noise_monitor: cam2"})
        last = {r.name: r for r in diagnostics[n0:]}
        assert last["noise_monitor: cam2"].message == "no image received yet"
        assert last["noise_monitor: cam1"].values["frames_processed"] == "3"
        assert last["noise_monitor: cam1"].hardware_id == "ICX285/cam1"
    finally:
        executor.shutdown()
        for n in (*nodes, probe):
            n.destroy_node()
        context.try_shutdown()
