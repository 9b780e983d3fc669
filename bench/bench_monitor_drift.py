"""The monitor's processing time per 1280x1024 frame when the metadata changes every frame.

Three monitors side by side on the same frames, interleaved frame by frame (so a busy machine slows all
three alike): fixed metadata, drifting metadata with interpolated physics tables (the node's default) and
drifting metadata with exact tables. Drift as ``bench_node.py --drift``: +0.013 degC per frame,
auto-exposure +-20 %, auto-gain +-1 dB.

``--scene photo``: a still textured scene, on which the temporal measurement runs every frame (the default smooth
scene never holds still).

Usage: .venv/bin/python bench/bench_monitor_drift.py [--frames 60] [--threads 1] [--scene smooth|photo] [--json out.json]
Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from bench_node import DYNAMIC, PROFILE, dynamic, make_frames

from noise_monitor.estimator import load
from noise_monitor.monitor import Frame, Monitor, MonitorConfig
from noise_monitor.physics import NoiseModel, load_profile


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--scene", choices=("smooth", "photo"), default="smooth")
    ap.add_argument("--json")
    args = ap.parse_args()
    profile = load_profile(PROFILE)
    frames = make_frames(6, scene=args.scene)
    runs = {}
    for label, interpolate, drift in (("fixed metadata", True, False), ("drift, interpolated tables", True, True),
                                      ("drift, exact tables", False, True)):
        model = NoiseModel(interpolate=interpolate)
        est = load("full_meta", device="cpu", model=model, threads=args.threads)
        runs[label] = (Monitor(MonitorConfig(), est, model, "bench", "bench"), drift, [])
    held = dict.fromkeys(runs, 0)  # frames whose xi had a temporal measurement
    for i in range(args.frames + 3):
        for label, (monitor, drift, times) in runs.items():
            meta = profile.metadata(**(dynamic(i, True) if drift else DYNAMIC))
            frame = Frame(i * 33_333_333, frames[i % len(frames)].astype(np.float32), meta)
            t0 = time.perf_counter()
            res = monitor.process(frame)
            if i >= 3:  # warm-up: first inference, first lattice cells
                times.append((time.perf_counter() - t0) * 1e3)
            assert res.processed, res.message
            held[label] += res.temporal_frames > 0
    out = {}
    for label, (monitor, _, times) in runs.items():
        grid = monitor.model.grid
        out[label] = {"p50_ms": round(float(np.percentile(times, 50)), 1), "p95_ms": round(float(np.percentile(times, 95)), 1),
                      "mean_ms": round(float(np.mean(times)), 1),
                      "lattice_nodes": grid.nodes_computed if grid else None,
                      "frames_with_temporal": held[label]}
        print(f"{label:<28} processing per 1280x1024 frame p50 {out[label]['p50_ms']:6.1f} ms, p95 "
              f"{out[label]['p95_ms']:6.1f} ms, mean {out[label]['mean_ms']:6.1f} ms"
              + (f", lattice nodes computed {grid.nodes_computed}" if grid else "")
              + f", temporal measurement on {held[label]} of {args.frames + 3} frames")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
