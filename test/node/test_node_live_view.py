"""`--foxglove PORT` on the node: a WebSocket client sees the node's topics with the node's numbers."""
from __future__ import annotations

import asyncio
import importlib.util
import json
import re
import threading
import time
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import websockets

from noise_monitor import dashboards
from noise_monitor.cli import main

rclpy = pytest.importorskip("rclpy")

from msg_adapters.live_view import LiveView  # noqa: E402
from msg_adapters.outputs import NUMBER_TYPE  # noqa: E402


def _load(name: str, path: Path) -> Any:
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


foxglove_ws = _load("foxglove_ws", Path(__file__).parents[1] / "msg_adapters" / "foxglove_ws.py")
Rig = _load("node_rig", Path(__file__).with_name("test_node.py")).Rig  # rig_factory builds this module's Rig


@pytest.fixture(scope="module")
def estimator() -> Any:
    from noise_monitor.estimator import load

    return load("full_meta", device="cpu")


def test_live_view_mirrors_the_nodes_topics(rig_factory):
    rig = rig_factory("live", debug_image_rate_hz=100.0, diagnostics_rate_hz=20.0)
    node = rig.node
    ns = node.get_fully_qualified_name()
    topics = node.live_topics()
    assert topics["/live/image_raw"] == "sensor_msgs/msg/Image" and topics[f"{ns}/xi"] == NUMBER_TYPE
    assert topics["/diagnostics"] == "diagnostic_msgs/msg/DiagnosticArray"
    assert topics[f"{ns}/debug_image"] == "sensor_msgs/msg/Image"
    # the dashboards generated for this node's namespace read only topics it publishes
    layout = ET.fromstring(dashboards.plotjuggler_layout(ns))
    assert {t.get("name") for t in layout.iter("topic")} <= set(topics)
    if importlib.util.find_spec("foxglove") is not None:
        fox = json.dumps(dashboards.foxglove_layout(ns, "live"))
        used = set(re.findall(r'"(/[\w/]+)\.', fox)) - {dashboards.BAND_TOPIC}
        assert used and used <= set(topics)
    wanted = [f"{ns}/xi", f"{ns}/sigma_rn", "/diagnostics", f"{ns}/debug_image", "/live/image_raw"]
    done, got = threading.Event(), []

    async def session(url: str) -> None:
        async with websockets.connect(url, subprotocols=[foxglove_ws.SUBPROTOCOL], max_size=None) as ws:
            client = foxglove_ws.Client(ws)
            await client.handshake(len(topics))
            await client.subscribe(wanted)
            got.extend(await client.receive(until=done))

    with LiveView(topics, 0) as live:
        node.live = live
        thread = threading.Thread(target=lambda: asyncio.run(session(live.url)), daemon=True)
        thread.start()
        end = time.monotonic() + 10
        while not all(live.has_subscribers(t) for t in wanted) and time.monotonic() < end:
            time.sleep(0.01)
        reports = [rig.step(i) for i in range(3)]
        rig.spin_until(lambda: False, 0.5)  # a few /diagnostics period summaries (20 Hz) reach the client
        done.set()
        thread.join(30)
        node.live = None
    stamps = [1_000 * 10**9 + i * 33_333_333 for i in range(3)]
    for key in ("xi", "sigma_rn"):
        served = {s: foxglove_ws.number(m) for t, s, m in got if t == f"{ns}/{key}"}
        assert sorted(served) == stamps
        for s, (report, _) in zip(stamps, reports):
            assert served[s] == pytest.approx(float(report.values[key]), abs=1e-6)
    diag = [m for t, _, m in got if t == "/diagnostics"]
    assert any(st.name == "noise_monitor: live" for m in diag for st in m.status)
    images = {s: m for t, s, m in got if t == "/live/image_raw"}
    assert sorted(images) == stamps and images[stamps[0]].encoding == "mono8"
    assert images[stamps[0]].width == images[stamps[0]].height == 256
    debug = {s: m for t, s, m in got if t == f"{ns}/debug_image"}
    assert stamps[0] in debug and debug[stamps[0]].encoding == "rgb8"
    first = np.frombuffer(images[stamps[0]].data.tobytes(), np.uint8).reshape(256, 256)
    rgb = np.frombuffer(debug[stamps[0]].data.tobytes(), np.uint8).reshape(256, 256, 3)
    assert np.mean(rgb[..., 0] == first) > 0.9  # the debug view is that frame (outlines aside)


def test_cli_rejects_a_bad_port(capsys):
    assert main(["node", "--profile", "icx285", "--foxglove", "-1"]) == 2
    assert "--foxglove port must be 0..65535, got -1" in capsys.readouterr().err
