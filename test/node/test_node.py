"""The live node on the real middleware (rclpy, Fast DDS) with the real estimator (estimator.load).

A fake camera node publishes simulated frames (NoiseModel.simulate, joint mode, quantised to mono8)
and their metadata; the test spins one executor with spin_once and timeouts (no sleeps) and reads
the per-frame statuses (~/frame), the stamped numbers and the /diagnostics period summaries back.
"""
from __future__ import annotations

import json
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
import torch

from msg_adapters import ERROR, OK, STALE, WARN, StatusReport, reports_from_msg
from noise_monitor.monitor import CAUSE_IMAGE_NOISIER, CAUSE_MODEL_NOISIER
from noise_monitor.physics import NoiseModel, load_profile

torch.set_num_threads(1)
rclpy = pytest.importorskip("rclpy")

from builtin_interfaces.msg import Time  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue  # noqa: E402
from geometry_msgs.msg import Vector3Stamped  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from sensor_msgs.msg import Image  # noqa: E402

from noise_monitor.estimator import load  # noqa: E402
from noise_monitor.node import node_class, parameter_table, transport_topic  # noqa: E402

SIZE = 256
MODEL = NoiseModel()
PROFILE = load_profile("icx285")
DYNAMIC = {"gain_db": 18.0, "exposure_time_s": 0.01, "sensor_temperature_c": 40.0}
TIMEOUT_S = 30.0


def _stamp(msg: Any) -> int:
    return msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec


def scene(h: int = SIZE, w: int = SIZE) -> np.ndarray:
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    return (120 + 60 * np.sin(2 * np.pi * x / w) * np.cos(1.4 * np.pi * y / h) + 20 * x / w).astype(np.float32)


@pytest.fixture(scope="module")
def estimator():
    return load("full_meta", device="cpu")


class Rig:
    """The node under test, a fake camera and listeners of ~/frame and /diagnostics on one executor."""

    def __init__(self, estimator: Any, topic: str, **params: Any) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        base = {"image_topic": f"/{topic}/image_raw", "metadata_topic": f"/{topic}/metadata",
                "camera_info_topic": "", "profile": "icx285", "camera_name": topic, "patches_per_frame": 4,
                "diagnostics_rate_hz": 5.0, "device": "cpu"}
        base.update(params)
        overrides = [Parameter(k, value=v) for k, v in base.items()]
        self.node = node_class()(node_name=f"{topic}_monitor", parameter_overrides=overrides,
                                 context=self.context, estimator=estimator)
        self.cam = rclpy.create_node(f"{topic}_camera", context=self.context)
        from sensor_msgs.msg import CompressedImage

        compressed = base.get("image_transport") == "compressed"
        self.pub_img = self.cam.create_publisher(CompressedImage if compressed else Image, transport_topic(
            base["image_topic"]) if compressed else base["image_topic"], qos_profile_sensor_data)
        meta_topic = base["metadata_topic"] or f"/{topic}/unused_metadata"
        self.pub_meta = self.cam.create_publisher(DiagnosticArray, meta_topic, 10)
        self.diagnostics: list[tuple[int, StatusReport]] = []  # /diagnostics: the period summaries
        self.cam.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag, 50)
        self.frames: list[tuple[int, StatusReport]] = []  # ~/frame: every frame's status, image stamp
        ns = self.node.get_fully_qualified_name()
        self.cam.create_subscription(DiagnosticArray, f"{ns}/frame", self._on_frame, 50)
        self.numbers: dict[str, list[tuple[int, float]]] = {}  # (header stamp, value) of stamped numbers
        for key in ("sigma_rn", "xi"):
            self.cam.create_subscription(Vector3Stamped, f"{ns}/{key}", lambda m, k=key: self.numbers.setdefault(
                k, []).append((_stamp(m), m.vector.x)), 50)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.cam)
        self.rng = np.random.default_rng(7)
        self.clean = scene()
        assert self.spin_until(lambda: self.pub_img.get_subscription_count() > 0
                               and self.cam.count_publishers("/diagnostics") > 0, TIMEOUT_S), "no discovery"

    def _on_diag(self, msg: DiagnosticArray) -> None:
        self.diagnostics.extend((_stamp(msg), r) for r in reports_from_msg(msg)
                                if r.name.endswith(self.node.params["camera_name"]))

    def _on_frame(self, msg: DiagnosticArray) -> None:
        self.frames.extend((_stamp(msg), r) for r in reports_from_msg(msg))

    def spin_until(self, done: Callable[[], bool], timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.02)
            if done():
                return True
        return False

    def publish(self, i: int, extra_sigma: float = 0.0, metadata: dict | None = None,
                dynamic: dict | None = None, hardware_id: str = "", pixels: np.ndarray | None = None
                ) -> tuple[int, dict]:
        """Publish frame i simulated with ``dynamic`` conditions (or the given mono8 ``pixels``), and
        ``metadata`` (default: the same conditions; its status's ``hardware_id``) first with the same header
        stamp; returns (stamp ns, simulator truth)."""
        dynamic = DYNAMIC if dynamic is None else dynamic
        truth: dict = {}
        if pixels is None:
            noisy, truth = MODEL.simulate(self.clean, PROFILE.metadata(**dynamic), self.rng)
            if extra_sigma:
                noisy = noisy + self.rng.normal(0.0, extra_sigma, noisy.shape).astype(np.float32)
            pixels = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
        img = pixels
        stamp_ns = 1_000 * 10**9 + i * 33_333_333
        stamp = Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
        values = dynamic if metadata is None else metadata
        if values:
            msg = DiagnosticArray(status=[DiagnosticStatus(name="camera", hardware_id=hardware_id, values=[
                KeyValue(key=k, value=repr(v)) for k, v in values.items()])])
            msg.header.stamp = stamp
            self.pub_meta.publish(msg)
        image = Image(height=SIZE, width=SIZE, encoding="mono8", step=SIZE, data=img.tobytes())
        image.header.stamp = stamp
        self.pub_img.publish(image)
        return stamp_ns, truth

    def status_for(self, stamp_ns: int) -> StatusReport:
        """Spin until the node's status for this image arrives."""
        found: list[StatusReport] = []

        def done() -> bool:
            found.extend(r for s, r in self.frames if s == stamp_ns)
            return bool(found)

        assert self.spin_until(done, TIMEOUT_S), f"no ~/frame status for image stamp {stamp_ns}"
        return found[0]

    def step(self, i: int, **kw: Any) -> tuple[StatusReport, dict]:
        stamp, truth = self.publish(i, **kw)
        return self.status_for(stamp), truth

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.cam.destroy_node()
        self.context.try_shutdown()



