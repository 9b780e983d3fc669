"""Output topics of the monitor: the node publishes and the replay writes exactly these.

``/diagnostics`` (diagnostic_msgs/DiagnosticArray, one status ``noise_monitor: <camera>``) and one
std_msgs/Float32 topic per plotted number under the monitor's namespace (default ``/noise_monitor``;
the node uses its own ``~/`` namespace), e.g. ``/noise_monitor/sigma_rn``: Foxglove and PlotJuggler plot
``.data`` without plug-ins. Numeric topics are only published for evaluated frames.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from noise_monitor.monitor.pipeline import FrameResult
from noise_monitor.monitor.status import StatusReport

from .diagnostics import jazzy_typestore, to_rclpy, to_rosbags

DIAGNOSTICS_TOPIC = "/diagnostics"
DIAGNOSTICS_TYPE = "diagnostic_msgs/msg/DiagnosticArray"
NUMBER_TYPE = "std_msgs/msg/Float32"
IMAGE_TYPE = "sensor_msgs/msg/Image"
#: ``<namespace>/debug_image``: the frame with its patches coloured by xi (msg_adapters.debug_image).
DEBUG_IMAGE = "debug_image"
DEFAULT_NAMESPACE = "/noise_monitor"
#: FrameResult.numeric() keys published as their own topic (<namespace>/<key>).
NUMERIC_KEYS = ("sigma_pn", "sigma_dcsn", "sigma_rn", "sigma_total", "sigma_model", "xi", "xi_filtered",
                "xi_model", "alarm", "xi_threshold")


def output_topics(namespace: str = DEFAULT_NAMESPACE) -> dict[str, str]:
    """Topic name -> message type name for a monitor namespace."""
    ns = "/" + namespace.strip("/")
    return {DIAGNOSTICS_TOPIC: DIAGNOSTICS_TYPE, **{f"{ns}/{k}": NUMBER_TYPE for k in NUMERIC_KEYS}}


OUTPUT_TOPICS: dict[str, str] = output_topics()


def debug_image_topic(namespace: str = DEFAULT_NAMESPACE) -> str:
    """``<namespace>/debug_image`` (sensor_msgs/Image rgb8, at most debug_image_rate_hz)."""
    return "/" + namespace.strip("/") + "/" + DEBUG_IMAGE


def _parts(result: FrameResult | StatusReport, stamp_ns: int | None, namespace: str
           ) -> tuple[StatusReport, int, dict[str, float]]:
    if isinstance(result, FrameResult):
        numbers = result.numeric()
        ns = "/" + namespace.strip("/")
        return result.report(), result.stamp_ns, {f"{ns}/{k}": numbers[k] for k in NUMERIC_KEYS if k in numbers}
    if stamp_ns is None:
        raise ValueError("a StatusReport needs stamp_ns")
    return result, stamp_ns, {}


def rclpy_messages(result: FrameResult | StatusReport, stamp_ns: int | None = None,
                   namespace: str = DEFAULT_NAMESPACE) -> dict[str, Any]:
    """{topic: rclpy message} for a frame result (or an idle StatusReport stamped ``stamp_ns``)."""
    from std_msgs.msg import Float32

    report, stamp, numbers = _parts(result, stamp_ns, namespace)
    out: dict[str, Any] = {DIAGNOSTICS_TOPIC: to_rclpy([report], stamp)}
    out.update({topic: Float32(data=float(v)) for topic, v in numbers.items()})
    return out


def rosbags_messages(result: FrameResult | StatusReport, stamp_ns: int | None = None,
                     namespace: str = DEFAULT_NAMESPACE, typestore: Any = None) -> dict[str, Any]:
    """{topic: rosbags message} with the same topics and values as :func:`rclpy_messages`."""
    ts = typestore or jazzy_typestore()
    report, stamp, numbers = _parts(result, stamp_ns, namespace)
    number = ts.types[NUMBER_TYPE]
    out: dict[str, Any] = {DIAGNOSTICS_TOPIC: to_rosbags([report], stamp, ts)}
    out.update({topic: number(data=float(v)) for topic, v in numbers.items()})
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
