"""Benchmark of the Foxglove live view (`--foxglove PORT`): what serving costs the replay and the node.

Replays a bundled bag and a simulated VGA campaign (640x480 @ 10 Hz) three times each: without a live
view, with a live view and no client, and with a WebSocket client subscribed to every topic (outputs,
debug image, the evaluated image) that receives everything. Also times what the node adds per frame
when a client watches its input: rclpy's serialize_message of a 1280x1024 mono8 Image plus the log call.

Usage: .venv/bin/python bench/bench_live_view.py [--threads N] [--vga-frames 60]
Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import asyncio
import json
import tempfile
import threading
import time
from pathlib import Path

from msg_adapters.live_view import LiveView
from noise_monitor.bag.replay import live_topics, replay
from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.estimator import load
from noise_monitor.monitor.runtime import set_inference_threads
from noise_monitor.paths import share_dir


class Watcher:
    """A WebSocket client in its own thread that subscribes to every channel and counts what arrives."""

    def __init__(self, url: str) -> None:
        self.url, self.messages, self.bytes = url, 0, 0
        self.stop = threading.Event()
        self.ready = threading.Event()
        self.thread = threading.Thread(target=lambda: asyncio.run(self._run()), daemon=True)
        self.thread.start()

    async def _run(self) -> None:
        import websockets

        async with websockets.connect(self.url, subprotocols=["foxglove.sdk.v1"], max_size=None) as ws:
            channels: list[int] = []
            while not channels:
                msg = json.loads(await ws.recv())
                if msg["op"] == "advertise":
                    channels = [c["id"] for c in msg["channels"]]
            await ws.send(json.dumps({"op": "subscribe",
                                      "subscriptions": [{"id": i, "channelId": c} for i, c in enumerate(channels)]}))
            self.ready.set()
            while not self.stop.is_set():
                try:
                    data = await asyncio.wait_for(ws.recv(), 0.5)
                except TimeoutError:
                    continue
                if isinstance(data, bytes) and data[0] == 1:
                    self.messages += 1
                    self.bytes += len(data)

    def close(self) -> None:
        time.sleep(0.5)  # let the last messages arrive
        self.stop.set()
        self.thread.join(10)


def run(bag: Path, profile: str, mode: str, threads: int) -> dict:
    est = load("full_meta", device="cpu")
    live = LiveView(live_topics(), 0) if mode != "off" else None
    watcher = Watcher(live.url) if live is not None and mode == "client" else None
    if watcher is not None:
        assert live is not None and watcher.ready.wait(10) and live.wait_for_subscriber(10)
    try:
        s = replay(bag, profile, None, estimator=est, threads=threads, progress=False, live=live)
    finally:
        if watcher is not None:
            watcher.close()
        if live is not None:
            live.close()
    return {"bag": bag.name, "mode": mode, "frames": s["frames_total"], "frames_per_s": s["frames_per_s"],
            "received": watcher.messages if watcher else 0, "mb": watcher.bytes / 1e6 if watcher else 0.0}


def node_mirror_cost(repeats: int = 200) -> float:
    """ms per 1280x1024 mono8 frame: serialize_message + LiveView.log_cdr with a subscribed client."""
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import Image

    msg = Image(height=1024, width=1280, encoding="mono8", step=1280, data=bytes(1280 * 1024))
    with LiveView({"/camera/image": "sensor_msgs/msg/Image"}, 0) as live:
        watcher = Watcher(live.url)
        assert watcher.ready.wait(10) and live.wait_for_subscriber(10)
        t = time.perf_counter()
        for i in range(repeats):
            live.log_cdr("/camera/image", serialize_message(msg), i)
        ms = 1e3 * (time.perf_counter() - t) / repeats
        watcher.close()
    return ms


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=0, help="torch threads (0 = all cores but one, as the node)")
    ap.add_argument("--vga-frames", type=int, default=60)
    args = ap.parse_args()
    set_inference_threads(args.threads)
    with tempfile.TemporaryDirectory() as tmp:
        vga = simulate_bag(Path(tmp) / "vga.mcap", "icx285", "gain_sweep", frames=args.vga_frames, width=640,
                           height=480, fps=10.0, hold_s=1.0, seed=1)
        for bag, prof in ((share_dir() / "bags" / "ev76c661_field.mcap", "ev76c661"), (vga, "icx285")):
            for mode in ("off", "server", "client"):
                r = run(bag, prof, mode, args.threads)
                extra = f", client received {r['received']} messages ({r['mb']:.1f} MB)" if mode == "client" else ""
                print(f"{r['bag']:20s} live view {mode:6s}: {r['frames']:4d} frames, {r['frames_per_s']:6.1f} "
                      f"frames/s{extra}", flush=True)
    print(f"node: mirroring a 1280x1024 mono8 input to a watching client costs {node_mirror_cost():.2f} ms/frame")


if __name__ == "__main__":
    main()
