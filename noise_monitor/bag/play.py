"""Publish a bag into live ROS 2 topics (rclpy) with its original timing, a rate factor and looping.

Messages are published as the bag's serialized CDR bytes (no re-encoding, so values are bit-exact);
topics whose message type has no rclpy type support installed are reported and left out.
"""
from __future__ import annotations

import importlib
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tqdm import tqdm

from .reader import BagReader


@dataclass
class PlayStats:
    """What a playback published."""

    published: dict[str, int] = field(default_factory=dict)
    unsupported: dict[str, str] = field(default_factory=dict)  # topic -> message type without rclpy support
    loops: int = 0
    wall_time_s: float = 0.0
    bag_duration_s: float = 0.0
    max_lag_s: float = 0.0  # worst delay behind the schedule

    def as_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


#: Playback speed factors accepted: 1000x slower to 1000x faster (a rate of 1e-300 would sleep for ever).
RATE_RANGE = (1e-3, 1e3)
#: Highest /clock rate (ros2 bag play's default is 40 Hz).
MAX_CLOCK_HZ = 1000.0


def rclpy_type(msgtype: str) -> type | None:
    """The rclpy message class of 'pkg/msg/Name', or None when its package is not installed."""
    pkg, _, name = msgtype.partition("/msg/")
    try:
        return getattr(importlib.import_module(f"{pkg}.msg"), name)
    except (ImportError, AttributeError):
        return None


def play(bag: str | Path, rate: float = 1.0, loop: bool = False, topics: list[str] | None = None,
         wait_subscribers_s: float = 0.0, wait_topics: list[str] | None = None, node: Any = None,
         progress: bool = True, should_stop: Callable[[], bool] = lambda: False, clock_hz: float = 0.0) -> PlayStats:
    """Publish the bag's messages at their log times scaled by ``1/rate`` (``loop``: until interrupted).

    ``wait_subscribers_s``: before starting, wait up to this long until each of ``wait_topics`` (default:
    the detected image and metadata topics) has a subscriber, so a node starting alongside sees frame 0.
    ``node``: an rclpy node to publish from (default: a new ``noise_monitor_player`` node).
    ``clock_hz``: also publish the bag's time on ``/clock`` (rosgraph_msgs/Clock) this often and before every
    message, as ``ros2 bag play --clock`` does, for nodes with ``use_sim_time``.
    """
    if not RATE_RANGE[0] <= rate <= RATE_RANGE[1]:
        raise ValueError(f"rate must be in [{RATE_RANGE[0]:g}, {RATE_RANGE[1]:g}], got {rate:g}")
    if not 0.0 <= clock_hz <= MAX_CLOCK_HZ:
        raise ValueError(f"clock_hz must be in [0, {MAX_CLOCK_HZ:g}] Hz, got {clock_hz:g}")
    import rclpy

    own_context = not rclpy.ok()
    if own_context:  # no rclpy signal handlers: they would shut the context down under the publishing loop
        from rclpy.signals import SignalHandlerOptions

        rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    own_node = node is None
    stats = PlayStats()
    try:
        if own_node:
            node = rclpy.create_node("noise_monitor_player")
        with BagReader(bag, detect_topics=False) as reader:
            wanted = [t for t in reader.topics if topics is None or t in topics]
            missing = sorted(set(topics or ()) - set(reader.topics))
            if missing:
                raise ValueError(f"topic(s) {', '.join(missing)} not in bag {bag}")
            pubs = {}
            for topic in wanted:
                cls = rclpy_type(reader.topics[topic])
                if cls is None:
                    stats.unsupported[topic] = reader.topics[topic]
                    continue
                pubs[topic] = node.create_publisher(cls, topic, 10)
            if not pubs:
                raise ValueError(f"no topic of bag {bag} has an installed rclpy message type")
            clock = _Clock(node, clock_hz) if clock_hz > 0 else None
            if wait_subscribers_s > 0:
                _wait_for_subscribers(pubs, wait_topics or _camera_topics(bag), wait_subscribers_s)
            stats.bag_duration_s = reader.duration_s
            t_start = time.perf_counter()
            try:
                _publish_loop(reader, pubs, rate, loop, stats, progress, should_stop, Path(bag).name, clock)
            finally:
                stats.wall_time_s = time.perf_counter() - t_start
    finally:
        if own_node and node is not None:
            node.destroy_node()
        if own_context and rclpy.ok():
            rclpy.shutdown()
    return stats


class _Clock:
    """Publishes the bag's time on /clock, at most ``hz`` apart while waiting for the next message."""

    def __init__(self, node: Any, hz: float) -> None:
        from rosgraph_msgs.msg import Clock

        self._msg = Clock
        self.pub = node.create_publisher(Clock, "/clock", 10)
        self.period_s = 1.0 / hz

    def publish(self, bag_ns: int) -> None:
        msg = self._msg()
        msg.clock.sec, msg.clock.nanosec = divmod(int(bag_ns), 1_000_000_000)
        self.pub.publish(msg)

    def wait(self, until_s: float, first_ns: int, t_loop: float, rate: float) -> None:
        """Sleep until ``until_s`` (perf_counter), publishing the bag time on the way."""
        while (left := until_s - time.perf_counter()) > 0:
            time.sleep(min(left, self.period_s))
            self.publish(first_ns + int((min(time.perf_counter(), until_s) - t_loop) * rate * 1e9))


def _publish_loop(reader: BagReader, pubs: dict[str, Any], rate: float, loop: bool, stats: PlayStats,
                  progress: bool, should_stop: Callable[[], bool], name: str, clock: _Clock | None = None) -> None:
    n = reader.count(list(pubs))
    with tqdm(total=n, unit="msg", desc=f"play {name}", disable=not progress) as bar:
        while True:
            t_loop = time.perf_counter()
            first: int | None = None
            for topic, _, log_time, raw in reader.raw_messages(list(pubs)):
                first = log_time if first is None else first
                due = t_loop + (log_time - first) / 1e9 / rate
                delay = due - time.perf_counter()
                if delay > 0:
                    if clock is not None:
                        clock.wait(due, first, t_loop, rate)
                    else:
                        time.sleep(delay)
                else:
                    stats.max_lag_s = max(stats.max_lag_s, -delay)
                if clock is not None:
                    clock.publish(log_time)
                if should_stop():
                    return
                pubs[topic].publish(raw)
                stats.published[topic] = stats.published.get(topic, 0) + 1
                bar.update(1)
            stats.loops += 1
            if not loop or should_stop():
                return
            bar.reset(total=n)


def _camera_topics(bag: str | Path) -> list[str]:
    """The image and metadata topics a monitor subscribes to (auto-detected)."""
    with BagReader(bag) as r:
        return [t for t in (r.image_topic, r.metadata_topic) if t]


def _wait_for_subscribers(pubs: dict[str, Any], topics: list[str], timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    waiting = [t for t in topics if t in pubs]
    while waiting and time.monotonic() < deadline:
        waiting = [t for t in waiting if pubs[t].get_subscription_count() == 0]
        time.sleep(0.05)
    if waiting:
        raise TimeoutError(f"no subscriber on {', '.join(waiting)} after {timeout_s:g} s")
