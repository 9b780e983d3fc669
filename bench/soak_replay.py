"""Soak test of the replay: >= 20,000 generated frames through the monitor with all outputs, memory sampled.

A simulated camera (ICX285 profile, static scene at 30 Hz, metadata updated every second) is written to an
MCAP bag, then replayed with the bundled full_meta estimator on CPU (MCAP + CSV + JSON outputs, no PNG).
A sampler thread reads this process's resident memory (VmRSS) every ``--sample-s`` seconds during the
replay. Printed: frames/s, real-time factor, memory at start / after warm-up / at the end and the growth,
and the accounting: every image of the bag is a CSV row and a /diagnostics message of the output MCAP,
processed or skipped with a reason, none lost.

Usage: .venv/bin/python bench/soak_replay.py [--frames 20000] [--width 128] [--height 96] [--json out.json]
Prints figures; asserts nothing (the accounting check prints PASS/FAIL and sets the exit code).
"""
from __future__ import annotations

import argparse
import csv
import json
import re
import tempfile
import threading
import time
from pathlib import Path

import torch
from mcap.reader import make_reader

from msg_adapters.outputs import frame_topic
from noise_monitor.bag.reader import open_bag
from noise_monitor.bag.replay import replay
from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.estimator import load
from noise_monitor.monitor import MonitorConfig


def rss_mb() -> float:
    """Resident memory of this process (MB) from /proc/self/status."""
    return int(re.search(r"VmRSS:\s+(\d+) kB", Path("/proc/self/status").read_text()).group(1)) / 1024


class MemorySampler(threading.Thread):
    """Samples (seconds since start, RSS MB) until stopped."""

    def __init__(self, period_s: float) -> None:
        super().__init__(daemon=True)
        self.period_s = period_s
        self.samples: list[tuple[float, float]] = []
        self._stop_event = threading.Event()
        self._t0 = time.perf_counter()

    def run(self) -> None:
        while not self._stop_event.is_set():
            self.samples.append((time.perf_counter() - self._t0, rss_mb()))
            self._stop_event.wait(self.period_s)

    def stop(self) -> list[tuple[float, float]]:
        self._stop_event.set()
        self.join()
        self.samples.append((time.perf_counter() - self._t0, rss_mb()))
        return self.samples


def account(bag: Path, out: Path, summary: dict) -> dict:
    """Images in the bag vs. summary, CSV rows and /diagnostics statuses of the output MCAP."""
    with open_bag(bag) as reader:
        images = len(reader)
    with open(out / "replay.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    indices = sorted(int(r["index"]) for r in rows)
    with open(out / "replay.mcap", "rb") as fh:
        statuses = sum(1 for _ in make_reader(fh).iter_messages(topics=[frame_topic()]))
    checks = {
        "summary frames_total == images in the bag": summary["frames_total"] == images,
        "processed + skipped == frames_total": summary["frames_processed"] + summary["frames_skipped"] == images,
        "skip reasons cover every skipped frame": sum(summary["skip_reasons"].values()) == summary["frames_skipped"],
        "one CSV row per image, indices 0..N-1": indices == list(range(images)),
        "a ~/frame status per image": statuses == images,
    }
    return {"images": images, "csv_rows": len(rows), "frame_statuses": statuses, "checks": checks,
            "ok": all(checks.values())}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=20_000)
    ap.add_argument("--width", type=int, default=128)
    ap.add_argument("--height", type=int, default=96)
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--patches", type=int, default=2, help="patches per frame (K)")
    ap.add_argument("--threads", type=int, default=1, help="torch threads")
    ap.add_argument("--sample-s", type=float, default=1.0, help="memory sampling period")
    ap.add_argument("--json", help="write the results here")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t = time.perf_counter()
        bag = simulate_bag(tmp / "soak.mcap", "icx285", "static", frames=args.frames, width=args.width,
                           height=args.height, fps=args.fps, hold_s=1.0, seed=3, progress=True)
        gen_s = time.perf_counter() - t
        print(f"generated {args.frames} frames {args.width}x{args.height} @ {args.fps:g} Hz in {gen_s:.1f} s "
              f"({bag.stat().st_size / 1e6:.1f} MB MCAP)")
        est = load("full_meta", device="cpu")
        config = MonitorConfig(patches_per_frame=args.patches)
        sampler = MemorySampler(args.sample_s)
        sampler.start()
        summary = replay(bag, "icx285", tmp / "out", estimator=est, config=config, plot=False, progress=True)
        samples = sampler.stop()
        acc = account(bag, tmp / "out", summary)
    wall = samples[-1][0]
    warm = next((m for s, m in samples if s >= 0.1 * wall), samples[0][1])
    start, peak, end = samples[0][1], max(m for _, m in samples), samples[-1][1]
    result = {
        "frames": summary["frames_total"], "processed": summary["frames_processed"],
        "skipped": summary["frames_skipped"], "skip_reasons": summary["skip_reasons"],
        "frames_per_s": summary["frames_per_s"], "realtime_factor": summary["realtime_factor"],
        "replay_wall_s": summary["wall_time_s"], "generate_s": round(gen_s, 1),
        "rss_start_mb": round(start, 1), "rss_after_10pct_mb": round(warm, 1), "rss_end_mb": round(end, 1),
        "rss_peak_mb": round(peak, 1), "growth_mb": round(end - start, 1),
        "growth_after_warmup_mb": round(end - warm, 1),
        "growth_per_1000_frames_mb": round(1000 * (end - warm) / max(0.9 * summary["frames_total"], 1), 3),
        "rss_samples": [(round(s, 1), round(m, 1)) for s, m in samples[:: max(1, len(samples) // 40)]],
        "accounting": acc,
    }
    print(f"\nreplay: {result['frames']} frames, {result['processed']} processed, {result['skipped']} skipped "
          f"{result['skip_reasons'] or ''}")
    print(f"  {result['frames_per_s']} frames/s, {result['realtime_factor']}x real time, {result['replay_wall_s']} s")
    print(f"  RSS: start {start:.1f} MB, after 10 % {warm:.1f} MB, end {end:.1f} MB, peak {peak:.1f} MB")
    print(f"  growth {end - start:+.1f} MB in total, {end - warm:+.1f} MB after warm-up "
          f"({result['growth_per_1000_frames_mb']:+.3f} MB per 1000 frames)")
    print("  accounting:")
    for name, ok in acc["checks"].items():
        print(f"    {'PASS' if ok else 'FAIL'}  {name}")
    print(f"  images {acc['images']}, CSV rows {acc['csv_rows']}, /diagnostics statuses {acc['diagnostics']}")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2))
    return 0 if acc["ok"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
