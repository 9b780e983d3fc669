"""`noise-monitor play BAG`: publish a bag into live ROS 2 topics with its original timing."""
from __future__ import annotations

import argparse
import json

from .play import play


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", help="rosbag2 folder (MCAP or sqlite3) or a bare .mcap / .db3 file")
    parser.add_argument("--rate", type=float, default=1.0, help="playback speed factor (2 = twice as fast)")
    parser.add_argument("--loop", action="store_true", help="start over at the end (until Ctrl-C)")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC", help="publish only these topics (default: all)")
    parser.add_argument("--wait-subscribers", type=float, default=0.0, metavar="SECONDS",
                        help="first wait up to SECONDS for a subscriber on the image and metadata topics")
    parser.add_argument("--json", metavar="PATH", help="write playback statistics (messages per topic, timing)")


def run(args: argparse.Namespace) -> int:
    stats = play(args.bag, rate=args.rate, loop=args.loop, topics=args.topics,
                 wait_subscribers_s=args.wait_subscribers)
    for topic, mtype in stats.unsupported.items():
        print(f"not published (no rclpy type support installed): {topic} [{mtype}]")
    print(f"published {sum(stats.published.values())} messages on {len(stats.published)} topics in "
          f"{stats.wall_time_s:.1f} s ({stats.loops} loop(s), bag {stats.bag_duration_s:.1f} s at rate {args.rate:g}, "
          f"max lag {stats.max_lag_s * 1e3:.1f} ms)")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(stats.as_dict(), fh, indent=2)
    return 0