def test_clean_frames_stay_ok_and_sources_match_truth(rig_factory):
    rig = rig_factory("clean")
    est = {k: [] for k in ("pn", "dcsn", "rn")}
    truth = {k: [] for k in est}
    for i in range(200):
        report, t = rig.step(i)
        assert report.level == OK, f"frame {i}: {report.message}"
        assert report.hardware_id == "ICX285/clean" and report.name == "noise_monitor: clean"
        for k in est:
            est[k].append(float(report.values[f"sigma_{k}"]))
            truth[k].append(t[k])
    for k in est:
        assert np.mean(est[k]) == pytest.approx(np.mean(truth[k]), abs=0.25, rel=0.1), k
    assert int(report.values["frames_processed"]) == 200 and report.values["alarm"] == "0"
    assert abs(float(report.values["xi_filtered"])) < 0.7
    # the stamped numbers carry the same numbers as ~/frame, stamped with the image's header
    assert rig.spin_until(lambda: len(rig.numbers.get("sigma_rn", [])) >= 200, TIMEOUT_S)
    stamp, value = rig.numbers["sigma_rn"][-1]
    assert stamp == 1_000 * 10**9 + 199 * 33_333_333 and value == pytest.approx(float(report.values["sigma_rn"]), rel=1e-5)


def test_extra_image_noise_raises_alarm_with_cause(rig_factory):
    rig = rig_factory("noisy")
    pn_clean = []
    for i in range(10):
        report, _ = rig.step(i)
        assert report.level == OK, report.message
        pn_clean.append(float(report.values["sigma_pn"]))
    pn_noisy = []
    for n in range(1, 21):
        report, _ = rig.step(10 + n, extra_sigma=5.0)
        pn_noisy.append(float(report.values["sigma_pn"]))
        if report.level == ERROR:
            break
    assert report.level == ERROR and n <= 12, report.message
    # the frame's xi: the evidence raises before the filter settles
    assert CAUSE_IMAGE_NOISIER in report.message and float(report.values["xi"]) < -1.0
    # sources stay put (frame to frame they vary with the patches chosen in the moving scene)
    assert np.mean(pn_noisy) == pytest.approx(np.mean(pn_clean), rel=0.1)


def test_doubled_thermal_white_noise_metadata_raises_alarm_with_cause(rig_factory):
    rig = rig_factory("metadata_lies")
    high_gain = {**DYNAMIC, "gain_db": 24.0}  # the paper's setting: readout noise is a visible share
    for i in range(5):
        report, _ = rig.step(i, dynamic=high_gain)
        assert report.level == OK, report.message
    rn_clean = float(report.values["sigma_rn"])
    wrong = {**high_gain, "thermal_white_noise_v_per_sqrt_hz": 2 * PROFILE.values["thermal_white_noise_v_per_sqrt_hz"]}
    for n in range(1, 21):
        report, _ = rig.step(5 + n, dynamic=high_gain, metadata=wrong)
        if report.level == ERROR:
            break
    assert report.level == ERROR and n <= 12, report.message
    assert CAUSE_MODEL_NOISIER in report.message and float(report.values["xi"]) > 1.0
    assert float(report.values["sigma_rn"]) > 1.5 * rn_clean  # the RN estimate follows the metadata


def test_stale_without_images_and_after_they_stop(rig_factory):
    rig = rig_factory("stale", image_timeout_s=0.5)
    assert rig.spin_until(lambda: any(r.level == STALE for _, r in rig.diagnostics), TIMEOUT_S)
    assert "no image received yet" in rig.diagnostics[0][1].message
    for i in range(3):
        report, _ = rig.step(i)
    assert report.level == OK
    n0 = len(rig.diagnostics)
    assert rig.spin_until(lambda: any(r.level == STALE for _, r in rig.diagnostics[n0:]), TIMEOUT_S)
    stale = next(r for _, r in rig.diagnostics[n0:] if r.level == STALE)
    assert "no image for" in stale.message and stale.hardware_id == "ICX285/stale"


