"""`noise_monitor_node`: the live ROS 2 node (rclpy) around the shared monitor pipeline.

Subscribes to an image (sensor-data QoS), its metadata (DiagnosticArray), optionally CameraInfo and
Temperature; pairs image and metadata by header stamp; evaluates frames in a worker thread fed by a
one-slot queue (a frame arriving while the worker is busy replaces the waiting one and is counted as
dropped); publishes ``/diagnostics`` and numeric per-source topics under ``~/`` for every evaluated
frame, and ``/diagnostics`` from a timer at least ``diagnostics_rate_hz`` even without input (STALE).
"""
from __future__ import annotations

import argparse
import json
import signal
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from msg_adapters import (
    AdapterError,
    camera_geometry,
    image_to_gray_dn,
    metadata_from_diagnostics,
    metadata_from_temperature,
    resolve_metadata,
)
from noise_monitor.monitor import DESCRIPTIONS, Frame, GapCounter, Matched, Monitor, MonitorConfig, StampSynchronizer
from msg_adapters.outputs import DIAGNOSTICS_TOPIC, output_topics, rclpy_messages
from noise_monitor.physics import CameraProfile, MetadataError, NoiseModel, load_profile

HELP = "run the live ROS 2 noise monitor node (image + metadata in, /diagnostics and sigma/xi topics out)"
NODE_NAME = "noise_monitor"

#: Node-only parameters: name -> (default, description). The monitor's come from MonitorConfig.
NODE_PARAMETERS: dict[str, tuple[Any, str]] = {
    "image_topic": ("image", "sensor_msgs/Image input (sensor-data QoS)"),
    "metadata_topic": ("metadata", "diagnostic_msgs/DiagnosticArray with CameraMetadata key/values; '' = none"),
    "camera_info_topic": ("camera_info", "sensor_msgs/CameraInfo (image size/binning/ROI check); '' = none"),
    "temperature_topic": ("", "sensor_msgs/Temperature with the sensor temperature in degC; '' = none"),
    "camera_name": ("camera", "camera name in the diagnostic status name 'noise_monitor: <camera_name>'"),
    "hardware_id": ("", "diagnostic hardware_id; '' = '<profile name>/<camera_name>'"),
    "profile": ("", "camera profile with the static metadata: bundled name or YAML path; '' = metadata topic only"),
    "bit_depth": (0, "bits per pixel in 16-bit images; 0 = the profile's bit_depth, else the container width"),
    "color": ("luma", "reduction of colour images to gray: luma or green"),
    "model": ("full_meta", "estimator variant (noise_monitor.estimator.load)"),
    "weights": ("", "estimator checkpoint (.pt written by `noise-monitor train`); '' = the bundled weights"),
    "device": ("cpu", "inference device: cpu, cuda or auto"),
    "threads": (0, "CPU threads for inference; 0 = all cores but one (keeps one for message handling)"),
    "max_rate_hz": (0.0, "evaluate at most this many frames per second (others are dropped); 0 = no limit"),
    "sync_tolerance_s": (0.01, "image and metadata header stamps closer than this belong together"),
    "sync_wait_s": (0.1, "an image waits this long for its metadata, then takes the latest older one"),
    "expected_rate_hz": (0.0, "the camera's frame rate, for an exact frames_lost count; 0 = inferred from stamp gaps"),
    "diagnostics_rate_hz": (1.0, "minimum /diagnostics rate, also without images (STALE)"),
}


def parameter_table() -> dict[str, tuple[Any, str]]:
    """All declared parameters: node-only ones plus every MonitorConfig field (same defaults)."""
    defaults = MonitorConfig()
    table = dict(NODE_PARAMETERS)
    for name in MonitorConfig.field_names():
        table[name] = (getattr(defaults, name), DESCRIPTIONS[name])
    return table


@dataclass
class _Job:
    """A matched image waiting for the worker."""

    matched: Matched
    temperature_c: float | None


def _coerce(name: str, value: Any, default: Any) -> Any:
    """A parameter value as the type of its default (ints accepted for floats); clear error otherwise."""
    kind = type(default)
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if not isinstance(value, kind) or isinstance(value, bool) != isinstance(default, bool):
        raise ValueError(f"parameter {name} must be of type {kind.__name__}, got {value!r}")
    return value


