"""Benchmark of `noise-monitor replay`: frames/s and speed relative to real time (bag time / wall time).

Bags: the bundled ones (bags/*.mcap, 256x192 @ 5 Hz, metadata updated every second) and a simulated
VGA campaign (640x480 @ 10 Hz, gain sweep, metadata updated every second). Each is replayed with all
outputs (MCAP, CSV, PNG, JSON) and once without outputs (pipeline only). Estimator: full_meta on CPU.

Usage: .venv/bin/python bench/bench_replay.py [--threads N] [--vga-frames 60] [--json out.json]
Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import torch

from noise_monitor.bag.replay import replay
from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.estimator import load
from noise_monitor.monitor.runtime import set_inference_threads
from noise_monitor.paths import share_dir

BUNDLED = (("ev76c661_field.mcap", "ev76c661"), ("icx285_lab.mcap", "icx285"))


def bench(bag: Path, profile: str, out: Path | None, threads: int) -> dict:
    """One replay with a freshly loaded estimator (cold model tables, as a user's first run)."""
    est = load("full_meta", device="cpu")
    t = time.perf_counter()
    s = replay(bag, profile, out, estimator=est, threads=threads, progress=False)
    total = time.perf_counter() - t
    n = s["frames_total"]
    return {"bag": bag.name, "outputs": out is not None, "frames": n, "processed": s["frames_processed"],
            "bag_s": s["bag_duration_s"], "replay_s": s["wall_time_s"], "total_s": round(total, 2),
            "frames_per_s": s["frames_per_s"], "ms_per_frame": round(1e3 * s["wall_time_s"] / n, 1),
            "realtime_factor": s["realtime_factor"], "alarms": len(s["alarms"])}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=0, help="torch threads (0 = all cores but one, as the node)")
    ap.add_argument("--vga-frames", type=int, default=60)
    ap.add_argument("--json", help="write the results here")
    args = ap.parse_args()
    est = load("full_meta", device="cpu")
    set_inference_threads(args.threads)
    print(f"estimator {est.name}, patch {est.patch_size}, torch threads {torch.get_num_threads()}; "
          "replay = frames through the monitor + MCAP writing; total adds CSV and PNG")
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        vga = simulate_bag(tmp / "vga.mcap", "icx285", "gain_sweep", frames=args.vga_frames, width=640, height=480,
                           fps=10.0, hold_s=1.0, seed=1)
        bags = [(share_dir() / "bags" / name, prof) for name, prof in BUNDLED] + [(vga, "icx285")]
        for bag, prof in bags:
            for out in (None, tmp / f"out_{bag.stem}"):
                r = bench(bag, prof, out, args.threads)
                results.append(r)
                print(f"{r['bag']:20s} outputs={'yes' if r['outputs'] else 'no ':3s} {r['frames']:4d} frames "
                      f"({r['bag_s']:.1f} s of bag): replay {r['replay_s']:.2f} s = {r['frames_per_s']:.1f} frames/s, "
                      f"{r['ms_per_frame']:.0f} ms/frame, {r['realtime_factor']:.2f}x real time; total {r['total_s']:.2f} s")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