@pytest.mark.parametrize("rate_hz,periods", [(1.0, 4), (5.0, 15)])
def test_diagnostics_summarise_each_period_at_the_configured_rate_under_30_hz_input(rig_factory, rate_hz, periods):
    """Frames at 30 Hz (node clock): /diagnostics comes at diagnostics_rate_hz (header stamps: the ROS clock
    of the node's timer), one summary per period whose frames and xi min/max are those of the ~/frame
    statuses it covers (by the frames_received counter, whatever the delivery order)."""
    rig = rig_factory(f"rate{int(rate_hz)}", diagnostics_rate_hz=rate_hz)
    clock = rig.node.get_clock()
    meta = PROFILE.metadata(**DYNAMIC)  # frames simulated before: the loop only publishes and spins
    images = [np.clip(np.rint(MODEL.simulate(rig.clean, meta, rig.rng)[0]), 0, 255).astype(np.uint8) for _ in range(8)]
    n0 = len(rig.diagnostics)
    next_ns, i = clock.now().nanoseconds, 0

    def camera_at_30_hz() -> bool:
        nonlocal next_ns, i
        if clock.now().nanoseconds >= next_ns:
            rig.publish(i, pixels=images[i % len(images)])
            i, next_ns = i + 1, next_ns + 33_333_333
        return len(rig.diagnostics) - n0 >= periods + 2

    assert rig.spin_until(camera_at_30_hz, TIMEOUT_S + periods / rate_hz)
    summaries = rig.diagnostics[n0 + 1:]  # the first one may cover the start-up
    stamps = np.array([t for t, _ in summaries], dtype=np.float64)
    rate = (len(stamps) - 1) / ((stamps[-1] - stamps[0]) / 1e9)
    assert rate == pytest.approx(rate_hz, rel=0.05), np.diff(stamps) / 1e9
    assert rig.spin_until(lambda: len(rig.frames) >= int(summaries[-1][1].values["frames_received"]), TIMEOUT_S)
    by_count = {int(r.values["frames_received"]): r for _, r in rig.frames}
    received = checked = 0
    for _, rep in summaries:
        v = rep.values
        before, received = received, int(v["frames_received"])
        if not before:
            continue
        inside = [by_count[n] for n in range(before + 1, received + 1)]
        assert int(v["period_frames"]) == int(v["period_processed"]) == len(inside)
        if not inside:  # a period without a finished frame (a loaded CPU): the last status, no xi statistics
            assert "xi_min" not in v
            continue
        checked += 1
        xi = [float(r.values["xi"]) for r in inside]
        assert float(v["xi_min"]) == pytest.approx(min(xi), rel=1e-4)
        assert float(v["xi_max"]) == pytest.approx(max(xi), rel=1e-4)
        assert v["xi"] == inside[-1].values["xi_filtered"] and v["sigma_pn"] == inside[-1].values["sigma_pn_filtered"]
        assert rep.level == OK == max(r.level for r in inside)
    assert checked >= periods // 2
    frames_per_period = i / (len(rig.diagnostics) - n0)  # frames offered per period: about 30 / rate
    assert frames_per_period == pytest.approx(30.0 / rate_hz, rel=0.3)


def test_missing_metadata_is_a_warning_naming_the_fields(rig_factory):
    rig = rig_factory("partial")
    report, _ = rig.step(0, metadata={"gain_db": 12.0})
    assert report.level == WARN
    assert "metadata missing: exposure_time_s, sensor_temperature_c" in report.message
    rig2 = rig_factory("no_profile", profile="", metadata_topic="", sync_wait_s=0.0)
    report, _ = rig2.step(0, metadata={})
    assert report.level == WARN and "gain_db" in report.message and "full_well_e" in report.message
    assert report.hardware_id == "unknown/no_profile"


def test_a_black_level_the_image_contradicts_is_a_warning_with_the_cameras_bound(rig_factory):
    """The node with ``black_level_dn`` 16 over a camera whose dark quarter reads 0 DN (no pedestal): its frames
    are evaluated and WARN that the pixels read far below the stated black level, with the bound the image puts on
    the camera's (a few DN); the same camera adding its 16 DN pedestal is OK (its noise below black is read clipped)."""
    clean = scene()
    clean[:128, :128] = 0.0
    meta = PROFILE.metadata(**DYNAMIC)
    rig = rig_factory("pedestal", black_level_dn=16.0)
    for i, pedestal in enumerate((0.0, 0.0, 16.0, 16.0)):
        noisy, _ = MODEL.simulate(clean, meta, rig.rng, black_level_dn=pedestal)
        report, _ = rig.step(i, pixels=np.clip(np.rint(noisy + pedestal), 0, 255).astype(np.uint8))
        if pedestal:
            assert report.level == OK and float(report.values["pixels_below_black_pct"]) == 0.0
            continue
        assert report.level == WARN and "below the stated black level of 16 DN" in report.message
        assert 5.0 < float(report.values["pixels_below_black_pct"]) <= 25.0  # of the dark quarter, past 8 sigma
        bound = float(report.message.split("at most ")[1].split(" DN")[0])
        assert 0.0 <= bound < 8.0


def test_the_black_level_the_cameras_metadata_reports_per_frame(rig_factory):
    """No black level configured: the node takes off what each frame's metadata reports (``black_level_dn``,
    8-bit DN) and says so (key ``black_level_dn``). The camera's 16 DN pedestal reported reads OK with the noise
    below black kept; 40 DN reported over the same pedestal WARNs, naming the metadata as the source and bounding
    the camera's below the 40 DN; a reported value that is no black level makes the frame's metadata invalid (not evaluated)."""
    clean = scene()
    clean[:128, :128] = 0.0
    meta = PROFILE.metadata(**DYNAMIC)
    rig = rig_factory("reported_black")
    for i, reported in enumerate((16.0, 16.0, 40.0, 300.0)):
        noisy, _ = MODEL.simulate(clean, meta, rig.rng, black_level_dn=16.0)
        report, _ = rig.step(i, pixels=np.clip(np.rint(noisy + 16.0), 0, 255).astype(np.uint8),
                             metadata={**DYNAMIC, "black_level_dn": reported})
        if reported == 300.0:
            assert report.level == WARN and "frame not evaluated: metadata invalid" in report.message
            assert "black_level_dn = 300 DN is not a black level" in report.message
        elif reported == 16.0:
            assert report.level == OK, report.message
            assert float(report.values["black_level_dn"]) == 16.0
            assert float(report.values["pixels_below_black_pct"]) == 0.0
        else:
            assert report.level == WARN and "below the stated black level of 40 DN (the camera's metadata)" in \
                report.message and float(report.values["black_level_dn"]) == 40.0
            assert 16.0 <= float(report.message.split("at most ")[1].split(" DN")[0]) < 30.0


def test_frames_arriving_while_busy_are_dropped_and_counted(rig_factory):
    rig = rig_factory("burst")
    stamps = [rig.publish(i)[0] for i in range(12)]  # faster than the worker evaluates them
    rig.status_for(stamps[-1])  # the newest frame is always evaluated
    counters = rig.node.monitor.counters
    assert counters["frames_dropped"] >= 1
    assert counters["frames_processed"] + counters["frames_dropped"] <= 12


