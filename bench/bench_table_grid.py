"""Interpolated physics tables (metadata that changes every frame): accuracy against the exact tables and cost.

Accuracy: at random cameras and conditions drawn over the paper's ranges (seeds other than the test's),
the worst |sigma_interp - sigma_exact| per intensity level relative to the bound max(0.5 % sigma, 0.01 DN)
(<= 1 is within the bound), per model and mode. Cost: tables for a drifting path (temperature +0.013 degC
and a sinusoidal auto-exposure per frame), exact vs interpolated, ms per new metadata set.

Usage: .venv/bin/python bench/bench_table_grid.py [--points 40] [--frames 300] [--json out.json]
Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np

from noise_monitor.physics import PAPER_RANGES, CameraMetadata, NoiseModel, load_profile, sample_static

EFFECTS = {"prnu": {}, "dsnu": {}, "hot_pixels": {}, "quantization": {"bits": 8}, "dark_current_law": {}}


def _sigma(t: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    return np.sqrt(np.maximum(t[1] - t[0] ** 2, 0.0))


def accuracy(points: int, seed: int) -> dict[str, float]:
    rng = np.random.default_rng(seed)
    worst: dict[str, float] = {}
    for _ in range(points):
        meta = CameraMetadata.from_mapping({
            **sample_static(rng), "gain_db": float(rng.uniform(*PAPER_RANGES["gain_db"])),
            "exposure_time_s": float(math.exp(rng.uniform(math.log(1e-3), math.log(0.2)))),
            "sensor_temperature_c": float(rng.uniform(0.0, 80.0))})
        for label, extra in (("paper", None), ("paper+5 effects", EFFECTS)):
            exact, interp = NoiseModel(extra=extra), NoiseModel(extra=extra, interpolate=True)
            for mode in ("joint", "sequential"):
                te, ti = exact.tables(meta, mode), interp.tables(meta, mode)
                for name in te:
                    se = _sigma(te[name])
                    r = float(np.max(np.abs(_sigma(ti[name]) - se) / np.maximum(0.005 * se, 0.01)))
                    key = f"{label} {mode}"
                    worst[key] = max(worst.get(key, 0.0), r)
    return worst


def cost(frames: int) -> dict[str, float]:
    profile = load_profile("icx285")
    path = [profile.metadata(gain_db=18.0, exposure_time_s=0.01 * (1.0 + 0.2 * math.sin(i / 15.0)),
                             sensor_temperature_c=40.0 + 0.013 * i) for i in range(frames)]
    out: dict[str, float] = {}
    for label, model in (("exact", NoiseModel()), ("interpolated", NoiseModel(interpolate=True))):
        times = []
        for meta in path:
            t0 = time.perf_counter()
            model.tables(meta, "joint")
            model.tables(meta, "sequential")
            times.append((time.perf_counter() - t0) * 1e3)
        out[f"{label} ms per new metadata set (both modes) p50"] = float(np.percentile(times, 50))
        out[f"{label} p95"] = float(np.percentile(times, 95))
        out[f"{label} mean"] = float(np.mean(times))
        if model.grid:
            out["interpolated: lattice nodes computed"] = model.grid.nodes_computed
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=40)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--json")
    args = ap.parse_args()
    res = {"accuracy worst ratio to bound": accuracy(args.points, args.seed), "cost": cost(args.frames)}
    for k, v in res["accuracy worst ratio to bound"].items():
        print(f"accuracy ({args.points} random cameras x conditions), {k}: worst {v:.2f} of the bound")
    for k, v in res["cost"].items():
        print(f"{k}: {v:.2f}" if isinstance(v, float) else f"{k}: {v}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(res, f, indent=1)


if __name__ == "__main__":
    main()
