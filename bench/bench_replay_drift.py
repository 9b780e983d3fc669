"""Replay of a campaign whose metadata changes every frame: interpolated vs exact physics tables.

A 320x256 EV76C661 ``live_drift`` campaign simulated with ``hold_s=0``: every frame carries new metadata, as
a live driver with auto-exposure, auto-gain and a drifting sensor temperature reports it (300 frames at
30 Hz: +0.013 degC per frame, exposure +-20 % and gain +-1 dB oscillating). Replayed without outputs, the estimator loaded by the replay with the monitor's
model (so its physics prior interpolates too), once with interpolated and once with exact tables; for
reference, the same campaign with its metadata held constant (one metadata set: tables built once).

Usage: .venv/bin/python bench/bench_replay_drift.py [--frames 300] [--threads 1] [--json out.json]
Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from noise_monitor.bag.replay import replay
from noise_monitor.bag.simulate import simulate_bag


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--threads", type=int, default=1, help="torch threads")
    ap.add_argument("--json")
    args = ap.parse_args()
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        bag = simulate_bag(Path(tmp) / "drift.mcap", "ev76c661", "live_drift", frames=args.frames, width=320, height=256,
                           fps=30.0, hold_s=0.0, seed=5)
        fixed = simulate_bag(Path(tmp) / "fixed.mcap", "ev76c661", "live_drift", frames=args.frames, width=320,
                             height=256, fps=30.0, hold_s=1e6, seed=5)
        for label, exact in (("interpolated", False), ("exact", True), ("fixed metadata (reference)", False)):
            if label.startswith("fixed"):
                bag = fixed
            s = replay(bag, "ev76c661", None, threads=args.threads, progress=False,
                       physics_tables="exact" if exact else "interpolated")
            results[label] = {"frames": s["frames_total"], "processed": s["frames_processed"],
                              "frames_per_s": s["frames_per_s"], "wall_s": s["wall_time_s"],
                              "xi_mean": s.get("xi", {}).get("mean") if isinstance(s.get("xi"), dict) else None}
            print(f"320x256 campaign, new metadata every frame, {label} tables: {s['frames_per_s']:.1f} frames/s "
                  f"({s['frames_processed']}/{s['frames_total']} evaluated, {s['wall_time_s']:.1f} s)", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