def test_node_loads_the_estimator_itself_and_declares_described_parameters():
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = node_class()(node_name="described", context=context,
                            parameter_overrides=[Parameter("camera_info_topic", value="")])
        try:
            assert node.monitor.estimator.name == "full_meta"
            descriptors = node.describe_parameters(list(parameter_table()))
            assert all(d.description for d in descriptors)
            assert node.get_parameter("xi_threshold_dn").value == 1.0
        finally:
            node.destroy_node()
        # a params file's integer for a float parameter is stored as the double (read-only ones too)
        node = node_class()(node_name="typed", context=context,
                            parameter_overrides=[Parameter("camera_info_topic", value=""),
                                                 Parameter("xi_threshold_dn", value=2),
                                                 Parameter("max_rate_hz", value=5)])
        try:
            for name in ("xi_threshold_dn", "max_rate_hz"):
                assert node.get_parameter(name).type_ == Parameter.Type.DOUBLE
            assert node.monitor.config.xi_threshold_dn == 2.0
            assert node.describe_parameter("max_rate_hz").read_only
        finally:
            node.destroy_node()
        with pytest.raises(ValueError, match="patches_per_frame"):
            node_class()(node_name="bad", context=context,
                         parameter_overrides=[Parameter("patches_per_frame", value="many")])
    finally:
        context.try_shutdown()


def test_cli_rejects_bad_parameters_with_exit_code_2(tmp_path, capsys):
    from noise_monitor.cli import main as cli_main
    from noise_monitor.node import main as node_main

    bad = tmp_path / "node.yaml"
    bad.write_text("noise_monitor:\n  ros__parameters:\n    patches_per_frmae: 4\n")
    assert cli_main(["node", "--params-file", str(bad), "--duration", "1"]) == 2
    assert "unknown parameter(s) patches_per_frmae" in capsys.readouterr().err
    assert node_main(["--ros-args", "-p", "xi_threshold_dn:=-1.0"]) == 2
    assert "xi_threshold_dn must be > 0" in capsys.readouterr().err


