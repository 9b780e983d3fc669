"""`noise-monitor replay BAG`: run the monitor over a bag faster than real time; MCAP + CSV + PNG + JSON."""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from noise_monitor.monitor.black_level import STATED_BY

from .input_options import add_input_arguments, topic_overrides
from .replay import live_topics, replay
from .staging import input_files, refuse_overwriting_inputs, write_text_atomic


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", help="rosbag2 folder (MCAP or sqlite3), a bare .mcap / .db3 file or a ROS 1 .bag")
    parser.add_argument("--profile", help="camera profile YAML or bundled name; optional when the bag's metadata "
                                          "carries every field")
    parser.add_argument("--out", metavar="DIR", help="output folder (default out/<bag name>): replay.mcap, "
                                                     "replay.csv, replay.png, summary.json")
    parser.add_argument("--json", metavar="PATH", help="also write the summary JSON here")
    parser.add_argument("--model", help="estimator variant (default: the params file's, full_meta)")
    parser.add_argument("--weights", metavar="PT", help="estimator checkpoint (default: the params file's, bundled)")
    parser.add_argument("--device", help="cpu, cuda or auto (default: the params file's, cpu)")
    parser.add_argument("--params", metavar="YAML", help="node parameter file with the monitor settings "
                                                         "(default config/node.yaml)")
    parser.add_argument("--camera-name", help="diagnostic status name 'noise_monitor: <name>' (default: params file)")
    add_input_arguments(parser)
    parser.add_argument("--threads", type=int, help="CPU threads for inference (default: the params file's; "
                                                    "0 = all cores but one)")
    parser.add_argument("--no-plot", action="store_true", help="skip the PNG plot")
    parser.add_argument("--foxglove", type=int, metavar="PORT",
                        help="serve the outputs, the debug image and the evaluated image over the Foxglove WebSocket "
                             "protocol on 127.0.0.1:PORT while replaying (0 = a free port; needs foxglove-sdk)")
    parser.add_argument("--foxglove-host", default="127.0.0.1", metavar="HOST",
                        help="address to serve on (0.0.0.0 for other machines; default 127.0.0.1)")
    parser.add_argument("--foxglove-wait", type=float, default=0.0, metavar="S",
                        help="with --foxglove: wait up to S seconds for a client to subscribe before replaying")
    parser.add_argument("--rate", type=float, default=None,
                        help="pace the replay to RATE x the recording's speed (1 = real time; default: as fast as "
                             "processed)")


def _fmt(v: Any) -> str:
    return "   n/a" if v is None else f"{v:6.2f}"


