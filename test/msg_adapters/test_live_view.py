"""Live view: the monitor's topics over the Foxglove WebSocket protocol, read by a real WebSocket client."""
from __future__ import annotations

import asyncio
import importlib.util
import json
import re
import threading
from pathlib import Path

import numpy as np
import pytest
import torch
import websockets

from msg_adapters.diagnostics import jazzy_typestore
from msg_adapters.live_view import LiveView
from msg_adapters.outputs import debug_image_topic, rosbags_image
from noise_monitor.bag.replay import INPUT_IMAGE, live_topics, replay
from noise_monitor.bag.results import FrameTable
from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.cli import main
from noise_monitor.monitor import MonitorConfig

_spec = importlib.util.spec_from_file_location("foxglove_ws", Path(__file__).with_name("foxglove_ws.py"))
assert _spec is not None and _spec.loader is not None
foxglove_ws = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(foxglove_ws)
SUBPROTOCOL, Client = foxglove_ws.SUBPROTOCOL, foxglove_ws.Client

torch.set_num_threads(1)
TS = jazzy_typestore()


async def subscribed(view: LiveView, topics) -> None:
    """Wait until every one of ``topics`` has the client's subscription: ``wait_for_subscriber`` returns at the first
    channel's, and the server registers the others on its own (a message logged before was sometimes never sent)."""
    assert await asyncio.to_thread(view.wait_for_subscriber, 5.0)
    for _ in range(500):
        if all(view.has_subscribers(t) for t in topics):
            return
        await asyncio.sleep(0.01)
    raise AssertionError(f"not every topic subscribed within 5 s: {[t for t in topics if not view.has_subscribers(t)]}")


def test_handshake_advertises_ros2_schemas_and_serves_decodable_messages():
    float32 = TS.types["std_msgs/msg/Float32"]
    image = np.arange(12, dtype=np.uint16).reshape(3, 4) * 1000
    topics = {"/noise_monitor/xi": "std_msgs/msg/Float32", "/cam/image": "sensor_msgs/msg/Image"}

    async def session(view: LiveView) -> list:
        async with websockets.connect(view.url, subprotocols=[SUBPROTOCOL]) as ws:
            assert ws.subprotocol == SUBPROTOCOL
            client = Client(ws)
            await client.handshake(len(topics))
            assert client.info["name"] == "noise_monitor" and "time" in client.info["capabilities"]
            xi = client.channels["/noise_monitor/xi"]
            assert (xi["encoding"], xi["schemaEncoding"], xi["schemaName"]) == ("cdr", "ros2msg",
                                                                               "std_msgs/msg/Float32")
            assert xi["schema"] == "float32 data\n"
            await client.subscribe(list(topics))
            await subscribed(view, topics)
            view.log({"/noise_monitor/xi": float32(data=-1.25)}, 1_700_000_000_123_456_789)
            view.log_image("/cam/image", image, 1_700_000_000_223_456_789, frame_id="cam")
            return await client.receive()

    with LiveView(topics, 0) as view:
        assert view.port > 0
        got = asyncio.run(session(view))
    assert [(t, s) for t, s, _ in got] == [("/noise_monitor/xi", 1_700_000_000_123_456_789),
                                           ("/cam/image", 1_700_000_000_223_456_789)]
    assert got[0][2].data == -1.25
    img = got[1][2]
    assert (img.encoding, img.height, img.width, img.header.frame_id) == ("mono16", 3, 4, "cam")
    assert (img.header.stamp.sec, img.header.stamp.nanosec) == (1_700_000_000, 223_456_789)
    np.testing.assert_array_equal(np.frombuffer(img.data.tobytes(), "<u2").reshape(3, 4), image)


def test_bad_port_and_types_are_refused():
    with pytest.raises(ValueError, match="0..65535"):
        LiveView({}, 70000)
    with pytest.raises(ValueError, match="unknown message type foo/msg/Bar"):
        LiveView({"/x": "foo/msg/Bar"}, 0)
    with LiveView({}, 0) as taken:
        with pytest.raises(OSError, match=f"cannot serve Foxglove on 127.0.0.1:{taken.port}"):
            LiveView({}, taken.port)
    with pytest.raises(ValueError, match="uint8/uint16"):
        rosbags_image(np.zeros((2, 2), np.float32), 0)


