"""A minimal Foxglove WebSocket client for the live-view tests (the protocol as the Foxglove app speaks it)."""
from __future__ import annotations

import asyncio
import json
import struct
import threading
from typing import Any

from msg_adapters.diagnostics import jazzy_typestore

TS = jazzy_typestore()


def number(msg: Any) -> float:
    """The value of a per-frame number message (whatever msg_adapters.outputs.NUMBER_TYPE is)."""
    from noise_monitor.dashboards import number_field

    for name in number_field():
        msg = getattr(msg, name)
    return float(msg)
SUBPROTOCOL = "foxglove.sdk.v1"  # the sdk's WebSocket subprotocol (foxglove_bridge: foxglove.websocket.v1)
MESSAGE_DATA, TIME = 0x01, 0x02  # binary opcodes server -> client


class Client:
    """A minimal Foxglove WebSocket client: handshake, subscribe by topic, decode CDR by schema name."""

    def __init__(self, ws: Any) -> None:
        self.ws = ws
        self.channels: dict[str, dict] = {}
        self.by_sub: dict[int, str] = {}
        self.info: dict = {}

    async def handshake(self, n_topics: int) -> None:
        while len(self.channels) < n_topics:
            msg = json.loads(await asyncio.wait_for(self.ws.recv(), 5))
            if msg["op"] == "serverInfo":
                self.info = msg
            elif msg["op"] == "advertise":
                self.channels.update({c["topic"]: c for c in msg["channels"]})

    async def subscribe(self, topics: list[str]) -> None:
        subs = [{"id": i + 1, "channelId": self.channels[t]["id"]} for i, t in enumerate(topics)]
        self.by_sub = {s["id"]: t for s, t in zip(subs, topics)}
        await self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    async def receive(self, until: threading.Event | None = None, timeout_s: float = 60.0
                      ) -> list[tuple[str, int, Any]]:
        """(topic, log time, decoded message) until ``until`` is set and nothing arrives for 0.5 s."""
        out: list[tuple[str, int, Any]] = []
        loop = asyncio.get_running_loop()
        end = loop.time() + timeout_s
        while loop.time() < end:
            try:
                data = await asyncio.wait_for(self.ws.recv(), 0.5)
            except TimeoutError:
                if until is None or until.is_set():
                    break
                continue
            if isinstance(data, bytes) and data[0] == MESSAGE_DATA:
                sub, log_time = struct.unpack_from("<IQ", data, 1)
                topic = self.by_sub[sub]
                out.append((topic, log_time, TS.deserialize_cdr(data[13:], self.channels[topic]["schemaName"])))
        return out