def print_summary(s: dict[str, Any]) -> None:
    """Per-source table and alarm episodes on stdout."""
    print(f"\n{s['bag']}: {s['frames_total']} frames, {s['frames_processed']} processed, "
          f"{s['frames_skipped']} skipped; estimator {s['estimator']}" + (f" ({s['weights']})" if s.get('weights') else ""))
    for reason, n in s["skip_reasons"].items():
        print(f"  skipped {n:4d} x {reason}")
    if s.get("frames_beyond_index"):
        print(f"  note: the bag's index (metadata.yaml) lists {s['frames_total'] - s['frames_beyond_index']} images; "
              f"all {s['frames_total']} in its storage were replayed")
    if s.get("frames_lost"):
        print(f"  lost    {s['frames_lost']:4d} frames before the recording (gaps in the image stamps)")
    if s.get("temporal_noise_changes"):
        print(f"  noise changed {s['temporal_noise_changes']} time(s) inside a still hold (its temporal measurement "
              "restarted there)")
    if s.get("temporal_light_steps"):
        print(f"  light stepped {s['temporal_light_steps']} time(s) inside a still hold (its temporal measurement "
              "restarted there)")
    if s.get("metadata_overrides"):
        print("  note: the bag's metadata set camera constants, which win over the profile's: " + ", ".join(
            f"{k} {v['bag']} (profile {v['profile']})" for k, v in s["metadata_overrides"].items()))
    if s.get("params_ignored"):
        print(f"  note: parameter(s) {', '.join(s['params_ignored'])} of the params file's every-node section are not "
              "the monitor's (other nodes'; a typo?)")
    black = s.get("black_level_contradicted")
    if black:
        print(f"  black level: {black['frames']} frame(s) read pixels far below the {black['stated_dn']:g} DN stated "
              f"by {STATED_BY[black['stated_by']]}: the camera's is at most {black['camera_at_most_dn']:g} DN "
              "(state it: profile or node "
              "parameter black_level_dn; a driver's value: its conversion, profile driver_black_level_dn)")
    print(f"\n  {'source':12s} {'mean':>6s} {'p5':>6s} {'p95':>6s}   [DN]")
    for key, label in (("sigma_pn", "PN"), ("sigma_dcsn", "DCSN"), ("sigma_rn", "RN"), ("sigma_total", "total"),
                       ("sigma_model", "model"), ("sigma_image", "image"), ("sigma_temporal", "frame diffs"),
                       ("sigma_temporal_model", "  its model"), ("xi", "xi")):
        st = s[key]
        print(f"  {label:12s} {_fmt(st['mean'])} {_fmt(st['p5'])} {_fmt(st['p95'])}")
    drove = s["xi_measurement"]
    print(f"  xi measured from the single image on {drove['image']} frame(s), from a still view's frame differences "
          f"on {drove['temporal']}" + (f", as the image's bound on {drove['bound']}" if drove["bound"] else ""))
    print(f"\n  alarm episodes: {len(s['alarms'])}")
    for ep in s["alarms"]:
        tail = " (still active at the end)" if ep["active_at_end"] else ""
        print(f"  - {ep['start_s']:7.2f} s .. {ep['end_s']:7.2f} s ({ep['frames']} frames), xi {ep['sign']} "
              f"(peak {ep['peak_xi_dn']:+.2f} DN): {ep['cause']}{tail}")
    check = s.get("truth_check")
    if check:
        print(f"  vs simulation truth: {check['detected']} of {len(check['episodes'])} corruption episode(s) "
              f"detected, {check['false_alarms']} false alarm(s)")
        for ep in check["episodes"]:
            delay = f"after {ep['delay_s']:.2f} s" if ep["detected"] else "MISSED"
            print(f"  - {'; '.join(ep['corrupted'])} (xi {ep['xi_sign']}): {delay}")
    rt = s["realtime_factor"]
    print(f"\n  {s['frames_per_s']} frames/s, {rt}x real time" if rt else f"\n  {s['frames_per_s']} frames/s")
    for kind, path in s.get("outputs", {}).items():
        print(f"  {kind:5s} {path}")


def _live_view(args: argparse.Namespace) -> Any:
    """The Foxglove server of ``--foxglove`` (None without it); waits ``--foxglove-wait`` for a client."""
    if args.foxglove is None:
        if args.foxglove_wait:
            raise ValueError("--foxglove-wait needs --foxglove PORT")
        return None
    if not (args.foxglove_wait >= 0 and args.foxglove_wait < float("inf")):
        raise ValueError(f"--foxglove-wait must be >= 0 seconds, got {args.foxglove_wait}")
    from msg_adapters.live_view import LiveView

    live = LiveView(live_topics(), args.foxglove, host=args.foxglove_host)
    print(f"foxglove: serving {live.url} (Foxglove: Open connection > Foxglove WebSocket)", flush=True)
    if args.foxglove_wait > 0 and not live.wait_for_subscriber(args.foxglove_wait):
        print(f"foxglove: no client after {args.foxglove_wait:g} s, replaying anyway", flush=True)
    return live


def default_out(bag: str) -> Path:
    """out/<the bag's name without its storage suffix> (``run.day1.mcap`` -> ``out/run.day1``)."""
    name = Path(bag.rstrip("/")).name
    stem = name[: -len(Path(name).suffix)] if Path(name).suffix.lower() in (".mcap", ".db3") else name
    return Path("out") / (stem or name)


def run(args: argparse.Namespace) -> int:
    if args.out is not None and not args.out.strip():
        raise ValueError("--out is empty: name the output folder")
    out = Path(args.out) if args.out is not None else default_out(args.bag)
    if args.json:
        if Path(args.json).is_dir():
            raise ValueError(f"--json {args.json} is a folder: name the file to write")
        refuse_overwriting_inputs([Path(args.json)], input_files(args.bag))
    if args.rate is not None and not (0 < args.rate < float("inf")):
        raise ValueError(f"--rate must be > 0, got {args.rate}")
    live = _live_view(args)
    try:
        summary = replay(args.bag, args.profile, out, model_name=args.model, weights=args.weights,
                         device=args.device, config=args.params, camera_name=args.camera_name,
                         **topic_overrides(args), bit_depth=args.bit_depth, threads=args.threads,
                         plot=not args.no_plot, live=live, rate=args.rate)
    finally:
        if live is not None:
            live.close()
    print_summary(summary)
    if args.json:
        write_text_atomic(args.json, json.dumps(summary, indent=2))
    return 0
