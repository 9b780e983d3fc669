"""Benchmark of the frame-difference measurement (``measure.block_temporal``) as the live monitor calls it: the
stacked patches of a hold (16 patches of 64 px by default, each its own view of the light), a still and steadily lit
camera, a vibrating one (0.3 px rms: the per-pixel displacement regression), flickering light (2 % rms: the gain undone
first), lamps on the mains through a rolling shutter (30 % at 100 Hz, 30 us per row, 1 ms exposure: each patch's
bands fitted as a polynomial of the row and undone first) and LEDs dimmed by pulse-width modulation (500 Hz, on 30 %
of the time, 60 % depth, 1 ms exposure: sharp bands, fitted row by row), side by side in one run.

Usage: .venv/bin/python bench/bench_temporal.py [--patches 16] [--frames 4 16] [--repeats 30]
Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

from noise_monitor.bag.lights import pwm_gain, rolling_shutter_gain
from noise_monitor.measure import block_temporal


def hold(kind: str, frames: int, patches: int, rng: np.random.Generator) -> np.ndarray:
    """(frames, patches * 64, 64) DN: a faint texture seen still, shaking, under flickering light or under a rolling
    shutter's bands (of lamps on the mains or of LEDs dimmed by PWM), plus noise."""
    side = 64
    tex = cv2.GaussianBlur(rng.standard_normal((patches * side + 8, side + 8)).astype(np.float32), (0, 0), 1.0)
    scene = 100.0 + 3.0 * tex / tex.std()
    out = []
    for _ in range(frames):
        dx, dy = rng.normal(0.0, 0.3, 2) if kind == "vibrating" else (0.0, 0.0)
        view = cv2.getRectSubPix(scene, (side, patches * side), (4 + dx + (side - 1) / 2, 4 + dy + (patches * side - 1) / 2))
        gain = np.ones((patches * side, 1))
        if kind == "flickering":
            gain = gain * (1.0 + 0.02 * rng.standard_normal())
        if kind == "banded":
            gain = rolling_shutter_gain(patches * side, 0.001, rng.uniform(0.0, 2.0 * np.pi), 0.3, 50.0, 30e-6)[:, None]
        if kind == "pwm":
            gain = pwm_gain(patches * side, 0.001, rng.uniform(0.0, 2.0 * np.pi), 0.6, 500.0, 0.3, 30e-6)[:, None]
        out.append(view * gain + rng.normal(0.0, 2.0, view.shape))
    return np.stack(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--patches", type=int, default=16)
    ap.add_argument("--frames", type=int, nargs="+", default=[4, 16])
    ap.add_argument("--repeats", type=int, default=30)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    print(f"block_temporal on {args.patches} patches of 64 px (ms per call, median of {args.repeats})")
    for k in args.frames:
        row = []
        for kind in ("still", "vibrating", "flickering", "banded", "pwm"):
            x = hold(kind, k, args.patches, rng)
            block_temporal(x, view_rows=64, row_light=True)
            times = []
            for _ in range(args.repeats):
                t = time.perf_counter()
                block_temporal(x, view_rows=64, row_light=True)
                times.append((time.perf_counter() - t) * 1e3)
            row.append(f"{kind} {np.median(times):6.1f}")
        print(f"  {k:3d} frames: " + "   ".join(row))


if __name__ == "__main__":
    main()