def test_node_help_lists_every_parameter_and_output_without_starting(capsys):
    """``ros2 run noise_monitor noise_monitor_node --help`` prints the parameters (default, description) and the
    outputs and exits 0 (it used to start the node, which ran until Ctrl-C); after --ros-args, --help is ROS's."""
    from msg_adapters.outputs import output_topics
    from noise_monitor.node import main as node_main

    assert node_main(["--help"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: ros2 run noise_monitor noise_monitor_node [--ros-args")
    for name, (default, _) in parameter_table().items():
        assert f"  {name} ({type(default).__name__}, default {default!r}): " in out
    assert all(f"  {topic} [{kind}]" in out for topic, kind in output_topics().items())
    # `noise-monitor node --help` lists its own options and points to the full list
    from noise_monitor.cli import main as cli_main

    with pytest.raises(SystemExit) as stop:
        cli_main(["node", "--help"])
    assert stop.value.code == 0
    assert "noise_monitor_node --help" in " ".join(capsys.readouterr().out.split())


def test_a_robots_params_file_with_sections_for_other_nodes_and_use_sim_time(tmp_path, capfd):
    """A launch's one params file: a camera driver's section first, every node's (``/**``: rclpy's use_sim_time, a
    key of other nodes, and monitor settings), QoS overrides of the image input, and the monitor's own sections per
    namespace. The node takes what names it in its namespace (until 2026-11-29 the first section was read: the
    driver's keys, use_sim_time or another node's key were 'unknown parameter(s)'); a typo in its own section is still
    refused; replay without a namespace refuses a file with sections for several."""
    from noise_monitor.cli import main as cli_main
    from noise_monitor.monitor.config import read_ros_params
    from noise_monitor.node import parameter_table

    known = parameter_table()
    robot = tmp_path / "robot.yaml"
    robot.write_text("camera_driver:\n  ros__parameters:\n    exposure_auto: 1\n"
                     "/**:\n  ros__parameters:\n    use_sim_time: true\n    frame_prefix: robot1/\n"
                     "    xi_threshold_dn: 2.0\n    patches_per_frame: 4\n"
                     "    qos_overrides:\n      /robot/image:\n        subscription:\n          reliability: reliable\n"
                     "/robot/noise_monitor:\n  ros__parameters:\n    xi_threshold_dn: 1.5\n"
                     "/other/noise_monitor:\n  ros__parameters:\n    xi_threshold_dn: 9.0\n")
    assert read_ros_params(robot, namespace="/robot", known=known) == {"xi_threshold_dn": 1.5, "patches_per_frame": 4}
    assert read_ros_params(robot, namespace="/other", known=known) == {"xi_threshold_dn": 9.0, "patches_per_frame": 4}
    with pytest.raises(ValueError, match="in several namespaces \\(/other, /robot\\): give the namespace"):
        read_ros_params(robot, known=known)
    driver_only = tmp_path / "driver.yaml"
    driver_only.write_text("camera_driver:\n  ros__parameters:\n    exposure_auto: 1\n")
    with pytest.raises(ValueError, match="no section for the node 'noise_monitor'.*camera_driver"):
        read_ros_params(driver_only)
    out = tmp_path / "summary.json"
    assert cli_main(["node", "--params-file", str(robot), "--duration", "1", "--json", str(out),
                     "--ros-args", "-r", "__ns:=/robot"]) == 0, capfd.readouterr().err
    assert json.loads(out.read_text())["frames_received"] == 0
    assert "monitoring /robot/image with full_meta (patch 64, K=4," in capfd.readouterr().err  # rcl read the file
    typo = tmp_path / "typo.yaml"
    typo.write_text("/**:\n  ros__parameters:\n    frame_prefix: robot1/\n"
                    "noise_monitor:\n  ros__parameters:\n    xi_treshold_dn: 2.0\n")
    assert cli_main(["node", "--params-file", str(typo), "--duration", "1"]) == 2
    err = capfd.readouterr().err
    assert "unknown parameter(s) xi_treshold_dn" in err and "frame_prefix of every node's section" in err


def test_qos_overrides_of_the_image_input(tmp_path):
    """``qos_overrides./<image topic>.subscription.reliability: reliable`` (ROS's QoS overriding) sets the image
    subscription's QoS; the default stays sensor-data best effort."""
    from rclpy.qos import ReliabilityPolicy

    params = tmp_path / "qos.yaml"
    params.write_text("/**:\n  ros__parameters:\n    qos_overrides:\n      /qcam/image:\n        subscription:\n"
                      "          reliability: reliable\n")
    for args, want in (([], ReliabilityPolicy.BEST_EFFORT), (["--params-file", str(params)], ReliabilityPolicy.RELIABLE)):
        ctx = rclpy.Context()
        rclpy.init(context=ctx)
        try:
            node = node_class()(node_name="qos_monitor", context=ctx, estimator=load("full_meta", device="cpu"),
                                cli_args=["--ros-args", "-r", "__ns:=/qcam", *args],
                                parameter_overrides=[Parameter("profile", value="icx285")])
            try:
                assert node._image_sub.qos_profile.reliability == want
            finally:
                node.destroy_node()
        finally:
            ctx.try_shutdown()


def test_sim_time_from_clock(rig_factory):
    """``use_sim_time`` with a bag's /clock (``noise-monitor play --clock``): /diagnostics follows /clock, and its
    first period starts where /clock did (until 2026-11-29 it started at sim time 0: period_s 1000 s here, and
    STALE "no image for 1.7e9 s" with a real bag's clock)."""
    from rosgraph_msgs.msg import Clock

    rig = rig_factory("simtime", use_sim_time=True)
    clock = rig.cam.create_publisher(Clock, "/clock", 10)

    def tick(stamp_ns: int) -> None:
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(stamp_ns, 10**9)
        clock.publish(msg)
        rig.spin_until(lambda: rig.node.get_clock().now().nanoseconds >= stamp_ns, TIMEOUT_S)

    for i in range(12):
        stamp = 1_000 * 10**9 + i * 33_333_333
        tick(stamp)
        report, _ = rig.step(i)
        assert report.level == OK, report.message
    tick(1_000 * 10**9 + 12 * 33_333_333)
    assert rig.spin_until(lambda: any(r.level == OK for _, r in rig.diagnostics), TIMEOUT_S)
    assert all(float(r.values["period_s"]) < 1.0 for _, r in rig.diagnostics), rig.diagnostics


def test_unusable_image_is_a_warning_with_the_reason(rig_factory):
    rig = rig_factory("yuv")
    image = Image(height=4, width=4, encoding="nv21", step=8, data=bytes(32))
    image.header.stamp = Time(sec=5, nanosec=0)
    rig.pub_img.publish(image)
    report = rig.status_for(5 * 10**9)
    assert report.level == WARN and "image unusable: unsupported image encoding 'nv21'" in report.message


def test_temperature_topic_completes_the_metadata(rig_factory):
    from sensor_msgs.msg import Temperature

    rig = rig_factory("thermo", temperature_topic="/thermo/temperature")
    pub = rig.cam.create_publisher(Temperature, "/thermo/temperature", 10)
    assert rig.spin_until(lambda: pub.get_subscription_count() > 0, TIMEOUT_S)
    no_temp = {k: v for k, v in DYNAMIC.items() if k != "sensor_temperature_c"}
    report, _ = rig.step(0, metadata=no_temp)
    assert report.level == WARN and "sensor_temperature_c" in report.message
    pub.publish(Temperature(temperature=DYNAMIC["sensor_temperature_c"]))
    assert rig.spin_until(lambda: rig.node.temperature_c is not None, TIMEOUT_S)
    report, _ = rig.step(1, metadata=no_temp)
    assert report.level == OK, report.message


@pytest.mark.parametrize("image_topic", ["/pngcam/image_raw", "/pngcam/image_raw/compressed"])
def test_compressed_transport_decodes_png_and_skips_jpeg(rig_factory, image_topic):
    """image_transport: compressed - the node reads <image_topic>/compressed as image_transport names it (or the
    topic given when it names a transport); a lossless PNG frame is evaluated, a JPEG one skipped with the reason.
    (Until 2026-11-29 it subscribed CompressedImage on image_topic itself, the raw Image's topic: nothing came.)"""
    import cv2
    from sensor_msgs.msg import CompressedImage

    rig = rig_factory("pngcam", image_transport="compressed", image_topic=image_topic)
    assert rig.node._image_sub.topic_name == "/pngcam/image_raw/compressed"
    img = np.clip(np.rint(MODEL.simulate(rig.clean, PROFILE.metadata(**DYNAMIC), rig.rng)[0]), 0, 255).astype(np.uint8)
    for i, (ext, fmt) in enumerate(((".png", "mono8; png compressed "), (".jpg", "mono8; jpeg compressed mono8"))):
        stamp = Time(sec=10 + i, nanosec=0)
        meta = DiagnosticArray(status=[DiagnosticStatus(name="camera", values=[
            KeyValue(key=k, value=repr(v)) for k, v in DYNAMIC.items()])])
        meta.header.stamp = stamp
        rig.pub_meta.publish(meta)
        msg = CompressedImage(format=fmt, data=cv2.imencode(ext, img)[1].tobytes())
        msg.header.stamp = stamp
        rig.pub_img.publish(msg)
        report = rig.status_for((10 + i) * 10**9)
        if ext == ".png":
            assert report.level == OK and float(report.values["sigma_rn"]) > 0, report.message
        else:
            assert report.level == WARN and "lossy (jpeg)" in report.message
            assert report.values["frames_skipped"] == "1"


def test_the_compressed_topic_follows_the_remapped_base_topic():
    """As image_transport does: ``-r image:=image_raw`` in /cam makes the compressed input /cam/image_raw/compressed."""
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        node = node_class()(node_name="remap_monitor", context=ctx, estimator=load("full_meta", device="cpu"),
                            cli_args=["--ros-args", "-r", "__ns:=/cam", "-r", "image:=image_raw"],
                            parameter_overrides=[Parameter("image_transport", value="compressed"),
                                                 Parameter("profile", value="icx285")])
        try:
            assert node._image_sub.topic_name == "/cam/image_raw/compressed"
        finally:
            node.destroy_node()
    finally:
        ctx.try_shutdown()


def test_keymap_metadata_source_reads_a_drivers_own_keys(rig_factory, tmp_path):
    """metadata_source keymap: a DiagnosticArray with the driver's key names and units gives the same
    numbers as this project's key names (the same first image: the rigs' simulators share a seed)."""
    ref, _ = rig_factory("kref").step(0)
    rig = rig_factory("kmap", metadata_source="keymap",
                      metadata_keymap="camera|ExposureMs|exposure_time_s|ms; *|GainX|gain_db|factor; "
                                      "camera|TempK|sensor_temperature_c|K")
    own = {"ExposureMs": DYNAMIC["exposure_time_s"] * 1e3, "GainX": 10 ** (DYNAMIC["gain_db"] / 20),
           "TempK": DYNAMIC["sensor_temperature_c"] + 273.15}
    report, _ = rig.step(0, metadata=own)
    assert report.level == OK, report.message
    for key in ("sigma_pn", "sigma_dcsn", "sigma_rn", "sigma_model"):
        assert float(report.values[key]) == pytest.approx(float(ref.values[key]), rel=1e-5), key
    bad, _ = rig.step(1, metadata={**own, "GainX": "high"})
    assert bad.level == WARN and "metadata invalid: metadata GainX = " in bad.message and "is not a number" in bad.message


def test_camera_ros_libcamera_metadata_on_diagnostics(rig_factory):
    """metadata_source camera_ros: camera_ros publishes each frame's libcamera metadata on /diagnostics, where the
    monitor's own summaries and other nodes' diagnostics go too. The camera's status gives the numbers of this
    project's key names (ExposureTime in us, AnalogueGain x DigitalGain, SensorTemperature); another node's array
    with the image's stamp is not taken for the metadata; the camera's libcamera id names it; with hardware_id set,
    another camera's status in the same array is left aside."""
    ref, _ = rig_factory("lref").step(0)
    gain = 10 ** (DYNAMIC["gain_db"] / 20)
    libcamera = {"AeLocked": "true", "AnalogueGain": gain / 2, "DigitalGain": 2.0, "ExposureTime": 10000,
                 "FrameDuration": 33333, "SensorTemperature": DYNAMIC["sensor_temperature_c"]}
    assert DYNAMIC["exposure_time_s"] == 0.01

    def array(i: int, *statuses: tuple[str, str, dict]) -> DiagnosticArray:
        msg = DiagnosticArray(status=[DiagnosticStatus(name=name, hardware_id=hw, values=[
            KeyValue(key=k, value=str(v)) for k, v in values.items()]) for name, hw, values in statuses])
        stamp_ns = 1_000 * 10**9 + i * 33_333_333  # Rig.publish's stamp of image i
        msg.header.stamp = Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
        return msg

    imx = "/base/axi/pcie@120000/rp1/i2c@88000/imx708@1a"
    rig = rig_factory("lcam", metadata_source="camera_ros", metadata_topic="/diagnostics")
    rig.pub_meta.publish(array(0, ("battery", "bms", {"voltage": "12.1"})))  # another node's, the image's stamp
    rig.pub_meta.publish(array(0, ("", imx, libcamera)))
    report, _ = rig.step(0, metadata={})
    assert report.level == OK, report.message
    assert report.hardware_id == imx
    for key in ("sigma_pn", "sigma_dcsn", "sigma_rn", "sigma_model"):
        assert float(report.values[key]) == pytest.approx(float(ref.values[key]), rel=1e-5), key
    two = rig_factory("lcam2", metadata_source="camera_ros", metadata_topic="/diagnostics", hardware_id=imx)
    other = {**libcamera, "AnalogueGain": 1.0, "DigitalGain": 1.0, "ExposureTime": 500}
    two.pub_meta.publish(array(0, ("", "/base/imx477@1a", other), ("", imx, libcamera)))
    report, _ = two.step(0, metadata={})
    assert report.level == OK, report.message
    assert float(report.values["sigma_model"]) == pytest.approx(float(ref.values["sigma_model"]), rel=1e-5)
    two.pub_meta.publish(array(1, ("", imx, {**libcamera, "ExposureTime": "-1"})))
    bad, _ = two.step(1, metadata={})
    assert bad.level == WARN and "camera_ros metadata ExposureTime = '-1' is not a positive number" in bad.message


def test_parameter_events_of_a_v4l2_driver_node_give_the_metadata(rig_factory, tmp_path):
    """metadata_source parameters: the driver node's exposure/gain parameters (v4l2_camera names and
    units) followed on /parameter_events; the temperature from a sensor_msgs/Temperature topic."""
    from sensor_msgs.msg import Temperature

    ref, _ = rig_factory("pref").step(0)
    prof = tmp_path / "icx285_v4l2.yaml"
    prof.write_text(PROFILE.to_yaml() + "gain_range_db: [0.0, 24.0]\ndriver_gain_range: [0, 240]\n")
    rig = rig_factory("pcam", metadata_source="parameters", metadata_topic="", profile=str(prof),
                      metadata_driver_node="/pcam/v4l2_camera", temperature_topic="/pcam/temperature")
    driver = rclpy.create_node("v4l2_camera", namespace="/pcam", context=rig.context)
    rig.executor.add_node(driver)
    driver.declare_parameter("exposure_time_absolute", 50)
    driver.declare_parameter("gain", 0)
    driver.declare_parameter("auto_exposure", 1)  # V4L2 manual mode
    temp = rig.cam.create_publisher(Temperature, "/pcam/temperature", 10)
    assert rig.spin_until(lambda: temp.get_subscription_count() > 0, TIMEOUT_S)
    temp.publish(Temperature(temperature=DYNAMIC["sensor_temperature_c"]))
    # auto-exposure and gain change: 100 x 100 us = 10 ms, gain 180 of 240 -> 18 dB
    driver.set_parameters([Parameter("exposure_time_absolute", value=100), Parameter("gain", value=180)])
    assert rig.spin_until(lambda: rig.node._held == {"exposure_time_s": pytest.approx(0.01),
                                                      "gain_db": pytest.approx(18.0)}, TIMEOUT_S), rig.node._held
    assert rig.spin_until(lambda: rig.node.temperature_c is not None, TIMEOUT_S)
    report, _ = rig.step(0, metadata={})
    assert report.level == OK, report.message
    for key in ("sigma_pn", "sigma_dcsn", "sigma_rn", "sigma_model"):
        assert float(report.values[key]) == pytest.approx(float(ref.values[key]), rel=1e-5), key
    # the camera's auto-exposure on (aperture priority): the exposure parameter is no longer the frame's; until
    # 2026-12-04 the frames kept the manual 10 ms
    driver.set_parameters([Parameter("auto_exposure", value=3)])
    assert rig.spin_until(lambda: isinstance(rig.node._held, str), TIMEOUT_S), rig.node._held
    auto, _ = rig.step(1, metadata={})
    assert auto.level == WARN and "v4l2_camera auto_exposure = 3: the camera's auto-exposure" in auto.message
    driver.set_parameters([Parameter("auto_exposure", value=1)])
    assert rig.spin_until(lambda: isinstance(rig.node._held, dict), TIMEOUT_S), rig.node._held
    read_at = rig.node._temperature_ns
    temp.publish(Temperature(temperature=DYNAMIC["sensor_temperature_c"]))  # fresh for the frame below
    assert rig.spin_until(lambda: rig.node._temperature_ns != read_at, TIMEOUT_S)
    again, _ = rig.step(2, metadata={})
    rig.executor.remove_node(driver)
    driver.destroy_node()
    assert again.level == OK, again.message


def test_a_v4l2_driver_that_started_first_is_read_at_start(rig_factory, tmp_path):
    """/parameter_events has no history: a driver node up before the monitor (the usual order) told its exposure and
    gain only on a change, so until 2026-11-29 every frame read "metadata missing" until then. The monitor reads the
    driver's parameters once it is up; a later change still comes by the events."""
    import threading

    from sensor_msgs.msg import Temperature

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    driver = rclpy.create_node("v4l2_camera", namespace="/early", context=ctx)
    driver.declare_parameter("exposure_time_absolute", 100)  # 10 ms
    driver.declare_parameter("gain", 180)  # of 240 -> 18 dB
    spinner = SingleThreadedExecutor(context=ctx)
    spinner.add_node(driver)
    thread = threading.Thread(target=spinner.spin, daemon=True)
    thread.start()
    try:
        ref, _ = rig_factory("eref").step(0)
        prof = tmp_path / "icx285_v4l2.yaml"
        prof.write_text(PROFILE.to_yaml() + "gain_range_db: [0.0, 24.0]\ndriver_gain_range: [0, 240]\n")
        rig = rig_factory("early", metadata_source="parameters", metadata_topic="", profile=str(prof),
                          metadata_driver_node="/early/v4l2_camera", temperature_topic="/early/temperature")
        temp = rig.cam.create_publisher(Temperature, "/early/temperature", 10)
        assert rig.spin_until(lambda: temp.get_subscription_count() > 0, TIMEOUT_S)
        assert rig.spin_until(lambda: rig.node._held == {"exposure_time_s": pytest.approx(0.01),
                                                          "gain_db": pytest.approx(18.0)}, TIMEOUT_S), rig.node._held
        temp.publish(Temperature(temperature=DYNAMIC["sensor_temperature_c"]))  # fresh for the frame below
        assert rig.spin_until(lambda: rig.node.temperature_c is not None, TIMEOUT_S)
        report, _ = rig.step(0, metadata={})
        assert report.level == OK, report.message
        for key in ("sigma_pn", "sigma_dcsn", "sigma_rn", "sigma_model"):
            assert float(report.values[key]) == pytest.approx(float(ref.values[key]), rel=1e-5), key
        driver.set_parameters([Parameter("gain", value=120)])  # a change: 12 dB by the event
        assert rig.spin_until(lambda: rig.node._held.get("gain_db") == pytest.approx(12.0), TIMEOUT_S), rig.node._held
        # a driver started under its auto-exposure (v4l2_camera's auto_exposure 3): read at start, refused; each
        # parameter is read on its own (one the driver lacks, exposure_auto here, fails a request of several names)
        late = rig_factory("late", metadata_source="parameters", metadata_topic="", profile=str(prof),
                           metadata_driver_node="/early/v4l2_camera")
        driver.declare_parameter("auto_exposure", 3)
        assert late.spin_until(lambda: isinstance(late.node._held, str), TIMEOUT_S), late.node._held
        assert "auto_exposure = 3" in late.node._held
    finally:
        spinner.shutdown()
        driver.destroy_node()
        ctx.try_shutdown()
        thread.join(timeout=5)


def test_driver_metadata_source_without_its_package_names_it():
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        orbbec_keys = "*|exposure|exposure_time_s|100us; *|gain|gain_db|relative"
        for source, package, keys in (("flir", "flir_camera_msgs", ""), ("aravis", "camera_aravis2_msgs", ""),
                                      ("orbbec", "orbbec_camera_msgs", orbbec_keys)):
            with pytest.raises(ValueError, match=f"metadata_source {source} subscribes to {package}/msg/.*: install "
                                                 f"the ROS package {package}"):
                node_class()(node_name=f"{source}_monitor", context=ctx, parameter_overrides=[
                    Parameter("metadata_source", value=source), Parameter("profile", value="icx285"),
                    Parameter("metadata_keymap", value=keys)], estimator=object())
        with pytest.raises(ValueError, match="metadata_source orbbec needs metadata_keymap entries .*exposure usually "
                                             "in 100 us on the color stream"):
            node_class()(node_name="orbbec_monitor", context=ctx, parameter_overrides=[
                Parameter("metadata_source", value="orbbec")], estimator=object())
        with pytest.raises(ValueError, match="metadata_source must be one of diagnostics, keymap, flir"):
            node_class()(node_name="bad_monitor", context=ctx, parameter_overrides=[
                Parameter("metadata_source", value="spinnaker")], estimator=object())
        with pytest.raises(ValueError, match="unknown field 'gain'"):
            node_class()(node_name="km_monitor", context=ctx, parameter_overrides=[
                Parameter("metadata_source", value="keymap"), Parameter("metadata_keymap", value="c|G|gain|dB")],
                estimator=object())
    finally:
        ctx.try_shutdown()


def test_run_time_parameter_changes_are_validated(rig_factory):
    """``ros2 param set`` through the parameter service: thresholds change and act, bad values and
    read-only parameters are rejected with the reason."""
    from rclpy.parameter_client import AsyncParameterClient

    rig = rig_factory("pset", alarm_min_frames=1)
    client = AsyncParameterClient(rig.cam, rig.node.get_fully_qualified_name())
    assert client.wait_for_services(TIMEOUT_S)

    def set_(**values):
        fut = client.set_parameters([Parameter(k, value=v) for k, v in values.items()])
        assert rig.spin_until(fut.done, TIMEOUT_S)
        return fut.result().results

    ok = set_(xi_threshold_dn=3, xi_hysteresis_dn=0.5)  # an integer, as `ros2 param set ... 3` sends it
    assert all(r.successful for r in ok)
    assert rig.node.monitor.alarm.threshold == 3.0 and rig.node.monitor.alarm.clear_level == 2.5
    stored = rig.node.get_parameter("xi_threshold_dn")
    assert stored.type_ == Parameter.Type.DOUBLE and stored.value == 3.0  # a double, as declared
    assert all(r.successful for r in set_(xi_threshold_dn=2.5))
    assert rig.node.monitor.alarm.threshold == 2.5 and rig.node.monitor.alarm.clear_level == 2.0
    bad = set_(xi_hysteresis_dn=3.0)[0]
    assert not bad.successful and "xi_hysteresis_dn must be in [0, xi_threshold_dn)" in bad.reason
    assert rig.node.monitor.config.xi_hysteresis_dn == 0.5
    ro = set_(patches_per_frame=2)[0]
    assert not ro.successful and "read-only parameter: patches_per_frame" in ro.reason  # its descriptor says so
    desc = {d.name: d for d in rig.node.describe_parameters(["patches_per_frame", "xi_threshold_dn", "black_level_dn"])}
    assert desc["patches_per_frame"].read_only and not desc["xi_threshold_dn"].read_only
    assert not desc["black_level_dn"].read_only
    typed = set_(alarm_min_frames="three")[0]
    assert not typed.successful and "alarm_min_frames must be of type int" in typed.reason
    # the new threshold acts: +N(0, 3 DN) image noise (|xi| ~ 1.5 DN) raises no alarm at 2.5 DN ...
    report, _ = rig.step(0, extra_sigma=3.0)
    assert report.level == OK, report.message
    # ... and raises it at once with 0.5 DN
    assert all(r.successful for r in set_(xi_hysteresis_dn=0.1, xi_threshold_dn=0.5))
    report, _ = rig.step(1, extra_sigma=3.0)
    assert report.level == ERROR and "image noisier" in report.message


def test_the_black_level_set_at_run_time(rig_factory):
    """``ros2 param set black_level_dn`` (an operator changed the camera's pedestal): taken off from the next frame,
    validated (300 DN is rejected with the reason), and -1 returns to the metadata's / profile's (none here)."""
    from rclpy.parameter_client import AsyncParameterClient

    rig = rig_factory("pset_black")
    client = AsyncParameterClient(rig.cam, rig.node.get_fully_qualified_name())
    assert client.wait_for_services(TIMEOUT_S)

    def set_black(value: float):
        fut = client.set_parameters([Parameter("black_level_dn", value=value)])
        assert rig.spin_until(fut.done, TIMEOUT_S)
        return fut.result().results[0]

    def frame(i: int) -> StatusReport:
        noisy, _ = MODEL.simulate(rig.clean, PROFILE.metadata(**DYNAMIC), rig.rng, black_level_dn=16.0)
        return rig.step(i, pixels=np.clip(np.rint(noisy + 16.0), 0, 255).astype(np.uint8))[0]

    assert "black_level_dn" not in frame(0).values
    assert set_black(16.0).successful
    report = frame(1)
    assert report.level == OK and float(report.values["black_level_dn"]) == 16.0
    bad = set_black(300.0)
    assert not bad.successful and "black_level_dn must be -1" in bad.reason
    assert float(frame(2).values["black_level_dn"]) == 16.0
    assert set_black(-1.0).successful and "black_level_dn" not in frame(3).values


def test_hardware_id_from_the_drivers_serial(rig_factory):
    """Two cameras of one model: the driver's device id (its metadata status's hardware_id) names each;
    an explicit hardware_id parameter wins."""
    first, _ = rig_factory("ser").step(0, hardware_id="SN-4711")
    assert first.hardware_id == "SN-4711"
    fixed, _ = rig_factory("ser_fixed", hardware_id="left-front").step(0, hardware_id="SN-4712")
    assert fixed.hardware_id == "left-front"


def test_debug_image_outlines_patches_coloured_by_xi(rig_factory):
    from msg_adapters.debug_image import GREEN, RED

    rig = rig_factory("dbg", debug_image_rate_hz=100.0)
    got: list = []
    rig.cam.create_subscription(Image, f"{rig.node.get_fully_qualified_name()}/debug_image", got.append, 10)
    for i, extra in enumerate((0.0, 6.0)):
        stamp, _ = rig.publish(i, extra_sigma=extra)
        assert rig.spin_until(lambda: any(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec == stamp for m in got),
                              TIMEOUT_S), "no debug image for the frame"
        msg = next(m for m in got if m.header.stamp.sec * 10**9 + m.header.stamp.nanosec == stamp)
        assert (msg.encoding, msg.height, msg.width) == ("rgb8", SIZE, SIZE)
        rgb = np.frombuffer(bytes(msg.data), np.uint8).reshape(SIZE, SIZE, 3)
        result = rig.node.monitor.last_result
        colours = {tuple(rgb[y, x]) for y, x in result.patches.corners}
        expected = GREEN if extra == 0.0 else RED  # clean: |xi| small; +N(0, 6 DN): xi << -1 DN
        assert expected in colours, (colours, result.patch_xi)
