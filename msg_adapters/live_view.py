"""Live view without a ROS install: the monitor's topics over the Foxglove WebSocket protocol (foxglove-sdk).

Messages are served as ROS 2 does it (``cdr`` payloads with ``ros2msg`` schemas generated from the
rosbags Jazzy typestore), so the Foxglove app decodes them exactly like the node's topics through
foxglove_bridge or the replay's MCAP, and the same layouts (``config/foxglove_layout.json``) apply.
Channels are advertised up front (the caller names the topics and types it will log), messages are
logged with their ROS stamp as log time, and the server's clock follows that time (``Time`` capability).
No ROS import: the node hands rclpy-serialised bytes, the replay rosbags messages.
"""
from __future__ import annotations

import threading
from collections.abc import Mapping
from typing import Any

import foxglove
from foxglove.websocket import Capability, ChannelView, Client, ServerListener

from .diagnostics import jazzy_typestore
from .outputs import rosbags_image


class _SubscriptionListener(ServerListener):
    """Sets an event when a client subscribes to any channel (the replay waits for it)."""

    def __init__(self) -> None:
        super().__init__()
        self.subscribed = threading.Event()

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        self.subscribed.set()


class LiveView:
    """A Foxglove WebSocket server for ROS 2 messages on a fixed set of topics.

    ``topics``: topic -> ROS 2 type name (``std_msgs/msg/Float32``); ``port`` 0 picks a free port
    (:attr:`port` tells which). Use as a context manager or call :meth:`close`.
    """

    def __init__(self, topics: Mapping[str, str], port: int, host: str = "127.0.0.1",
                 name: str = "noise_monitor", typestore: Any = None) -> None:
        if not 0 <= int(port) <= 65535:
            raise ValueError(f"--foxglove port must be 0..65535, got {port}")
        self.typestore = typestore or jazzy_typestore()
        self._context = foxglove.Context()
        self._channels: dict[str, foxglove.Channel] = {}
        self.types: dict[str, str] = {}
        for topic, type_name in topics.items():
            self.add_topic(topic, type_name)
        self._listener = _SubscriptionListener()
        try:
            self._server = foxglove.start_server(name=name, host=host, port=int(port), context=self._context,
                                                 capabilities=[Capability.Time], server_listener=self._listener)
        except RuntimeError as exc:  # e.g. the port is taken
            raise OSError(f"cannot serve Foxglove on {host}:{port}: {exc}") from exc
        self.host = host

    def add_topic(self, topic: str, type_name: str) -> None:
        """Advertise ``topic`` with the ROS 2 message definition of ``type_name``."""
        if topic in self._channels:
            if self.types[topic] != type_name:
                raise ValueError(f"live view topic {topic} is {self.types[topic]}, not {type_name}")
            return
        if type_name not in self.typestore.types:
            raise ValueError(f"live view topic {topic}: unknown message type {type_name}")
        msgdef, _ = self.typestore.generate_msgdef(type_name, ros_version=2)
        schema = foxglove.Schema(name=type_name, encoding="ros2msg", data=msgdef.encode())
        self._channels[topic] = foxglove.Channel(topic, schema=schema, message_encoding="cdr", context=self._context)
        self.types[topic] = type_name

    @property
    def port(self) -> int:
        """The TCP port the server listens on."""
        return int(self._server.port)

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def wait_for_subscriber(self, timeout_s: float) -> bool:
        """Block until a client subscribed to a channel (True) or ``timeout_s`` passed (False)."""
        return self._listener.subscribed.wait(timeout_s)

    def has_subscribers(self, topic: str) -> bool:
        """True when a client subscribed to ``topic`` (callers skip serialising otherwise)."""
        return self._channels[topic].has_sinks()

    def log_cdr(self, topic: str, data: bytes, stamp_ns: int) -> None:
        """Log an already CDR-serialised message (e.g. rclpy's ``serialize_message``) at ``stamp_ns``."""
        self._channels[topic].log(bytes(data), log_time=int(stamp_ns))

    def log(self, messages: Mapping[str, Any], stamp_ns: int) -> None:
        """Log rosbags messages of this view's typestore ``{topic: msg}`` at ``stamp_ns`` (serialised only for
        topics a client subscribed to)."""
        for topic, msg in messages.items():
            if self.has_subscribers(topic):
                self.log_cdr(topic, self.typestore.serialize_cdr(msg, msg.__msgtype__), stamp_ns)

    def log_image(self, topic: str, image: Any, stamp_ns: int, frame_id: str = "") -> None:
        """Log a sensor_msgs/Image of an (H, W) uint8/uint16 gray or (H, W, 3) uint8 RGB array."""
        if self.has_subscribers(topic):
            self.log({topic: rosbags_image(image, stamp_ns, frame_id, self.typestore)}, stamp_ns)

    def broadcast_time(self, stamp_ns: int) -> None:
        """Move the clients' clock to ``stamp_ns`` (bag time in a replay)."""
        self._server.broadcast_time(int(stamp_ns))

    def close(self) -> None:
        self._server.stop()

    def __enter__(self) -> LiveView:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

