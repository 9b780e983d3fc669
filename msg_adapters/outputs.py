"""Output topics of the monitor: the node publishes and the replay writes exactly these.

Per frame, stamped with the image's header (stamp and frame_id), under the monitor's namespace (default
``/noise_monitor``; the node uses its own ``~/``):

- ``<ns>/frame`` (diagnostic_msgs/DiagnosticArray): the frame's status, evaluated or skipped, with every
  per-frame number as a numeric string (PlotJuggler plots them; tools read one topic);
- ``<ns>/<key>`` for each of :data:`NUMERIC_KEYS` (geometry_msgs/Vector3Stamped, the value in
  ``vector.x``, y and z 0): stamped numbers Foxglove's Plot panel plots without plug-ins (there is no
  stamped scalar in common_interfaces; Vector3Stamped is the smallest stamped all-numeric one that does
  not claim a physical quantity). Only evaluated frames have numbers, and only a still hold's frames have the
  frame differences' (:data:`HOLD_KEYS`).

Periodic: ``/diagnostics`` (diagnostic_msgs/DiagnosticArray), the period summary
(``noise_monitor.monitor.period``) or an idle status, stamped with the clock at the report.
:func:`rclpy_messages` / :func:`rosbags_messages` build the per-frame topics of a FrameResult and the
``/diagnostics`` message of a StatusReport, with identical contents in both middlewares.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from noise_monitor.monitor.pipeline import FrameResult
from noise_monitor.monitor.status import StatusReport

from .diagnostics import jazzy_typestore, to_rclpy, to_rosbags

DIAGNOSTICS_TOPIC = "/diagnostics"
DIAGNOSTICS_TYPE = "diagnostic_msgs/msg/DiagnosticArray"
NUMBER_TYPE = "geometry_msgs/msg/Vector3Stamped"
IMAGE_TYPE = "sensor_msgs/msg/Image"
#: ``<namespace>/debug_image``: the frame with its patches coloured by xi (msg_adapters.debug_image).
DEBUG_IMAGE = "debug_image"
#: ``<namespace>/frame``: every frame's status (DiagnosticArray stamped with the image's header).
FRAME = "frame"
DEFAULT_NAMESPACE = "/noise_monitor"
#: FrameResult.numeric() keys published as their own stamped number (<namespace>/<key>, ``vector.x``).
NUMERIC_KEYS = ("sigma_pn", "sigma_dcsn", "sigma_rn", "sigma_total", "sigma_model", "sigma_image", "xi",
                "xi_filtered", "xi_model", "alarm", "xi_threshold", "sigma_temporal", "xi_temporal")
#: Of those, the numbers only a still hold's frames have (the frame differences' measurement).
HOLD_KEYS = ("sigma_temporal", "xi_temporal")


def namespace_prefix(namespace: str) -> str:
    """A monitor namespace as an absolute topic prefix (``noise_monitor/`` -> ``/noise_monitor``)."""
    return "/" + namespace.strip("/")


def frame_topic(namespace: str = DEFAULT_NAMESPACE) -> str:
    """``<namespace>/frame``."""
    return f"{namespace_prefix(namespace)}/{FRAME}"


def output_topics(namespace: str = DEFAULT_NAMESPACE) -> dict[str, str]:
    """Topic name -> message type name for a monitor namespace (``/diagnostics`` first)."""
    ns = namespace_prefix(namespace)
    return {DIAGNOSTICS_TOPIC: DIAGNOSTICS_TYPE, frame_topic(ns): DIAGNOSTICS_TYPE,
            **{f"{ns}/{k}": NUMBER_TYPE for k in NUMERIC_KEYS}}


OUTPUT_TOPICS: dict[str, str] = output_topics()


def debug_image_topic(namespace: str = DEFAULT_NAMESPACE) -> str:
    """``<namespace>/debug_image`` (sensor_msgs/Image rgb8, at most debug_image_rate_hz)."""
    return f"{namespace_prefix(namespace)}/{DEBUG_IMAGE}"


def _numbers(result: FrameResult, namespace: str) -> dict[str, float]:
    values = result.numeric()
    ns = namespace_prefix(namespace)
    return {f"{ns}/{k}": float(values[k]) for k in NUMERIC_KEYS if k in values}


def rclpy_messages(result: FrameResult | StatusReport, stamp_ns: int | None = None,
                   namespace: str = DEFAULT_NAMESPACE, frame_id: str = "") -> dict[str, Any]:
    """{topic: rclpy message}: a frame result's per-frame topics (stamped with its image's stamp and
    ``frame_id``), or ``/diagnostics`` for a StatusReport (stamped ``stamp_ns``)."""
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import Vector3, Vector3Stamped
    from std_msgs.msg import Header

    if isinstance(result, StatusReport):
        return {DIAGNOSTICS_TOPIC: to_rclpy([result], _status_stamp(stamp_ns))}
    msg = to_rclpy([result.report()], result.stamp_ns)
    msg.header.frame_id = frame_id
    out: dict[str, Any] = {frame_topic(namespace): msg}
    sec, nsec = divmod(int(result.stamp_ns), 1_000_000_000)
    for topic, v in _numbers(result, namespace).items():
        out[topic] = Vector3Stamped(header=Header(stamp=Time(sec=sec, nanosec=nsec), frame_id=frame_id),
                                    vector=Vector3(x=v))
    return out


def rosbags_messages(result: FrameResult | StatusReport, stamp_ns: int | None = None,
                     namespace: str = DEFAULT_NAMESPACE, typestore: Any = None, frame_id: str = "") -> dict[str, Any]:
    """{topic: rosbags message} with the same topics and values as :func:`rclpy_messages`."""
    ts = typestore or jazzy_typestore()
    if isinstance(result, StatusReport):
        return {DIAGNOSTICS_TOPIC: to_rosbags([result], _status_stamp(stamp_ns), ts)}
    t = ts.types
    msg = to_rosbags([result.report()], result.stamp_ns, ts)
    msg.header.frame_id = frame_id
    out: dict[str, Any] = {frame_topic(namespace): msg}
    sec, nsec = divmod(int(result.stamp_ns), 1_000_000_000)
    header = t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id=frame_id)
    vector, stamped = t["geometry_msgs/msg/Vector3"], t[NUMBER_TYPE]
    for topic, v in _numbers(result, namespace).items():
        out[topic] = stamped(header=header, vector=vector(x=v, y=0.0, z=0.0))
    return out


def rosbags_image(image: np.ndarray, stamp_ns: int, frame_id: str = "", typestore: Any = None) -> Any:
    """A rosbags sensor_msgs/Image of an (H, W) uint8 (mono8) / uint16 (mono16) or (H, W, 3) uint8 (rgb8) array."""
    ts = typestore or jazzy_typestore()
    img = np.ascontiguousarray(image)
    if img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8:
        encoding = "rgb8"
    elif img.ndim == 2 and img.dtype in (np.uint8, np.uint16):
        encoding = "mono8" if img.dtype == np.uint8 else "mono16"
        img = img.astype("<u2") if img.dtype == np.uint16 else img
    else:
        raise ValueError(f"an image message needs (H, W) uint8/uint16 or (H, W, 3) uint8, got {img.shape} {img.dtype}")
    t = ts.types
    stamp = t["builtin_interfaces/msg/Time"](sec=int(stamp_ns // 10**9), nanosec=int(stamp_ns % 10**9))
    return t[IMAGE_TYPE](header=t["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id), height=img.shape[0],
                         width=img.shape[1], encoding=encoding, is_bigendian=0, step=img.strides[0],
                         data=np.frombuffer(img.tobytes(), np.uint8))


def _status_stamp(stamp_ns: int | None) -> int:
    if stamp_ns is None:
        raise ValueError("a StatusReport needs stamp_ns")
    return stamp_ns


def number_of(msg: Any) -> float:
    """The value of one of the stamped number topics (either middleware)."""
    return float(msg.vector.x)
