"""Output topics of the monitor: the node publishes and the replay writes exactly these.

``/diagnostics`` (diagnostic_msgs/DiagnosticArray, one status ``noise_monitor: <camera>``) and one
std_msgs/Float32 topic per plotted number under the monitor's namespace (default ``/noise_monitor``;
the node uses its own ``~/`` namespace), e.g. ``/noise_monitor/sigma_rn``: Foxglove and PlotJuggler plot
``.data`` without plug-ins. Numeric topics are only published for evaluated frames.
"""
from __future__ import annotations

from typing import Any

from noise_monitor.monitor.pipeline import FrameResult
from noise_monitor.monitor.status import StatusReport

from .diagnostics import jazzy_typestore, to_rclpy, to_rosbags

DIAGNOSTICS_TOPIC = "/diagnostics"
DIAGNOSTICS_TYPE = "diagnostic_msgs/msg/DiagnosticArray"
NUMBER_TYPE = "std_msgs/msg/Float32"
DEFAULT_NAMESPACE = "/noise_monitor"
#: FrameResult.numeric() keys published as their own topic (<namespace>/<key>).
NUMERIC_KEYS = ("sigma_pn", "sigma_dcsn", "sigma_rn", "sigma_total", "sigma_model", "xi", "xi_filtered",
                "xi_model", "alarm")


def output_topics(namespace: str = DEFAULT_NAMESPACE) -> dict[str, str]:
    """Topic name -> message type name for a monitor namespace."""
    ns = "/" + namespace.strip("/")
    return {DIAGNOSTICS_TOPIC: DIAGNOSTICS_TYPE, **{f"{ns}/{k}": NUMBER_TYPE for k in NUMERIC_KEYS}}


OUTPUT_TOPICS: dict[str, str] = output_topics()


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
