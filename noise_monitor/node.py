"""`noise_monitor_node`: the live ROS 2 node (rclpy) around the shared monitor pipeline.

Subscribes to an image (sensor-data QoS), its metadata (DiagnosticArray), optionally CameraInfo and
Temperature; pairs image and metadata by header stamp; evaluates frames in a worker thread fed by a
one-slot queue (a frame arriving while the worker is busy replaces the waiting one and is counted as
dropped); publishes every frame's status (``~/frame``) and stamped numbers (``~/sigma_pn`` ...) with the
image's header, and ``/diagnostics`` from a timer at ``diagnostics_rate_hz`` summarising the period
(``noise_monitor.monitor.period``; STALE without input).
Parameters, profile, model, estimator and monitor come from the shared runtime
(:class:`noise_monitor.monitor.runtime.MonitorRuntime`), frames from ``msg_adapters.prepare_frame``:
the replay and the lab run the same code.
"""
from __future__ import annotations

import argparse
import copy
import json
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any, Generic, TypeVar

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Vector3Stamped
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.clock import JumpThreshold
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.serialization import serialize_message
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, Temperature

from msg_adapters import (
    AdapterError,
    CameraGeometry,
    camera_geometry,
    metadata_from_temperature,
    prepare_frame,
)
from msg_adapters.debug_image import debug_view
from msg_adapters.outputs import DIAGNOSTICS_TYPE, output_topics, rclpy_messages
from msg_adapters.parameter_events import read_values
from msg_adapters.sources import resolve_source
from noise_monitor.monitor import FrameResult, GapCounter, Matched, StampSynchronizer
from noise_monitor.monitor.config import NODE_NAME
from noise_monitor.monitor.period import PeriodSummary
from noise_monitor.monitor.runtime import (
    SETTABLE_PARAMETERS,
    MonitorRuntime,
    check_parameters,
    coerce,
    parameter_table,
)

#: A jump of the node's clock by more than this (s, either way; sim time: /clock starting or looping) restarts the
#: diagnostics period and the image age.
CLOCK_JUMP_S = 5.0
#: How often the node looks for a parameter-driven camera driver to read its parameters from (s).
DRIVER_POLL_S = 0.5
#: How often images waiting for their metadata are checked (the synchroniser's wait, seconds).
SYNC_POLL_S = 0.05
J = TypeVar("J")


def ros_type_name(msg_type: type) -> str:
    """``std_msgs/msg/Float32`` for an rclpy message class (module ``std_msgs.msg._float32``)."""
    package, kind = msg_type.__module__.split(".")[:2]
    return f"{package}/{kind}/{msg_type.__name__}"


@dataclass
class _Job:
    """A matched image waiting for the worker."""

    matched: Matched
    temperature_c: float | str | None  # the latest Temperature reading, or why it cannot be used


def _stamp_ns(msg: Any) -> int:
    s = msg.header.stamp
    return int(s.sec) * 1_000_000_000 + int(s.nanosec)


class LatestJobWorker(Generic[J]):
    """A worker thread that handles the newest waiting job: a job submitted while another one waits
    replaces it (``submit`` returns True then, so the caller counts a dropped frame)."""

    def __init__(self, handle: Callable[[J], None], name: str) -> None:
        self._handle = handle
        self._cv = threading.Condition()
        self._slot: J | None = None
        self._stop = False
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    @property
    def waiting(self) -> bool:
        """A job is waiting for the worker."""
        with self._cv:
            return self._slot is not None

    def submit(self, job: J) -> bool:
        with self._cv:
            replaced = self._slot is not None
            self._slot = job
            self._cv.notify()
        return replaced

    def _run(self) -> None:
        while True:
            with self._cv:
                while self._slot is None and not self._stop:
                    self._cv.wait()
                if self._stop:
                    return
                job, self._slot = self._slot, None
            if job is not None:
                self._handle(job)

    def stop(self, timeout_s: float = 10.0) -> None:
        with self._cv:
            self._stop = True
            self._cv.notify_all()
        self._thread.join(timeout=timeout_s)


