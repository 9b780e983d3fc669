"""Fault tolerance of the live node on the real middleware (rclpy, Fast DDS) with the real estimator.

Bad images and metadata give a WARN naming the reason for that frame, and the node goes on; metadata
late, duplicated, out of order, dropping out and returning; a camera publisher that restarts; a burst
of 30 Hz 4k frames (one-slot queue, every frame accounted as processed, dropped or lost); SIGINT and
SIGTERM end the `noise-monitor node` process cleanly (exit code 0, no traceback, summary written).
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
import torch

from msg_adapters import OK, STALE, WARN, StatusReport, reports_from_msg
from noise_monitor.physics import NoiseModel, load_profile

torch.set_num_threads(1)
rclpy = pytest.importorskip("rclpy")

from builtin_interfaces.msg import Time  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from sensor_msgs.msg import CameraInfo, Image  # noqa: E402

from noise_monitor.estimator import load  # noqa: E402
from noise_monitor.node import node_class  # noqa: E402

SIZE = 128
PROFILE = load_profile("icx285")
DYNAMIC = {"gain_db": 12.0, "exposure_time_s": 0.01, "sensor_temperature_c": 30.0}
TIMEOUT_S = 30.0
PERIOD_NS = 33_333_333  # 30 Hz


def stamp_msg(stamp_ns: int) -> Time:
    return Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)


def scene(h: int, w: int) -> np.ndarray:
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    return (110 + 50 * np.sin(2 * np.pi * x / w) * np.cos(np.pi * y / h) + 30 * x / w).astype(np.float32)


def mono8(img: np.ndarray, stamp_ns: int) -> Image:
    msg = Image(height=img.shape[0], width=img.shape[1], encoding="mono8", step=img.shape[1], data=img.tobytes())
    msg.header.stamp = stamp_msg(stamp_ns)
    return msg


def metadata(values: dict[str, Any], stamp_ns: int) -> DiagnosticArray:
    msg = DiagnosticArray(status=[DiagnosticStatus(name="camera", values=[
        KeyValue(key=k, value=str(v)) for k, v in values.items()])])
    msg.header.stamp = stamp_msg(stamp_ns)
    return msg


@pytest.fixture(scope="module")
def estimator():
    return load("full_meta", device="cpu")


class Rig:
    """The node under test, a fake camera (its own node, restartable) and listeners of the node's
    per-frame statuses (~/frame) and its /diagnostics period summaries."""

    def __init__(self, estimator: Any, topic: str, **params: Any) -> None:
        self.topic = topic
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        base = {"image_topic": f"/{topic}/image_raw", "metadata_topic": f"/{topic}/metadata",
                "camera_info_topic": f"/{topic}/camera_info", "profile": "icx285", "camera_name": topic,
                "patches_per_frame": 2, "diagnostics_rate_hz": 5.0, "device": "cpu"}
        base.update(params)
        self.node = node_class()(node_name=f"{topic}_monitor", context=self.context, estimator=estimator,
                                 parameter_overrides=[Parameter(k, value=v) for k, v in base.items()])
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.listener = rclpy.create_node(f"{topic}_listener", context=self.context)
        self.diagnostics: list[tuple[int, StatusReport]] = []  # /diagnostics: the period summaries
        self.listener.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag, 100)
        self.frames: list[tuple[int, StatusReport]] = []  # ~/frame: every frame's status, image stamp
        self.listener.create_subscription(DiagnosticArray, f"{self.node.get_fully_qualified_name()}/frame",
                                          self._on_frame, 100)
        self.executor.add_node(self.listener)
        self.cam = None
        self.start_camera()
        self.rng = np.random.default_rng(11)
        self.clean = scene(SIZE, SIZE)
        self.model = NoiseModel()

    def start_camera(self) -> None:
        """A camera driver node with image, metadata and CameraInfo publishers (again after a restart)."""
        self.cam = rclpy.create_node(f"{self.topic}_camera", context=self.context)
        self.pub_img = self.cam.create_publisher(Image, f"/{self.topic}/image_raw", qos_profile_sensor_data)
        self.pub_meta = self.cam.create_publisher(DiagnosticArray, f"/{self.topic}/metadata", 10)
        self.pub_info = self.cam.create_publisher(CameraInfo, f"/{self.topic}/camera_info", 10)
        self.executor.add_node(self.cam)
        assert self.spin_until(lambda: self.pub_img.get_subscription_count() > 0
                               and self.pub_meta.get_subscription_count() > 0, TIMEOUT_S), "no discovery"

    def stop_camera(self) -> None:
        self.executor.remove_node(self.cam)
        self.cam.destroy_node()

    def _on_diag(self, msg: DiagnosticArray) -> None:
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        self.diagnostics.extend((stamp, r) for r in reports_from_msg(msg) if r.name == f"noise_monitor: {self.topic}")

    def _on_frame(self, msg: DiagnosticArray) -> None:
        self.frames.extend((msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec, r) for r in reports_from_msg(msg))

    def spin_until(self, done: Callable[[], bool], timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.02)
            if done():
                return True
        return False

    def frame(self, gain_db: float = DYNAMIC["gain_db"]) -> np.ndarray:
        meta = PROFILE.metadata(**{**DYNAMIC, "gain_db": gain_db})
        noisy, _ = self.model.simulate(self.clean, meta, self.rng)
        return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)

    def publish(self, i: float, meta: dict | None = None, image: Image | None = None, gain_db: float | None = None
                ) -> int:
        """Frame i (stamp = i x 33 ms) with its metadata (``meta`` overrides; {} = none)."""
        stamp = 10**12 + int(round(i * PERIOD_NS))
        gain = DYNAMIC["gain_db"] if gain_db is None else gain_db
        values = {**DYNAMIC, "gain_db": gain} if meta is None else meta
        img = image if image is not None else mono8(self.frame(gain), stamp)
        img.header.stamp = stamp_msg(stamp)
        if values:
            self.pub_meta.publish(metadata(values, stamp))
        self.pub_img.publish(img)
        return stamp

    def status_for(self, stamp_ns: int) -> StatusReport:
        found: list[StatusReport] = []

        def done() -> bool:
            found.extend(r for s, r in self.frames if s == stamp_ns)
            return bool(found)

        assert self.spin_until(done, TIMEOUT_S), f"no ~/frame status for image stamp {stamp_ns}"
        return found[0]

    def close(self) -> None:
        self.executor.shutdown()
        for n in (self.node, self.listener, self.cam):
            n.destroy_node()
        self.context.try_shutdown()



def bad_images(patch_size: int) -> list[tuple[str, Image, str]]:
    good = np.full((SIZE, SIZE), 100, np.uint8).tobytes()
    big16 = np.full((SIZE, SIZE), 1000, ">u2").tobytes()
    return [
        ("unknown encoding", Image(height=SIZE, width=SIZE, encoding="nv21", step=SIZE, data=good),
         "image unusable: unsupported image encoding 'nv21'"),
        ("data shorter", Image(height=SIZE, width=SIZE, encoding="mono8", step=SIZE, data=good[:-SIZE - 1]),
         f"image unusable: image data has {SIZE * SIZE - SIZE - 1} bytes"),
        ("data longer", Image(height=SIZE, width=SIZE, encoding="mono8", step=SIZE, data=good + good),
         f"image unusable: image data has {2 * SIZE * SIZE} bytes, expected {SIZE * SIZE}"),
        ("step too small", Image(height=SIZE, width=SIZE, encoding="mono16", step=SIZE, data=big16),
         f"image unusable: step {SIZE} is smaller than width*channels*bytes = {2 * SIZE}"),
        ("0x0", Image(height=0, width=0, encoding="mono8", step=0, data=b""), "image unusable: empty image (0x0)"),
        ("1x1", Image(height=1, width=1, encoding="mono8", step=1, data=b"\x64"),
         f"image 1x1 is smaller than the patch size {patch_size}"),
        ("big-endian beyond 12 bits", Image(height=SIZE, width=SIZE, encoding="mono16", step=2 * SIZE,
                                            is_bigendian=0, data=big16),
         "pixel value 59395 exceeds the 12-bit range"),
    ]


def test_bad_images_are_warnings_with_the_reason_and_the_node_goes_on(rig_factory):
    rig = rig_factory("badimg", bit_depth=12)
    assert rig.status_for(rig.publish(0)).level == OK
    cases = bad_images(rig.node.monitor.patch_size)
    for i, (case, img, reason) in enumerate(cases, start=1):
        report = rig.status_for(rig.publish(i, image=img))
        assert report.level == WARN and reason in report.message, (case, report.message)
        assert "sigma_pn" not in report.values  # no numbers for a frame that was not evaluated
    n = len(cases) + 1
    big_endian = np.full((SIZE, SIZE), 0, ">u2")
    big_endian[:] = (rig.frame().astype(np.uint16) * 16)  # 12-bit data in big-endian words
    ok = Image(height=SIZE, width=SIZE, encoding="mono16", step=2 * SIZE, is_bigendian=1, data=big_endian.tobytes())
    report = rig.status_for(rig.publish(n, image=ok))
    assert report.level == OK, report.message
    assert abs(float(report.values["xi"])) < 1.0  # the right scale: 12 bits in big-endian words
    assert report.values["frames_skipped"] == str(n - 1) and report.values["frames_processed"] == "2"


def test_camera_info_disagreeing_with_the_image_size(rig_factory):
    rig = rig_factory("info")
    rig.pub_info.publish(CameraInfo(width=2 * SIZE, height=2 * SIZE))
    assert rig.spin_until(lambda: rig.node._geometry is not None, TIMEOUT_S)
    report = rig.status_for(rig.publish(0))
    assert report.level == WARN
    assert f"image is {SIZE}x{SIZE} but CameraInfo implies {2 * SIZE}x{2 * SIZE}" in report.message
    rig.pub_info.publish(CameraInfo(width=SIZE, height=SIZE))  # a corrected CameraInfo is honoured
    assert rig.spin_until(lambda: rig.node._geometry.width == SIZE, TIMEOUT_S)
    assert rig.status_for(rig.publish(1)).level == OK


@pytest.mark.parametrize("values,reason", [
    ({**DYNAMIC, "gain_db": "nan"}, "metadata invalid: metadata value gain_db='nan' is not finite"),
    ({**DYNAMIC, "exposure_time_s": "inf"}, "metadata invalid: metadata value exposure_time_s='inf' is not finite"),
    ({**DYNAMIC, "exposure_time_s": "-0.01"}, "metadata invalid: exposure_time_s = -0.01 s is outside"),
    ({**DYNAMIC, "gain_db": "99"}, "metadata invalid: gain_db = 99 dB is outside the allowed range"),
    ({**DYNAMIC, "sensor_temperature_c": "warm"}, "metadata invalid: metadata value sensor_temperature_c='warm'"),
    ({"gain_db": "12"}, "metadata missing: exposure_time_s, sensor_temperature_c"),
])
def test_bad_metadata_is_a_warning_naming_the_field(rig_factory, values, reason):
    rig = rig_factory("badmeta")
    report = rig.status_for(rig.publish(0, meta=values))
    assert report.level == WARN and report.message.startswith(f"frame not evaluated: {reason}"), report.message
    assert rig.status_for(rig.publish(1)).level == OK  # the next good frame is evaluated


def test_metadata_late_duplicated_and_out_of_order_pair_by_stamp(rig_factory):
    """Gains alternate 0 / 24 dB, so a wrong pairing shows as |xi| of several DN."""
    rig = rig_factory("timing", sync_wait_s=0.5)
    gains = {i: 0.0 if i % 2 else 24.0 for i in range(8)}

    def xi(stamp: int) -> float:
        report = rig.status_for(stamp)
        assert report.level == OK, report.message
        return abs(float(report.values["xi"]))

    assert xi(rig.publish(0, gain_db=gains[0])) < 1.0
    late = rig.publish(1, meta={}, image=mono8(rig.frame(gains[1]), 0))  # metadata 0.2 s after its image
    rig.spin_until(lambda: False, 0.2)
    rig.pub_meta.publish(metadata({**DYNAMIC, "gain_db": gains[1]}, late))
    assert xi(late) < 1.0
    s2 = rig.publish(2, gain_db=gains[2])
    rig.pub_meta.publish(metadata({**DYNAMIC, "gain_db": gains[2]}, s2))  # duplicated
    assert xi(s2) < 1.0
    # out of order: metadata of frame 4, then of frame 3, then the images (one at a time: two frames
    # completed at once would share the one-slot queue and one would be dropped, see the burst test)
    s3, s4 = (10**12 + i * PERIOD_NS for i in (3, 4))
    rig.pub_meta.publish(metadata({**DYNAMIC, "gain_db": gains[4]}, s4))
    rig.pub_meta.publish(metadata({**DYNAMIC, "gain_db": gains[3]}, s3))
    rig.spin_until(lambda: False, 0.1)
    rig.publish(3, meta={}, image=mono8(rig.frame(gains[3]), s3))
    assert xi(s3) < 1.0
    rig.publish(4, meta={}, image=mono8(rig.frame(gains[4]), s4))
    assert xi(s4) < 1.0
    assert rig.spin_until(lambda: rig.node.monitor.counters["frames_processed"] == 5, TIMEOUT_S)
    assert rig.node.monitor.counters["frames_received"] == 5  # the duplicate made no extra frame


def test_metadata_topic_dropping_out_and_returning(rig_factory):
    rig = rig_factory("dropout", metadata_timeout_s=0.3, sync_wait_s=0.05)
    assert rig.status_for(rig.publish(0)).level == OK
    report = None
    for i in range(1, 30):  # images keep coming, metadata stops: sample-and-hold until it is too old
        report = rig.status_for(rig.publish(i, meta={}))
        if report.level != OK:
            break
    assert report.level == WARN and "metadata stale" in report.message and "timeout 0.3 s" in report.message
    assert 9 <= i <= 12  # 0.3 s of 30 Hz frames used the held metadata first
    assert rig.status_for(rig.publish(i + 1)).level == OK  # metadata is back


def test_an_unusable_or_stale_temperature_reading_is_named_not_replaced_by_an_older_one(rig_factory):
    """The sensor temperature from its own topic: a NaN reading is the frame's reason (until 2026-12-04 the frames
    said "metadata missing", or used the previous reading without a word) and so is a topic that went quiet (the
    last reading was used however old)."""
    from sensor_msgs.msg import Temperature

    rig = rig_factory("temp", temperature_topic="/temp/temperature", metadata_timeout_s=0.5)
    pub = rig.cam.create_publisher(Temperature, "/temp/temperature", qos_profile_sensor_data)
    assert rig.spin_until(lambda: pub.get_subscription_count() > 0, TIMEOUT_S)
    meta = {k: v for k, v in DYNAMIC.items() if k != "sensor_temperature_c"}

    def reading(celsius: float) -> None:
        pub.publish(Temperature(temperature=celsius))
        assert rig.spin_until(lambda: rig.node._temperature_ns > 0 and (
            rig.node.temperature_c == celsius or (celsius != celsius and rig.node.temperature_c is None)), TIMEOUT_S)

    reading(30.0)
    assert rig.status_for(rig.publish(0, meta=meta)).level == OK
    reading(float("nan"))
    report = rig.status_for(rig.publish(1, meta=meta))
    assert report.level == WARN and "sensor_temperature_c from the Temperature topic" in report.message
    assert "not finite" in report.message
    reading(30.0)
    assert rig.status_for(rig.publish(2, meta=meta)).level == OK
    rig.spin_until(lambda: False, 0.8)  # the topic goes quiet beyond metadata_timeout_s
    report = rig.status_for(rig.publish(3, meta=meta))
    assert report.level == WARN and "Temperature topic stale: last reading" in report.message
    assert rig.status_for(rig.publish(4)).level == OK  # the metadata's own temperature needs no topic


def test_a_failure_inside_the_evaluation_or_the_outputs_counts_the_frame_once_and_the_worker_goes_on(rig_factory):
    """The estimator raising inside the monitor's evaluation (after it counted the frame): the frame is skipped with
    the reason and counted once (until 2026-12-04 twice); an output that fails to publish is logged and the next
    frames are evaluated (it would have ended the worker thread: every later frame only "dropped")."""
    rig = rig_factory("fail", debug_image_rate_hz=100.0)
    assert rig.status_for(rig.publish(0)).level == OK
    predict = rig.node.monitor.estimator.predict
    calls = {"n": 0}

    def once(*args: Any, **kwargs: Any) -> Any:
        calls["n"] += 1
        if calls["n"] == 1:
            raise RuntimeError("CUDA error: an illegal memory access")
        return predict(*args, **kwargs)

    rig.node.monitor.estimator.predict = once
    report = rig.status_for(rig.publish(1))
    assert report.level == WARN and "evaluation failed: CUDA error" in report.message
    counters = rig.node.monitor.counters
    assert counters["frames_received"] == 2 and counters["frames_skipped"] == 1, counters

    def broken(*args: Any) -> None:
        raise OSError("the debug image's publisher is gone")

    rig.node._publish_debug_image = broken
    assert rig.status_for(rig.publish(2)).level == OK  # ~/frame went out before the failing output
    assert rig.status_for(rig.publish(3)).level == OK  # and the worker lives on
    assert counters["frames_received"] == 4 and counters["frames_processed"] == 3, counters


def test_camera_publisher_restart_is_stale_then_recovers(rig_factory):
    rig = rig_factory("restart", image_timeout_s=0.5)
    for i in range(3):
        assert rig.status_for(rig.publish(i)).level == OK
    rig.stop_camera()
    n0 = len(rig.diagnostics)
    assert rig.spin_until(lambda: any(r.level == STALE for _, r in rig.diagnostics[n0:]), TIMEOUT_S)
    rig.start_camera()
    # a restarted driver may start its clock again: stamps jump back, nothing is counted as lost
    report = rig.status_for(rig.publish(-10**4))
    assert report.level == OK, report.message
    assert rig.status_for(rig.publish(-10**4 + 1)).level == OK
    assert rig.node.monitor.counters["frames_lost"] == 0


def test_a_burst_of_stamps_at_start_up_counts_no_lost_frames(rig_factory):
    """A driver flushing its buffer at start-up (10 images 3 ms apart), then 30 Hz: every image arrives, none is
    lost (the node's audit, 2026-12-04: the burst became the frame period and 524 frames were counted lost of 40)."""
    rig = rig_factory("startburst", camera_info_topic="")
    arrived: list[int] = []
    observe = rig.node.gaps.observe
    rig.node.gaps.observe = lambda stamp: (arrived.append(stamp), observe(stamp))[1]  # count arrivals
    stamps = [0.1 * k for k in range(10)] + [float(k) for k in range(1, 31)]
    t0 = time.monotonic()
    for k, i in enumerate(stamps):
        rig.publish(i)
        rig.spin_until(lambda: time.monotonic() >= t0 + (k + 1) / 30.0, 1.0)
    rig.spin_until(lambda: len(arrived) == len(stamps), 5.0)
    c = rig.node.monitor.counters
    assert rig.node.summary()["frames_lost"] == c["frames_lost"] <= len(stamps) - len(arrived), (c, len(arrived))


def test_burst_of_30hz_4k_frames_is_bounded_and_every_frame_accounted(rig_factory):
    """60 frames of 3840x2160 at 30 Hz: the worker keeps at most one waiting frame; every frame that
    reaches the node is evaluated or counted as dropped (worker busy) in /diagnostics."""
    rig = rig_factory("burst4k", camera_info_topic="", patches_per_frame=4)
    arrived: list[int] = []
    observe = rig.node.gaps.observe
    rig.node.gaps.observe = lambda stamp: (arrived.append(stamp), observe(stamp))[1]  # count arrivals
    h, w = 2160, 3840
    base = np.clip(np.rint(scene(h, w) + np.random.default_rng(5).normal(0, 2.0, (h, w))), 0, 255).astype(np.uint8)
    img = Image(height=h, width=w, encoding="mono8", step=w, data=base.tobytes())
    sent, t0 = 60, time.monotonic()
    for i in range(sent):
        rig.publish(i, image=img)
        rig.spin_until(lambda: time.monotonic() >= t0 + (i + 1) / 30.0, 1.0)  # 30 Hz pacing, spinning
        assert len(rig.node.sync.pending) <= rig.node.sync.max_pending  # bounded: 1 slot + a few pairing
    c = rig.node.monitor.counters

    def accounted() -> bool:  # every arrival evaluated (or skipped) or dropped, none in flight
        return (c["frames_received"] + c["frames_dropped"] == len(arrived)
                and c["frames_received"] == c["frames_processed"] + c["frames_skipped"])

    assert rig.spin_until(accounted, TIMEOUT_S), c  # nothing vanishes inside the node
    rig.spin_until(lambda: False, 0.5)
    assert accounted() and not rig.node._worker.waiting and not rig.node.sync.pending, c
    assert c["frames_processed"] >= 1 and c["frames_dropped"] >= 1, c
    rig.node.summary()  # judges the last stamp intervals
    assert len(arrived) + c["frames_lost"] <= sent, c  # transport losses are never over-counted
    # the next /diagnostics summary carries the final counters; the periods' drops add up to them
    n0 = len(rig.diagnostics)
    assert rig.spin_until(lambda: len(rig.diagnostics) > n0, TIMEOUT_S)
    final = rig.diagnostics[-1][1].values
    assert (final["frames_received"], final["frames_dropped"]) == (str(c["frames_received"]), str(c["frames_dropped"]))
    assert sum(int(r.values["period_dropped"]) for _, r in rig.diagnostics) == c["frames_dropped"], c
    assert sum(int(r.values["period_frames"]) for _, r in rig.diagnostics) == c["frames_received"], c


# --- process shutdown ----------------------------------------------------------------------------
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_node_process_shuts_down_cleanly_on_signal(tmp_path, sig):
    """`noise-monitor node` as a subprocess in this test's ROS domain: up (its /diagnostics arrive),
    then the signal: exit code 0, no traceback, the --json summary written on the way out."""
    summary = tmp_path / "summary.json"
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "OMP_NUM_THREADS": "1"}
    name = f"sig{int(sig)}"
    proc = subprocess.Popen(
        [sys.executable, "-m", "noise_monitor.cli", "node", "--camera-name", name, "--image-topic", f"/{name}/image",
         "--metadata-topic", f"/{name}/metadata", "--profile", "icx285", "--json", str(summary),
         "--ros-args", "-p", "diagnostics_rate_hz:=5.0", "-p", "threads:=1"],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        listener = rclpy.create_node(f"{name}_listener", context=context)
        seen: list[str] = []
        listener.create_subscription(DiagnosticArray, "/diagnostics", lambda m: seen.extend(
            s.name for s in m.status), 10)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(listener)
        end = time.monotonic() + 60.0
        while f"noise_monitor: {name}" not in seen and time.monotonic() < end and proc.poll() is None:
            executor.spin_once(timeout_sec=0.1)
        assert f"noise_monitor: {name}" in seen, "the node never published /diagnostics"
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=30.0)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        context.try_shutdown()
    assert proc.returncode == 0, err
    assert "Traceback" not in err and "Error" not in err, err
    data = json.loads(summary.read_text())
    assert data["frames_received"] == 0 and data["last_level"] is None


