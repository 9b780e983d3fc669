"""Diagnostic status reports and their DiagnosticArray messages for rclpy and rosbags.

The level is ``bytes`` (length 1) in rclpy and ``int`` in rosbags: this module is the only place where
that conversion happens. Everything else uses the core's :class:`StatusReport` with int levels
(``noise_monitor.monitor.status``, re-exported here).
"""
from __future__ import annotations

from collections.abc import Iterable
from functools import lru_cache
from typing import Any

from noise_monitor.monitor.status import ERROR, LEVEL_NAMES, OK, STALE, WARN, StatusReport

__all__ = ["ERROR", "LEVEL_NAMES", "OK", "STALE", "WARN", "StatusReport", "jazzy_typestore", "level_of",
           "reports_from_msg", "to_rclpy", "to_rosbags"]


def _stamp(stamp_ns: int) -> tuple[int, int]:
    return int(stamp_ns) // 1_000_000_000, int(stamp_ns) % 1_000_000_000


def to_rclpy(reports: Iterable[StatusReport], stamp_ns: int) -> Any:
    """diagnostic_msgs/msg/DiagnosticArray (rclpy) with the given header stamp."""
    from builtin_interfaces.msg import Time
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from std_msgs.msg import Header

    sec, nsec = _stamp(stamp_ns)
    msg = DiagnosticArray(header=Header(stamp=Time(sec=sec, nanosec=nsec)))
    msg.status = [
        DiagnosticStatus(
            level=bytes([r.level]), name=r.name, message=r.message, hardware_id=r.hardware_id,
            values=[KeyValue(key=k, value=v) for k, v in r.values.items()],
        )
        for r in reports
    ]
    return msg


def to_rosbags(reports: Iterable[StatusReport], stamp_ns: int, typestore: Any = None) -> Any:
    """diagnostic_msgs/msg/DiagnosticArray (rosbags dataclasses) with the given header stamp."""
    ts = typestore or jazzy_typestore()
    t = ts.types
    sec, nsec = _stamp(stamp_ns)
    header = t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id="")
    status = [
        t["diagnostic_msgs/msg/DiagnosticStatus"](
            level=int(r.level), name=r.name, message=r.message, hardware_id=r.hardware_id,
            values=[t["diagnostic_msgs/msg/KeyValue"](key=k, value=v) for k, v in r.values.items()],
        )
        for r in reports
    ]
    return t["diagnostic_msgs/msg/DiagnosticArray"](header=header, status=status)


def level_of(status: Any) -> int:
    """Int level of a DiagnosticStatus from either middleware."""
    level = status.level
    return level[0] if isinstance(level, (bytes, bytearray)) else int(level)


def reports_from_msg(msg: Any) -> list[StatusReport]:
    """StatusReports of a DiagnosticArray from either middleware (for reading results back)."""
    return [
        StatusReport(level_of(s), s.name, s.message, s.hardware_id, {kv.key: kv.value for kv in s.values})
        for s in msg.status
    ]


@lru_cache(maxsize=1)
def jazzy_typestore() -> Any:
    """The rosbags ROS 2 Jazzy typestore, built once (~85 ms) and shared."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)
