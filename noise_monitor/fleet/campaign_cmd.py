"""`noise-monitor campaign BAG_OR_DIR... --out DIR`: replay a field campaign's bags on Ray or a local pool."""
from __future__ import annotations

import argparse
import os
import signal
import sys
from typing import Any

from .campaign import run_campaign

HELP = ("Replay many bags through the monitor (Ray tasks or a local process pool), resumable; "
        "per-frame Parquet, campaign.json and an HTML report with cameras ranked by health.")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("inputs", nargs="+", metavar="BAG_OR_DIR",
                        help="bags (rosbag2 folders, .mcap, .db3, ROS 1 .bag) or folders searched recursively for bags "
                             "(the --out folder left out)")
    parser.add_argument("--out", required=True, metavar="DIR",
                        help="output folder: manifest.jsonl, campaign.json, frames.parquet, report.html, bags/")
    who = parser.add_mutually_exclusive_group()
    who.add_argument("--profile", help="one camera profile (bundled name or YAML) for every bag")
    who.add_argument("--profiles", metavar="MAP.yaml",
                     help="camera profile per hardware_id: 'cameras: {hardware_id or glob: profile}', optional 'default'")
    run = parser.add_mutually_exclusive_group()
    run.add_argument("--ray", nargs="?", const="local", metavar="ADDRESS",
                     help="run on Ray: a local Ray (default when Ray is installed), or join the cluster at "
                          "ADDRESS (HOST:PORT, ray://HOST:PORT or auto)")
    run.add_argument("--pool", action="store_true", help="run on a local process pool without Ray")
    parser.add_argument("--workers", type=int, default=max(1, os.cpu_count() or 1),
                        help="worker processes / CPUs of a local Ray (default: all cores)")
    parser.add_argument("--timeout", type=float, default=600.0, metavar="SECONDS",
                        help="per-bag time limit; a bag past it is reported and its worker killed (default 600)")
    parser.add_argument("--worker-memory", type=float, default=4096.0, metavar="MB",
                        help="resident memory limit per worker; a bag past it is reported (default 4096; 0 = none)")
    parser.add_argument("--model", help="estimator variant (default: the params file's, full_meta)")
    parser.add_argument("--weights", metavar="PT", help="estimator checkpoint")
    parser.add_argument("--device", help="cpu, cuda or auto (default: the params file's, cpu)")
    parser.add_argument("--params", metavar="YAML", help="node parameter file (default config/node.yaml)")
    parser.add_argument("--effect-plugin", action="append", default=[], metavar="FILE",
                        help="load noise effects from FILE in every worker (repeatable)")
    parser.add_argument("--bag-outputs", action="store_true",
                        help="also write replay's MCAP, CSV and PNG per bag (bags/<sha>/)")
    parser.add_argument("--image-topic", help="the camera to evaluate in bags that hold several (e.g. "
                                             "/left/image_raw; its metadata topic is then detected in its namespace)")
    parser.add_argument("--metadata-topic", help="override the detected metadata topic")
    parser.add_argument("--no-report", action="store_true", help="skip the HTML report")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def _print(c: dict[str, Any]) -> None:
    t, run = c["totals"], c["run"]
    print(f"\n{t['bags_found']} bags: {t['bags_evaluated']} evaluated, {t['bags_failed']} failed, "
          f"{t['bags_duplicate']} duplicate(s), {t['bags_not_run']} not run; {t['inputs_rejected']} input(s) rejected")
    print(f"{t['frames_total']} frames ({t['frames_processed']} processed, {t['frames_skipped']} skipped), "
          f"{t['alarm_episodes']} alarm episode(s), {t['cameras']} camera(s)")
    print(f"backend {run['backend']}: {run['bags_run']} bags run in {run['wall_time_s']} s "
          f"({run['frames_per_s']} frames/s), {run['bags_resumed']} finished in an earlier run")
    if run.get("backend_note"):
        print(f"  note: {run['backend_note']}")
    for p in (*c["failed"], *c["duplicates"], *c["problems"]):
        print(f"  not evaluated: {p['path']}: {p['reason']}")
    print("\ncameras by health (worst first):")
    for cam in c["cameras"]:
        print(f"  #{cam['rank']} {cam['hardware_id']}: health {cam['health']:.2f}, {cam['bags']} bags, "
              f"mean xi {cam['mean']['xi'] if cam['mean']['xi'] is not None else 'n/a'} DN"
              + (f"; {'; '.join(cam['findings'])}" if cam["findings"] else ""))
    for cam in c.get("cameras_not_evaluated", []):
        print(f"  {cam['hardware_id']}: not evaluated, {cam['bags_failed']} bag(s) failed: {cam['reason']}")
    for kind, path in c["outputs"].items():
        print(f"  {kind:8s} {path}")


def _stop(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt  # SIGTERM (systemd, Kubernetes) stops a campaign as Ctrl-C does: resumable, recorded


def run(args: argparse.Namespace) -> int:
    signal.signal(signal.SIGTERM, _stop)
    backend = "pool" if args.pool else ("ray" if args.ray else "auto")
    address = None if args.ray in (None, "local") else args.ray
    try:
        campaign = run_campaign(args.inputs, args.out, profile=args.profile, profile_map=args.profiles,
                                model=args.model, weights=args.weights, device=args.device, params=args.params,
                                plugins=args.effect_plugin, backend=backend, ray_address=address,
                                workers=args.workers, timeout_s=args.timeout, memory_limit_mb=args.worker_memory,
                                bag_outputs=args.bag_outputs, image_topic=args.image_topic,
                                metadata_topic=args.metadata_topic, progress=not args.no_progress,
                                report=not args.no_report)
    except KeyboardInterrupt as exc:
        print(f"noise-monitor campaign: {exc}" if str(exc) else "noise-monitor campaign: interrupted", file=sys.stderr)
        return 130
    _print(campaign)
    return 0