def _check_node_parameters(p: dict[str, Any]) -> None:
    """Range checks of the node-only parameters (the monitor's are checked by MonitorConfig)."""
    if p["color"] not in ("luma", "green"):
        raise ValueError(f"parameter color must be luma or green, got {p['color']!r}")
    for name in ("max_rate_hz", "sync_tolerance_s", "sync_wait_s", "expected_rate_hz", "threads", "bit_depth"):
        if p[name] < 0:
            raise ValueError(f"parameter {name} must be >= 0, got {p[name]}")
    if p["bit_depth"] > 16:
        raise ValueError(f"parameter bit_depth must be in 0..16, got {p['bit_depth']}")
    if p["diagnostics_rate_hz"] <= 0:
        raise ValueError("parameter diagnostics_rate_hz must be > 0")
    if not p["image_topic"]:
        raise ValueError("parameter image_topic must not be empty")


def _set_inference_threads(threads: int) -> None:
    """torch intra-op threads: ``threads``, or all cores but one when 0."""
    import os

    import torch

    torch.set_num_threads(threads or max(1, (os.cpu_count() or 2) - 1))


def _stamp_ns(msg: Any) -> int:
    s = msg.header.stamp
    return int(s.sec) * 1_000_000_000 + int(s.nanosec)


def _make_node_class():
    """Define the rclpy node class lazily (rclpy is imported only when the node is used)."""
    from rcl_interfaces.msg import ParameterDescriptor
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import CameraInfo, Image, Temperature
    from std_msgs.msg import Float32

    class NoiseMonitorNode(Node):
        """The live monitor; see the module docstring."""

        def __init__(self, node_name: str = NODE_NAME, estimator: Any = None, **kwargs: Any) -> None:
            super().__init__(node_name, **kwargs)
            p = {}
            for name, (default, description) in parameter_table().items():
                desc = ParameterDescriptor(description=description, dynamic_typing=True)
                p[name] = _coerce(name, self.declare_parameter(name, default, desc).value, default)
            self.params = p
            _check_node_parameters(p)
            config = MonitorConfig.from_mapping({k: p[k] for k in MonitorConfig.field_names()})
            self.profile: CameraProfile | None = load_profile(p["profile"]) if p["profile"] else None
            model = NoiseModel(extra=self.profile.effects if self.profile else None)
            _set_inference_threads(p["threads"])
            if estimator is None:
                from noise_monitor.estimator import load

                estimator = load(p["model"], device=p["device"], weights=p["weights"] or None, model=model)
            profile_name = self.profile.name if self.profile else "unknown"
            hardware_id = p["hardware_id"] or f"{profile_name}/{p['camera_name']}"
            self.monitor = Monitor(config, estimator, model, p["camera_name"], hardware_id)
            self.bit_depth = int(p["bit_depth"]) or (self.profile.bit_depth if self.profile else None)
            wait = p["sync_wait_s"] if p["metadata_topic"] else 0.0
            self.sync: StampSynchronizer = StampSynchronizer(p["sync_tolerance_s"], wait)
            self.gaps = GapCounter(expected_rate_hz=p["expected_rate_hz"])
            self._temperature_c: float | None = None
            self._geometry = None
            self._lock = threading.Condition()
            self._slot: _Job | None = None
            self._stop = False
            self._last_accept_ns: int | None = None
            self._last_publish_ns = 0
            self.published = 0

            ns = self.get_fully_qualified_name()
            self._pubs = {DIAGNOSTICS_TOPIC: self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, 10)}
            self._pubs.update({t: self.create_publisher(Float32, t, 10) for t in output_topics(ns) if t != DIAGNOSTICS_TOPIC})
            self.namespace_out = ns
            self.create_subscription(Image, p["image_topic"], self._on_image, qos_profile_sensor_data)
            relaxed = QoSProfile(depth=20, reliability=ReliabilityPolicy.BEST_EFFORT)
            if p["metadata_topic"]:
                self.create_subscription(DiagnosticArray, p["metadata_topic"], self._on_metadata, relaxed)
            if p["camera_info_topic"]:
                self.create_subscription(CameraInfo, p["camera_info_topic"], self._on_camera_info, relaxed)
            if p["temperature_topic"]:
                self.create_subscription(Temperature, p["temperature_topic"], self._on_temperature, relaxed)
            period = min(1.0 / p["diagnostics_rate_hz"], 0.05)
            self._diag_period_ns = int(1e9 / p["diagnostics_rate_hz"])
            self.create_timer(period, self._on_timer)
            self._worker = threading.Thread(target=self._work, name="noise_monitor_worker", daemon=True)
            self._worker.start()
            self.get_logger().info(
                f"monitoring {p['image_topic']} with {estimator.name} (patch {self.monitor.patch_size}, "
                f"K={config.patches_per_frame}, xi from {self.monitor.xi_source}); outputs /diagnostics and {ns}/<sigma_*|xi*>"
            )

        # --- inputs (executor thread) --------------------------------------------------------
        def _now(self) -> int:
            return self.get_clock().now().nanoseconds

        def _on_image(self, msg: Any) -> None:
            stamp = _stamp_ns(msg)
            self.monitor.count_lost(self.gaps.observe(stamp))
            for matched in self.sync.add_image(stamp, msg, self._now()):
                self._enqueue(matched)

        def _on_metadata(self, msg: Any) -> None:
            try:
                values: dict | str = metadata_from_diagnostics(msg)
            except AdapterError as exc:
                values = str(exc)  # the frames it belongs to report the problem
            for matched in self.sync.add_metadata(_stamp_ns(msg), values):
                self._enqueue(matched)

        def _on_camera_info(self, msg: Any) -> None:
            try:
                self._geometry = camera_geometry(msg)
            except AdapterError as exc:
                self._geometry = None
                self.get_logger().warning(f"ignoring CameraInfo: {exc}", throttle_duration_sec=10.0)

        def _on_temperature(self, msg: Any) -> None:
            try:
                self._temperature_c = metadata_from_temperature(msg)["sensor_temperature_c"]
            except AdapterError as exc:
                self.get_logger().warning(f"ignoring Temperature: {exc}", throttle_duration_sec=10.0)

        def _enqueue(self, matched: Matched) -> None:
            max_rate = self.params["max_rate_hz"]
            now = self._now()
            if max_rate > 0 and self._last_accept_ns is not None and now - self._last_accept_ns < 1e9 / max_rate:
                self.monitor.count_dropped()
                return
            self._last_accept_ns = now
            with self._lock:
                if self._slot is not None:
                    self.monitor.count_dropped()  # the worker is busy: keep the newest frame only
                self._slot = _Job(matched, self._temperature_c)
                self._lock.notify()

        def _on_timer(self) -> None:
            now = self._now()
            for matched in self.sync.poll(now):
                self._enqueue(matched)
            with self._lock:
                due = now - self._last_publish_ns >= self._diag_period_ns
            if due:
                self._publish(rclpy_messages(self.monitor.idle_report(now), stamp_ns=now, namespace=self.namespace_out), now)

        # --- worker thread -------------------------------------------------------------------
        def _work(self) -> None:
            while True:
                with self._lock:
                    while self._slot is None and not self._stop:
                        self._lock.wait()
                    if self._stop:
                        return
                    job, self._slot = self._slot, None
                try:
                    result = self._evaluate(job)
                except Exception as exc:  # keep the node alive; the status names the failure
                    self.get_logger().error(f"frame evaluation failed: {exc!r}")
                    result = self.monitor.reject(job.matched.stamp_ns, f"evaluation failed: {exc}",
                                                 job.matched.received_ns)
                self._publish(rclpy_messages(result, namespace=self.namespace_out), self._now())

        def _evaluate(self, job: _Job):
            m = job.matched
            try:
                image = image_to_gray_dn(m.image, bit_depth=self.bit_depth, color=self.params["color"])
                if self._geometry is not None:
                    self._geometry.check_image(int(m.image.height), int(m.image.width))
            except AdapterError as exc:
                return self.monitor.reject(m.stamp_ns, f"image unusable: {exc}", m.received_ns)
            frame = Frame(m.stamp_ns, image, None, metadata_age_s=m.metadata_age_s)
            if isinstance(m.metadata, str):
                frame.metadata_error = m.metadata
            else:
                try:
                    frame.metadata, frame.missing = resolve_metadata(self.profile, m.metadata or {}, job.temperature_c)
                except MetadataError as exc:
                    frame.metadata_error = str(exc)
            return self.monitor.process(frame, received_ns=m.received_ns)

        def _publish(self, messages: dict[str, Any], now_ns: int) -> None:
            for topic, msg in messages.items():
                self._pubs[topic].publish(msg)
            with self._lock:
                self._last_publish_ns = now_ns
                self.published += 1

        @property
        def temperature_c(self) -> float | None:
            """The latest sensor temperature from the Temperature topic (None before the first)."""
            return self._temperature_c

        def summary(self) -> dict[str, Any]:
            """Counters, alarm episodes and the last status (for --json)."""
            last = self.monitor.last_result
            return {
                **self.monitor.counters,
                "alarm_episodes": self.monitor.alarm.state.episodes,
                "alarm_active": self.monitor.alarm.state.active,
                "last_level": last.level if last else None,
                "last_message": last.message if last else None,
                "last_values": last.numeric() if last else {},
            }

        def destroy_node(self) -> None:
            with self._lock:
                self._stop = True
                self._lock.notify_all()
            self._worker.join(timeout=10.0)
            super().destroy_node()

    return NoiseMonitorNode


