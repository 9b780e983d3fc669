"""`noise-monitor play BAG`: publish a bag into live ROS 2 topics with its original timing."""
from __future__ import annotations

import argparse
import json
import signal
import threading

from .play import play


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", help="rosbag2 folder (MCAP or sqlite3) or a bare .mcap / .db3 file")
    parser.add_argument("--rate", type=float, default=1.0, help="playback speed factor (2 = twice as fast)")
    parser.add_argument("--loop", action="store_true", help="start over at the end (until Ctrl-C)")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC", help="publish only these topics (default: all)")
    parser.add_argument("--wait-subscribers", type=float, default=0.0, metavar="SECONDS",
                        help="first wait up to SECONDS for a subscriber on the image and metadata topics")
    parser.add_argument("--json", metavar="PATH", help="write playback statistics (messages per topic, timing)")
    parser.add_argument("--clock", type=float, nargs="?", const=40.0, default=None, metavar="HZ",
                        help="also publish the bag's time on /clock (default 40 Hz), for nodes with use_sim_time")


def run(args: argparse.Namespace) -> int:
    if args.clock is not None and not args.clock > 0:  # 0 published no /clock without a word (until 2026-12-04)
        raise ValueError(f"--clock must be > 0 Hz, got {args.clock:g} (leave it out for no /clock)")
    stop = threading.Event()  # Ctrl-C / SIGTERM end the playback; its statistics are still printed and written
    handlers = {sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        stats = play(args.bag, rate=args.rate, loop=args.loop, topics=args.topics,
                     wait_subscribers_s=args.wait_subscribers, should_stop=stop.is_set, clock_hz=args.clock or 0.0)
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
    for topic, mtype in stats.unsupported.items():
        print(f"not published (no rclpy type support installed): {topic} [{mtype}]")
    print(f"published {sum(stats.published.values())} messages on {len(stats.published)} topics in "
          f"{stats.wall_time_s:.1f} s ({stats.loops} loop(s), bag {stats.bag_duration_s:.1f} s at rate {args.rate:g}, "
          f"max lag {stats.max_lag_s * 1e3:.1f} ms){'; stopped by a signal' if stop.is_set() else ''}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(stats.as_dict(), fh, indent=2)
    return 0