@pytest.fixture(scope="module")
def estimator():
    from noise_monitor.estimator import load

    return load("full_meta", device="cpu")


@pytest.fixture(scope="module")
def bag(tmp_path_factory, estimator) -> Path:
    ps = estimator.patch_size
    return simulate_bag(tmp_path_factory.mktemp("live") / "noise.mcap", "ev76c661", "image_noise", frames=12,
                        width=3 * ps, height=2 * ps, seed=4, hold_s=0)


def test_replay_serves_every_frame_with_the_replays_numbers(bag, estimator, tmp_path):
    """A client subscribed before the replay starts gets every frame's numbers, stamped with the frame."""
    config = MonitorConfig(patches_per_frame=4)
    table = FrameTable()
    topics = live_topics()
    wanted = ["/noise_monitor/xi", "/noise_monitor/sigma_rn", "/diagnostics", debug_image_topic(),
              f"/noise_monitor/{INPUT_IMAGE}"]
    done = threading.Event()

    def run(view: LiveView) -> None:
        try:
            replay(bag, "ev76c661", tmp_path / "out", estimator=estimator, config=config, progress=False,
                   plot=False, table=table, live=view)
        finally:
            done.set()

    async def session(view: LiveView) -> list:
        async with websockets.connect(view.url, subprotocols=[SUBPROTOCOL], max_size=None) as ws:
            client = Client(ws)
            await client.handshake(len(topics))
            assert set(client.channels) == set(topics)
            await client.subscribe(wanted)
            await subscribed(view, wanted)
            threading.Thread(target=run, args=(view,), daemon=True).start()
            return await client.receive(until=done)

    with LiveView(topics, 0) as view:
        got = asyncio.run(session(view))
    assert done.is_set() and len(table) == 12 and table.column("processed").all()
    stamps = [int(s) for s in table.column("stamp_ns")]
    for key in ("xi", "sigma_rn"):
        served = {s: foxglove_ws.number(m) for t, s, m in got if t == f"/noise_monitor/{key}"}
        assert sorted(served) == stamps  # every frame, at its own stamp
        np.testing.assert_array_equal(np.float32([served[s] for s in stamps]), np.float32(table.numbers(key)))
    diag = [m for t, _, m in got if t == "/diagnostics"]
    assert diag and diag[0].status[0].name.startswith("noise_monitor: ")
    inputs = {s: m for t, s, m in got if t == f"/noise_monitor/{INPUT_IMAGE}"}
    assert sorted(inputs) == stamps and inputs[stamps[0]].encoding == "mono8"
    debug = [(s, m) for t, s, m in got if t == debug_image_topic()]
    # debug_image_rate_hz 1 in bag time: the 12 frames at 5 Hz span 2.2 s -> frames 0, 5, 10
    assert [s for s, _ in debug] == stamps[::5] and debug[0][1].encoding == "rgb8"


def test_cli_rejects_bad_live_options(bag, capsys):
    assert main(["replay", str(bag), "--profile", "ev76c661", "--foxglove", "70000"]) == 2
    assert "port must be 0..65535" in capsys.readouterr().err
    assert main(["replay", str(bag), "--profile", "ev76c661", "--foxglove-wait", "3"]) == 2
    assert "--foxglove-wait needs --foxglove PORT" in capsys.readouterr().err
    assert main(["replay", str(bag), "--profile", "ev76c661", "--rate", "0"]) == 2
    assert "--rate must be > 0" in capsys.readouterr().err


def test_cli_serves_and_paces(bag, tmp_path, capsys):
    """`replay --foxglove 0 --rate 4`: the URL is printed, and 12 frames at 5 Hz take at least 11 / 5 / 4 s."""
    assert main(["replay", str(bag), "--profile", "ev76c661", "--out", str(tmp_path / "o"), "--no-plot",
                 "--foxglove", "0", "--rate", "4", "--json", str(tmp_path / "s.json")]) == 0
    assert re.search(r"foxglove: serving ws://127\.0\.0\.1:\d+ ", capsys.readouterr().out)
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["frames_processed"] == 12 and summary["wall_time_s"] >= 11 / 5 / 4