FAILING_EFFECTS = """
import numpy as np
from noise_monitor.physics.effects import Effect


class NodeRaises(Effect):
    name = "node_raises"
    distribution = "gaussian"

    def sigma_dn(self, signal_dn, cond):
        raise RuntimeError("lookup table missing")


class NodeNan(Effect):
    name = "node_nan"
    distribution = "gaussian"

    def sigma_dn(self, signal_dn, cond):
        return np.full(np.shape(signal_dn), np.nan)
"""


@pytest.mark.parametrize("effect,reason", [
    ("node_raises", "evaluation failed: effect 'node_raises' failed to evaluate: lookup table missing"),
    ("node_nan", "evaluation failed: effect(s) node_nan returned a NaN, infinite or negative variance"),
])
def test_failing_plugin_effect_in_the_profile_is_a_warning_per_frame(rig_factory, tmp_path, monkeypatch, effect,
                                                                    reason):
    from noise_monitor.physics import load_plugin_file
    from noise_monitor.physics.effects import registry

    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))  # forget the plug-ins afterwards
    (tmp_path / "effects.py").write_text(FAILING_EFFECTS)
    load_plugin_file(tmp_path / "effects.py")
    profile = tmp_path / "broken.yaml"
    profile.write_text(PROFILE.to_yaml().replace("name: ICX285", "name: broken") + f"effects: [{effect}]\n")
    rig = rig_factory(f"plugin_{effect}", profile=str(profile))
    for i in range(2):
        report = rig.status_for(rig.publish(i))
        assert report.level == WARN and reason in report.message, report.message
    assert rig.node.monitor.counters["frames_skipped"] == 2


def test_profile_naming_an_unknown_effect_stops_the_node_at_start(estimator, tmp_path):
    profile = tmp_path / "typo.yaml"
    profile.write_text(PROFILE.to_yaml() + "effects: [prnuu]\n")
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        with pytest.raises(ValueError, match="unknown effect 'prnuu' .*; known: "):
            node_class()(node_name="typo", context=context, estimator=estimator,
                         parameter_overrides=[Parameter("profile", value=str(profile))])
    finally:
        context.try_shutdown()