def as_declared_types(params: list[Parameter]) -> list[Parameter]:
    """The parameters with an integer given for one of the monitor's float parameters made a double (ROS keeps
    the type it is given: ``ros2 param set ... xi_threshold_dn 3`` would store an INTEGER and ``ros2 param get``
    show it so); anything else unchanged, for the set callback to validate."""
    table = parameter_table()
    return [Parameter(p.name, Parameter.Type.DOUBLE, float(p.value))
            if p.name in table and isinstance(table[p.name][0], float) and p.type_ == Parameter.Type.INTEGER else p
            for p in params]


class NoiseMonitorNode(Node):
    """The live monitor; see the module docstring."""

    def __init__(self, node_name: str = NODE_NAME, estimator: Any = None, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        p, table = {}, parameter_table()
        for name, (default, description) in table.items():
            desc = ParameterDescriptor(description=description, dynamic_typing=True)
            p[name] = coerce(name, self.declare_parameter(name, default, desc).value, default)
        # a YAML or `ros2 param set` integer for a float parameter (3 for 3.0) is stored as the double it means
        given = [self.get_parameter(k) for k in table]
        self.set_parameters([q for q, g in zip(as_declared_types(given), given, strict=True) if q is not g])
        self.add_pre_set_parameters_callback(as_declared_types)
        for name, (_, description) in table.items():  # the unsettable read-only while it runs
            if name not in SETTABLE_PARAMETERS:
                self.set_descriptor(name, ParameterDescriptor(description=description, dynamic_typing=True,
                                                              read_only=True))
        # a camera namespace names the camera: /cam1 and /cam2 report apart on /diagnostics
        p["camera_name"] = p["camera_name"] or self.get_namespace().strip("/").replace("/", "_")
        source_args = {"source": p["metadata_source"], "topic": p["metadata_topic"], "keymap": p["metadata_keymap"],
                       "driver_node": p["metadata_driver_node"], "driver": p["metadata_driver"],
                       "hardware_id": p["hardware_id"]}
        resolve_source(**source_args)  # a bad source, key map or missing driver package: fail before loading
        self.runtime = MonitorRuntime(p, estimator=estimator)
        self.params = p = self.runtime.params
        self.profile = self.runtime.profile
        self.monitor = self.runtime.monitor
        self.metadata_source = resolve_source(**source_args, profile=self.profile)
        self._held: dict | str = {}  # latest values of a held source (parameter events)
        paired = self.metadata_source is not None and not self.metadata_source.held
        wait = p["sync_wait_s"] if paired else 0.0
        self.sync: StampSynchronizer = StampSynchronizer(p["sync_tolerance_s"], wait)
        self.gaps = GapCounter(expected_rate_hz=p["expected_rate_hz"])
        self._last_image_ns = 0
        self._temperature_c: float | str | None = None  # the latest reading, or why it cannot be used
        self._temperature_ns = 0  # when it arrived (node clock)
        self._geometry: CameraGeometry | None = None
        self._last_accept_ns: int | None = None

        ns = self.get_fully_qualified_name()
        self._pubs = {t: self.create_publisher(DiagnosticArray if kind == DIAGNOSTICS_TYPE else Vector3Stamped, t, 10)
                      for t, kind in output_topics(ns).items()}
        self.namespace_out = ns
        compressed = p["image_transport"] == "compressed"  # the base name resolved (remapped) first, as image_transport
        self._image_sub = self.create_subscription(
            CompressedImage if compressed else Image,
            transport_topic(self.resolve_topic_name(p["image_topic"])) if compressed else p["image_topic"],
            # a copy: rclpy writes the qos_overrides.<topic>.subscription.* parameters into the profile it is given
            self._on_image, copy.copy(qos_profile_sensor_data),
            qos_overriding_options=QoSOverridingOptions.with_default_policies())
        relaxed = QoSProfile(depth=20, reliability=ReliabilityPolicy.BEST_EFFORT)
        src = self.metadata_source
        if src is not None:
            qos = QoSProfile(depth=100) if src.held else relaxed  # parameter events are reliable
            self.create_subscription(src.msg_type, src.topic, self._on_metadata, qos)
        self._driver: Any = None  # a driver whose values are its parameters: read once it is up (events tell changes)
        if src is not None and src.driver_node:
            from rclpy.parameter_client import AsyncParameterClient

            self._driver = AsyncParameterClient(self, src.driver_node)
            self._driver_read = False
            self.create_timer(DRIVER_POLL_S, self._read_driver_parameters)
        if p["camera_info_topic"]:
            self.create_subscription(CameraInfo, p["camera_info_topic"], self._on_camera_info, relaxed)
        if p["temperature_topic"]:
            self.create_subscription(Temperature, p["temperature_topic"], self._on_temperature, relaxed)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._debug_pub = self.create_publisher(Image, f"{ns}/debug_image", 2)
        #: a :class:`msg_adapters.live_view.LiveView` (``--foxglove PORT``) mirrored every published message
        self.live: Any = None
        self._last_debug_ns = -(1 << 62)
        self.period = PeriodSummary(self._now())
        # sim time (use_sim_time): /clock starts, loops or restarts; the period and the image age restart with it
        self._jump = self.get_clock().create_jump_callback(
            JumpThreshold(min_forward=Duration(seconds=CLOCK_JUMP_S), min_backward=Duration(seconds=-CLOCK_JUMP_S)),
            post_callback=self._on_clock_jump)
        self.create_timer(self.runtime.diagnostics_period_ns / 1e9, self._on_diagnostics_timer)
        self.create_timer(SYNC_POLL_S, self._on_sync_timer)
        self._worker: LatestJobWorker[_Job] = LatestJobWorker(self._work, "noise_monitor_worker")
        est, cfg = self.runtime.estimator, self.runtime.config
        opts = self.runtime.frame_options
        black = (f", black level {opts.black_level_dn:g} DN taken off every image" if opts.black_level_dn is not None
                 else f", black level: the metadata's per frame, else {opts.black_level:g} DN (profile)")
        self.get_logger().info(
            f"monitoring {self._image_sub.topic_name} with {est.name} (patch {self.monitor.patch_size}, "
            f"K={cfg.patches_per_frame}, xi from {self.monitor.xi_source}"
            f"{black}); outputs /diagnostics at "
            f"{p['diagnostics_rate_hz']:g} Hz, per frame {ns}/frame and {ns}/<sigma_*|xi*>"
        )

    def live_topics(self) -> dict[str, str]:
        """Topic -> ROS 2 type name of what a live view mirrors: every output and the input image."""
        ends: list[Any] = [*self._pubs.values(), self._debug_pub, self._image_sub]
        return {e.topic_name: ros_type_name(e.msg_type) for e in ends}

    def _mirror(self, topic: str, msg: Any, stamp_ns: int) -> None:
        """Send a message to the live view, serialised as ROS does (only when a client subscribed to it)."""
        live = self.live
        if live is not None and live.has_subscribers(topic):
            live.log_cdr(topic, serialize_message(msg), stamp_ns)

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """``ros2 param set``: thresholds, alarm settings and the black level change at run time (validated, the
        alarm keeps its state); every other parameter is read-only while the node runs. Rejections carry the reason."""
        table = parameter_table()  # others (use_sim_time) are rclpy's own
        try:
            changes = {p.name: coerce(p.name, p.value, table[p.name][0]) for p in params if p.name in table}
            black = changes.pop("black_level_dn", None)  # the camera's pedestal: an operator may change it
            if black is not None:
                check_parameters({**self.params, "black_level_dn": black})
            self.monitor.reconfigure(**changes)
        except ValueError as exc:
            self.get_logger().warning(f"parameter change rejected: {exc}")
            return SetParametersResult(successful=False, reason=str(exc))
        if black is not None:
            self.runtime.set_black_level(black)
            changes["black_level_dn"] = black
        self.params.update(changes)
        self.get_logger().info(f"parameters changed: {', '.join(f'{k}={v}' for k, v in changes.items())}")
        return SetParametersResult(successful=True)

    # --- inputs (executor thread) --------------------------------------------------------
    def _now(self) -> int:
        return self.get_clock().now().nanoseconds

    def _on_image(self, msg: Any) -> None:
        stamp = _stamp_ns(msg)
        implausible = self.gaps.implausible
        lost = self.gaps.observe(stamp)
        self.monitor.count_lost(lost, self.gaps.implausible - implausible)
        self._last_image_ns = self._now()
        for matched in self.sync.add_image(stamp, msg, self._last_image_ns):
            self._enqueue(matched)

    def _on_metadata(self, msg: Any) -> None:
        assert self.metadata_source is not None
        try:
            values: dict | str | None = self.metadata_source.convert(msg)
        except AdapterError as exc:
            values = str(exc)  # the frames it belongs to report the problem
        if values is None:  # not this camera's (another node's parameter event)
            return
        serial = None if self.params["hardware_id"] else self.metadata_source.hardware_id(msg)
        if serial and serial != self.monitor.hardware_id:
            self.monitor.hardware_id = serial  # the driver's device id: two cameras of one model stay apart
        if self.metadata_source.held:
            self._held = values
            return
        stamp = _stamp_ns(msg) if hasattr(msg, "header") else self._now()  # Basler: no header
        for matched in self.sync.add_metadata(stamp, values):
            self._enqueue(matched)

    def _read_driver_parameters(self) -> None:
        """Read the driver's parameters whenever it (re)appears: /parameter_events has no history, so a driver that
        started first would tell its exposure and gain only when they change."""
        ready = self._driver.services_are_ready()
        if ready and not self._driver_read:
            self._driver_read = True
            assert self.metadata_source is not None
            for name in self.metadata_source.parameter_names:  # one by one: a name the driver lacks fails the request
                self._driver.get_parameters([name]).add_done_callback(partial(self._on_driver_parameters, name))
        elif not ready:
            self._driver_read = False

    def _on_driver_parameters(self, name: str, future: Any) -> None:
        src = self.metadata_source
        assert src is not None and src.from_values is not None
        try:
            values: dict | str = src.from_values(read_values([name], future.result().values))
        except AdapterError as exc:
            values = str(exc)
        except Exception as exc:  # the service call failed: try again when the driver is next up
            self.get_logger().warning(f"reading the parameters of {src.driver_node} failed: {exc!r}")
            self._driver_read = False
            return
        self._held = values

    def _on_camera_info(self, msg: Any) -> None:
        try:
            self._geometry = camera_geometry(msg)
        except AdapterError as exc:
            self._geometry = None
            self.get_logger().warning(f"ignoring CameraInfo: {exc}", throttle_duration_sec=10.0)

    def _on_temperature(self, msg: Any) -> None:
        self._temperature_ns = self._now()
        try:
            self._temperature_c = metadata_from_temperature(msg)["sensor_temperature_c"]
        except AdapterError as exc:  # the frames that need it say why (an older reading is no longer the camera's)
            self._temperature_c = f"Temperature topic: {exc}"
            self.get_logger().warning(f"Temperature unusable: {exc}", throttle_duration_sec=10.0)

    def _temperature(self, now_ns: int) -> float | str | None:
        """The latest Temperature reading for a frame now, or why there is none to use (stale after
        metadata_timeout_s, as the metadata)."""
        age = (now_ns - self._temperature_ns) / 1e9
        timeout = self.runtime.config.metadata_timeout_s
        if isinstance(self._temperature_c, float) and age > timeout:
            return f"Temperature topic stale: last reading {age:.2f} s ago (timeout {timeout:g} s)"
        return self._temperature_c

    def _enqueue(self, matched: Matched) -> None:
        max_rate = self.params["max_rate_hz"]
        now = self._now()
        if max_rate > 0 and self._last_accept_ns is not None and now - self._last_accept_ns < 1e9 / max_rate:
            self.monitor.count_dropped()
            return
        self._last_accept_ns = now
        if self._worker.submit(_Job(matched, self._temperature(now))):
            self.monitor.count_dropped()  # the worker is busy: keep the newest frame only

    def _on_sync_timer(self) -> None:
        for matched in self.sync.poll(self._now()):
            self._enqueue(matched)

    def _on_clock_jump(self, jump: Any) -> None:
        """The node's clock jumped (sim time started, a bag looped): what was timed on the old clock restarts."""
        now = self._now()
        self.period.restart(now)
        self.monitor.clock_jumped(now)
        for matched in self.sync.poll(now + (1 << 62)):  # images waiting on the old clock: released now
            self._enqueue(matched)
        self.get_logger().info(f"clock jumped by {jump.delta.nanoseconds / 1e9:+.3f} s: the period and the image age "
                               "restart")

    def _on_diagnostics_timer(self) -> None:
        """``/diagnostics`` at diagnostics_rate_hz: the summary of the period since the previous one."""
        now = self._now()
        if self.gaps.pending and now - self._last_image_ns > self.gaps.pause_ns:  # the stream stopped: judge its end
            self.monitor.count_lost(self.gaps.flush())
        self._publish(rclpy_messages(self.period.report(self.monitor, now), stamp_ns=now))

    # --- worker thread -------------------------------------------------------------------
    def _work(self, job: _Job) -> None:
        """Evaluate a frame and publish its outputs; a failure anywhere is logged and the worker goes on (the frame
        counted once: skipped with the reason when the evaluation itself failed)."""
        received = self.monitor.counters["frames_received"]
        try:
            frame = self._prepare(job)
            result = self.runtime.process(frame, received_ns=job.matched.received_ns)
        except Exception as exc:  # keep the node alive; the status names the failure
            self.get_logger().error(f"frame evaluation failed: {exc!r}")
            result = self.monitor.reject(job.matched.stamp_ns, f"evaluation failed: {exc}", job.matched.received_ns,
                                         counted=self.monitor.counters["frames_received"] > received)
            frame = None
        try:
            self.period.add(result)
            self._publish(rclpy_messages(result, namespace=self.namespace_out,
                                         frame_id=job.matched.image.header.frame_id))
            if frame is not None:
                self._publish_debug_image(frame.image_dn, result, job.matched.image.header)
            if self.live is not None:
                self._mirror(self._image_sub.topic_name, job.matched.image, result.stamp_ns)
                self.live.broadcast_time(result.stamp_ns)
        except Exception as exc:  # an output that failed: the next frame's are tried again
            self.get_logger().error(f"publishing the frame's outputs failed: {exc!r}", throttle_duration_sec=10.0)

    def _prepare(self, job: _Job) -> Any:
        """The job's Frame (image, metadata and the driver's held parameters merged, Temperature, CameraInfo)."""
        m = job.matched
        held, metadata = self._held, m.metadata
        if isinstance(held, str) and not isinstance(metadata, str):
            metadata = held  # the driver's parameters could not be read
        elif isinstance(held, dict) and held and not isinstance(metadata, (str, Exception)):
            metadata = {**held, **(metadata or {})}
        return prepare_frame(m.image, m.stamp_ns, self.runtime.frame_options, metadata=metadata,
                             metadata_stamp_ns=m.metadata_stamp_ns, temperature_c=job.temperature_c,
                             geometry=self._geometry)

    def _publish_debug_image(self, image_dn: Any, result: FrameResult, header: Any) -> None:
        """``~/debug_image`` at most at debug_image_rate_hz: the frame with its patches coloured by xi."""
        rate = self.params["debug_image_rate_hz"]
        now = self._now()
        if rate <= 0 or not result.processed or result.patches is None or now - self._last_debug_ns < 1e9 / rate:
            return
        self._last_debug_ns = now
        rgb = debug_view(image_dn, result.patches.corners, result.patches.size, result.patch_xi,
                         self.monitor.config.xi_threshold_dn)
        msg = Image(height=rgb.shape[0], width=rgb.shape[1], encoding="rgb8", step=rgb.shape[1] * 3,
                    data=rgb.tobytes())
        msg.header = header  # stamped with the image it shows
        self._debug_pub.publish(msg)
        self._mirror(self._debug_pub.topic_name, msg, result.stamp_ns)

    def _publish(self, messages: dict[str, Any]) -> None:
        for topic, msg in messages.items():
            pub = self._pubs[topic]
            pub.publish(msg)
            self._mirror(pub.topic_name, msg, _stamp_ns(msg))  # every output is stamped

    @property
    def temperature_c(self) -> float | None:
        """The latest sensor temperature from the Temperature topic (None before the first or when unusable)."""
        return self._temperature_c if isinstance(self._temperature_c, float) else None

    def summary(self) -> dict[str, Any]:
        """Counters, alarm episodes and the last status (for --json); the stamp intervals still waiting are judged."""
        self.monitor.count_lost(self.gaps.flush())
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
        self._worker.stop()
        super().destroy_node()


def node_class() -> type[NoiseMonitorNode]:
    """The node class (kept for scripts written against the former lazy factory)."""
    return NoiseMonitorNode


# --- running it ---------------------------------------------------------------------------------
def spin(argv: list[str], overrides: dict[str, Any], duration_s: float | None = None,
         json_path: str | None = None, foxglove_port: int | None = None, foxglove_host: str = "127.0.0.1") -> int:
    """Run the node until Ctrl-C (or ``duration_s``); optional JSON summary at exit.

    ``argv``: process arguments as rclpy.init expects them (ROS arguments after ``--ros-args``).
    ``foxglove_port``: also serve the node's topics over the Foxglove WebSocket protocol (0 = a free port)."""
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.parameter import Parameter

    context = rclpy.Context()
    rclpy.init(args=argv, context=context)
    node = None
    live = None
    stop = threading.Event()
    previous = _catch_signals(stop)
    try:
        params = [Parameter(k, value=v) for k, v in overrides.items()]
        node = node_class()(parameter_overrides=params, context=context)
        if foxglove_port is not None:
            from msg_adapters.live_view import LiveView

            live = LiveView(node.live_topics(), foxglove_port, host=foxglove_host)
            node.live = live
            print(f"foxglove: serving {live.url} (Foxglove: Open connection > Foxglove WebSocket)", flush=True)
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
        if live is not None:  # after the worker stopped: nothing logs into a closed server
            live.close()
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
    parser.epilog = ("Every ROS parameter with its default and description, and the topics published: "
                     "noise_monitor_node --help. Set any parameter with --ros-args -p NAME:=VALUE.")
    parser.add_argument("--params-file", help="ROS params YAML (default: the package's config/node.yaml)")
    table = parameter_table()
    for name, kind in _CLI_OVERRIDES.items():
        parser.add_argument(f"--{name.replace('_', '-')}", dest=name, type=kind, default=None,
                            help=f"{table[name][1]} (overrides the params file)")
    parser.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    parser.add_argument("--json", metavar="PATH", help="write counters, alarm episodes and the last status at exit")
    parser.add_argument("--foxglove", type=int, metavar="PORT",
                        help="also serve the outputs, ~/debug_image and the input image over the Foxglove WebSocket "
                             "protocol on 127.0.0.1:PORT (0 = a free port; needs foxglove-sdk)")
    parser.add_argument("--foxglove-host", default="127.0.0.1", metavar="HOST",
                        help="address to serve on (0.0.0.0 for other machines; default 127.0.0.1)")
    parser.add_argument("--ros-args", dest="ros_args", nargs=argparse.REMAINDER, default=[],
                        help="remaining arguments are passed to ROS (remappings, -p name:=value)")


#: image_transport's sub-topics of a base image topic whose messages are sensor_msgs/CompressedImage
COMPRESSED_SUFFIXES = ("/compressed", "/compressedDepth", "/zstd")


def transport_topic(image_topic: str) -> str:
    """The CompressedImage topic of a base image topic as image_transport names it (``image`` -> ``image/compressed``);
    a topic already naming a transport (``image/zstd``) is kept."""
    return image_topic if image_topic.endswith(COMPRESSED_SUFFIXES) else f"{image_topic.rstrip('/')}/compressed"


def _remapped(ros_args: list[str], what: str, default: str) -> str:
    """The node's name (``__node``) or namespace (``__ns``) after ``-r what:=VALUE`` among the ROS arguments."""
    values = [a.split(":=", 1)[1] for a in ros_args if a.startswith(f"{what}:=")
              or (what == "__node" and a.startswith("__name:="))]
    return values[-1] if values else default


def run(args: argparse.Namespace) -> int:
    from .monitor.config import default_params_path, read_ros_params

    params_file = Path(args.params_file) if args.params_file else default_params_path()
    if not params_file.is_file():
        raise FileNotFoundError(f"params file {params_file} not found")
    name, namespace = _remapped(args.ros_args, "__node", NODE_NAME), _remapped(args.ros_args, "__ns", "/")
    others: list[str] = []
    unknown = sorted(set(read_ros_params(params_file, name, namespace, parameter_table(), others))
                     - set(parameter_table()))
    if others:  # rcl gives every node these; the monitor declares none of them
        print(f"note: {params_file}: parameter(s) {', '.join(sorted(set(others)))} of every node's section are not "
              "the monitor's (other nodes'; a typo?)", file=sys.stderr)
    if unknown:
        raise ValueError(f"{params_file}: unknown parameter(s) {', '.join(unknown)}")
    overrides = {k: getattr(args, k) for k in _CLI_OVERRIDES if getattr(args, k) is not None}
    if args.duration is not None and args.duration <= 0:
        raise ValueError("--duration must be > 0")
    if args.foxglove is not None and not 0 <= args.foxglove <= 65535:
        raise ValueError(f"--foxglove port must be 0..65535, got {args.foxglove}")
    argv = ["noise-monitor", "--ros-args", "--params-file", str(params_file), *args.ros_args]
    return spin(argv, overrides, args.duration, args.json, args.foxglove, args.foxglove_host)


def node_help() -> str:
    """``noise_monitor_node --help``: how to run it the ROS way, its parameters (default, description) and outputs."""
    lines = ["usage: ros2 run noise_monitor noise_monitor_node [--ros-args [--params-file FILE] [-p NAME:=VALUE] "
             "[-r __ns:=/NS] [-r image:=TOPIC] ...]",
             "", "Online camera noise diagnosis: per frame PN, DCSN, RN and the residual xi; alarms on /diagnostics.",
             "(`noise-monitor node --help`: the same node with plain command-line options.)", "",
             "parameters (ROS parameters; defaults of config/node.yaml may differ):"]
    for name, (default, description) in parameter_table().items():
        lines.append(f"  {name} ({type(default).__name__}, default {default!r}): {description}")
    lines += ["", "publishes (in the default namespace; -r __ns:=/NS moves all but /diagnostics):"]
    lines += [f"  {topic} [{kind}]" for topic, kind in output_topics().items()]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Console script ``noise_monitor_node`` (ROS style: configure with --ros-args; ``--help`` before them prints
    :func:`node_help`)."""
    from .cli import USER_ERRORS, error_line

    args = list(sys.argv[1:] if argv is None else argv)
    own = args[:args.index("--ros-args")] if "--ros-args" in args else args
    if {"-h", "--help"} & set(own):
        print(node_help())
        return 0
    try:
        return spin(list(sys.argv if argv is None else ["noise_monitor_node", *argv]), {})
    except USER_ERRORS as exc:  # the same one-line errors as `noise-monitor node`
        print(f"noise_monitor_node: error: {error_line(exc)}", file=sys.stderr)
        return 2
