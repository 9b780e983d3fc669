"""Benchmark of the node's and replay's lost-frame bookkeeping (``monitor.sync.GapCounter.observe``, once per image):
a 30 Hz stream with 0.5 ms stamp jitter, clean and with 10 % of the frames lost, the period inferred and stated
(``expected_rate_hz``), side by side in one run.

Usage: .venv/bin/python bench/bench_gap_counter.py [--frames 20000] [--repeats 3]
Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from noise_monitor.monitor import GapCounter

PERIOD_NS = 33_333_333


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=20000)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    jitter = rng.integers(-500_000, 500_000, args.frames)
    kept = rng.random(args.frames) > 0.1
    streams = {"clean": np.arange(args.frames), "10 % lost": np.flatnonzero(kept)}
    print(f"{'stream':10s} {'period':9s} {'us/image (best of ' + str(args.repeats) + ')':>24s} {'lost counted':>13s}")
    for name, frames in streams.items():
        stamps = [int(i) * PERIOD_NS + int(jitter[i]) for i in frames]
        truth = int(frames[-1] + 1 - len(frames))
        for mode, rate in (("inferred", 0.0), ("stated", 30.0)):
            best, lost = float("inf"), 0
            for _ in range(args.repeats):
                counter = GapCounter(expected_rate_hz=rate)
                t0 = time.perf_counter()
                lost = sum(counter.observe(s) for s in stamps) + counter.flush()
                best = min(best, (time.perf_counter() - t0) / len(stamps))
            print(f"{name:10s} {mode:9s} {best * 1e6:24.1f} {lost:8d} of {truth}")


if __name__ == "__main__":
    main()