_NODE_CLASS = None


def node_class():
    """The NoiseMonitorNode class (imports rclpy on first use)."""
    global _NODE_CLASS
    if _NODE_CLASS is None:
        _NODE_CLASS = _make_node_class()
    return _NODE_CLASS


# --- running it ---------------------------------------------------------------------------------
def spin(argv: list[str], overrides: dict[str, Any], duration_s: float | None = None,
         json_path: str | None = None) -> int:
    """Run the node until Ctrl-C (or ``duration_s``); optional JSON summary at exit.

    ``argv``: process arguments as rclpy.init expects them (ROS arguments after ``--ros-args``)."""
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.parameter import Parameter

    context = rclpy.Context()
    rclpy.init(args=argv, context=context)
    node = None
    stop = threading.Event()
    previous = _catch_signals(stop)
    try:
        params = [Parameter(k, value=v) for k, v in overrides.items()]
        node = node_class()(parameter_overrides=params, context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        end = None if duration_s is None else time.monotonic() + duration_s
        try:
            while context.ok() and not stop.is_set() and (end is None or time.monotonic() < end):
                executor.spin_once(timeout_sec=0.1)
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        summary = node.summary()
        if json_path:
            Path(json_path).parent.mkdir(parents=True, exist_ok=True)
            Path(json_path).write_text(json.dumps(summary, indent=2))
        executor.shutdown()
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        if node is not None:
            node.destroy_node()
        context.try_shutdown()
    return 0


def _catch_signals(stop: threading.Event) -> dict:
    """SIGINT/SIGTERM (Ctrl-C, kill, systemd, docker stop) end the spin loop cleanly: summary written,
    node destroyed, exit code 0. rclpy installs no handlers for own contexts. Returns the old handlers."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    return {s: signal.signal(s, lambda *_: stop.set()) for s in (signal.SIGINT, signal.SIGTERM)}


_CLI_OVERRIDES = {
    "image_topic": str, "metadata_topic": str, "camera_info_topic": str, "temperature_topic": str,
    "camera_name": str, "hardware_id": str, "profile": str, "model": str, "weights": str, "device": str,
    "patches_per_frame": int, "max_rate_hz": float, "xi_threshold_dn": float,
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--params-file", help="ROS params YAML (default: the package's config/node.yaml)")
    table = parameter_table()
    for name, kind in _CLI_OVERRIDES.items():
        parser.add_argument(f"--{name.replace('_', '-')}", dest=name, type=kind, default=None,
                            help=f"{table[name][1]} (overrides the params file)")
    parser.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    parser.add_argument("--json", metavar="PATH", help="write counters, alarm episodes and the last status at exit")
    parser.add_argument("--ros-args", dest="ros_args", nargs=argparse.REMAINDER, default=[],
                        help="remaining arguments are passed to ROS (remappings, -p name:=value)")


def run(args: argparse.Namespace) -> int:
    from .monitor.config import default_params_path, read_ros_params

    params_file = Path(args.params_file) if args.params_file else default_params_path()
    if not params_file.is_file():
        raise FileNotFoundError(f"params file {params_file} not found")
    unknown = sorted(set(read_ros_params(params_file)) - set(parameter_table()))
    if unknown:
        raise ValueError(f"{params_file}: unknown parameter(s) {', '.join(unknown)}")
    overrides = {k: getattr(args, k) for k in _CLI_OVERRIDES if getattr(args, k) is not None}
    if args.duration is not None and args.duration <= 0:
        raise ValueError("--duration must be > 0")
    argv = ["noise-monitor", "--ros-args", "--params-file", str(params_file), *args.ros_args]
    return spin(argv, overrides, args.duration, args.json)


def main(argv: list[str] | None = None) -> int:
    """Console script ``noise_monitor_node`` (ROS style: configure with --ros-args)."""
    import sys

    try:
        return spin(list(sys.argv if argv is None else ["noise_monitor_node", *argv]), {})
    except (ValueError, FileNotFoundError) as exc:
        print(f"noise_monitor_node: error: {exc}", file=sys.stderr)
        return 2
