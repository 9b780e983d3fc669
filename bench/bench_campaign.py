"""Benchmark `noise-monitor campaign`: 200 small generated bags (10 cameras x 20 bags, 10 frames of 128x128).

Prints: bit-exactness against replay() of every bag; wall time on the local pool with 1 and 2 workers and
the parallel efficiency; the same on a local Ray with 2 CPUs and Ray's overhead per bag; the driver's
peak memory and manifest bytes per bag; the machine's load average next to each figure (the CPU is shared).

    .venv/bin/python bench/bench_campaign.py [--bags 200] [--out out/bench_campaign] [--skip-exact] [--skip-ray]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("OMP_NUM_THREADS", "1")

from noise_monitor.bag.simulate import START_NS, simulate_bag  # noqa: E402
from noise_monitor.physics import load_profile  # noqa: E402
from noise_monitor.physics.metadata import CameraProfile  # noqa: E402

DAY_NS = 86400 * 10**9
CAMERAS = 10


def make_bags(root: Path, n: int) -> list[Path]:
    """n bags over CAMERAS cameras, one every 2 days per camera; camera 0 ages (dark current x1 -> x3),
    camera 1 sees unexpected image noise (the image_noise scenario). Reused when already there."""
    prof = load_profile("ev76c661")
    bags = []
    for i in range(n):
        cam, k = i % CAMERAS, i // CAMERAS
        path = root / f"cam{cam:02d}" / f"bag{k:03d}.mcap"
        bags.append(path)
        if path.is_file():
            continue
        path.parent.mkdir(parents=True, exist_ok=True)
        p: str | CameraProfile = "ev76c661"
        if cam == 0:
            scale = 1.0 + 2.0 * k / max(1, n // CAMERAS - 1)
            p = CameraProfile(prof.name, {**prof.values,
                                          "dark_signal_fom_na_cm2": prof.values["dark_signal_fom_na_cm2"] * scale})
        simulate_bag(path, p, "image_noise" if cam == 1 else "static", frames=10, width=128, height=128, seed=i,
                     hardware_id=f"robot{cam:02d}/front", start_ns=START_NS + 2 * k * DAY_NS + cam * 3600 * 10**9)
    return bags


def load() -> str:
    return "/".join(f"{x:.1f}" for x in os.getloadavg())


def campaign(bags_dir: Path, out: Path, backend: str, workers: int) -> dict:
    from noise_monitor.fleet import run_campaign

    shutil.rmtree(out, ignore_errors=True)
    before = load()
    t0 = time.perf_counter()
    c = run_campaign([bags_dir], out, profile="ev76c661", backend=backend, workers=workers, progress=False)
    wall = time.perf_counter() - t0
    walls = [b["wall_s"] for b in c["bags"]]
    ent = [json.loads(ln) for ln in (out / "manifest.jsonl").read_text().splitlines()]
    task_s = [e.get("task_s") for e in ent if e.get("task_s") is not None]
    return {"backend": backend, "workers": workers, "wall_s": round(wall, 2), "run_wall_s": c["run"]["wall_time_s"],
            "bags": c["totals"]["bags_evaluated"], "frames": c["totals"]["frames_total"],
            "bag_wall_mean_s": round(float(np.mean(walls)), 4), "bag_wall_median_s": round(float(np.median(walls)), 4),
            "bag_cpu_mean_s": round(float(np.mean([e["cpu_s"] for e in ent if "cpu_s" in e])), 4),
            "task_minus_bag_s": round(float(np.mean([e["task_s"] - e["wall_s"] for e in ent])), 4) if task_s else None,
            "task_minus_bag_median_s": round(float(np.median([e["task_s"] - e["wall_s"] for e in ent])), 4)
            if task_s else None,
            "driver_peak_rss_mb": c["run"]["driver_peak_rss_mb"],
            "manifest_bytes_per_bag": round((out / "manifest.jsonl").stat().st_size / len(ent)),
            "campaign_json_bytes_per_bag": round((out / "campaign.json").stat().st_size / len(ent)),
            "load_before": before, "load_after": load()}


def exact(bags: list[Path], out: Path) -> dict:
    """Every bag's per-frame numbers in the campaign table vs replay() of the bag, bit for bit."""
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    from noise_monitor.bag.replay import replay
    from noise_monitor.bag.results import CONDITION_KEYS, FrameTable

    t = pq.read_table(out / "frames.parquet")
    mismatched, values = [], 0
    for bag in bags:
        table = FrameTable()
        replay(bag, "ev76c661", None, progress=False, table=table)
        got = t.filter(pc.equal(t["bag"], str(bag.resolve())))
        keys = [k for k in (*CONDITION_KEYS, *table.number_keys) if k != "processing_ms"]
        ok = got.num_rows == len(table) and got["processed"].to_pylist() == table.column("processed").tolist()
        for k in keys:
            a = np.asarray(got[k].to_numpy(), np.float32).view(np.uint32)
            ok &= np.array_equal(a, table.numbers(k).astype(np.float32).view(np.uint32))
            values += len(table)
        if not ok:
            mismatched.append(str(bag))
    return {"bags_compared": len(bags), "values_compared": values, "bags_mismatched": mismatched}


def driver_at_scale(manifest: Path, n: int) -> dict:
    """The driver's bookkeeping for n bags: a manifest of n entries (the measured ones, replicated under new
    paths and hashes) loaded and summarised as a campaign of n bags; resident memory growth and time."""
    import gc

    from noise_monitor.fleet.manifest import Manifest
    from noise_monitor.fleet.report import summarize
    from noise_monitor.fleet.task import rss_mb

    lines = [json.loads(ln) for ln in manifest.read_text().splitlines()]
    big = manifest.parent / "scale" / "manifest.jsonl"
    big.parent.mkdir(exist_ok=True)
    key = lines[0]["settings"]
    with open(big, "w") as fh:
        for i in range(n):
            e = dict(lines[i % len(lines)])
            e["path"] = f"/fleet/bag{i:06d}.mcap"
            e["sha256"] = f"{i:064x}"
            e["record"] = {**e["record"], "hardware_id": f"robot{i % 500:03d}/front"}
            fh.write(json.dumps(e, separators=(",", ":")) + "\n")
    gc.collect()
    rss0, t0 = rss_mb(), time.perf_counter()
    m = Manifest(big.parent, key)
    t_load = time.perf_counter() - t0
    paths = [f"/fleet/bag{i:06d}.mcap" for i in range(n)]
    c = summarize(paths, [m.entries[p] for p in paths], [], {"backend": "pool"})
    t_sum = time.perf_counter() - t0 - t_load
    rss1 = rss_mb()
    t1 = time.perf_counter()
    out = json.dumps(c)
    t_json = time.perf_counter() - t1
    return {"bags": n, "cameras": len(c["cameras"]), "manifest_mb": round(big.stat().st_size / 2**20, 1),
            "load_s": round(t_load, 2), "summarize_s": round(t_sum, 2), "json_dump_s": round(t_json, 2),
            "campaign_json_mb": round(len(out) / 2**20, 1), "driver_rss_growth_mb": round(rss1 - rss0, 1),
            "load": load()}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bags", type=int, default=200)
    ap.add_argument("--out", default="out/bench_campaign")
    ap.add_argument("--skip-exact", action="store_true")
    ap.add_argument("--skip-ray", action="store_true")
    args = ap.parse_args()
    root = Path(args.out)
    t0 = time.perf_counter()
    bags = make_bags(root / "bags", args.bags)
    print(f"{len(bags)} bags in {root / 'bags'} ({time.perf_counter() - t0:.1f} s to make or find)", flush=True)
    res: dict = {"cpus": os.cpu_count()}
    res["pool1"] = campaign(root / "bags", root / "pool1", "pool", 1)
    print("pool, 1 worker:", res["pool1"], flush=True)
    res["pool2"] = campaign(root / "bags", root / "pool2", "pool", 2)
    print("pool, 2 workers:", res["pool2"], flush=True)
    res["efficiency_2_vs_1"] = round(res["pool1"]["run_wall_s"] / (2 * res["pool2"]["run_wall_s"]), 3)
    res["efficiency_2_vs_1_end_to_end"] = round(res["pool1"]["wall_s"] / (2 * res["pool2"]["wall_s"]), 3)
    print(f"parallel efficiency, 2 workers vs 1 (pool): {100 * res['efficiency_2_vs_1']:.1f} % over the bags "
          f"(workers' start-up included), {100 * res['efficiency_2_vs_1_end_to_end']:.1f} % end to end "
          "(+ the serial merge and report)", flush=True)
    if not args.skip_ray:
        res["ray2"] = campaign(root / "bags", root / "ray2", "ray", 2)
        print("ray, 2 CPUs:", res["ray2"], flush=True)
        res["ray_overhead_per_bag_s"] = round((res["ray2"]["run_wall_s"] - res["pool2"]["run_wall_s"]) / len(bags), 4)
        res["ray_task_latency_median_s"] = res["ray2"]["task_minus_bag_median_s"]
        print(f"Ray overhead per bag (wall, vs the pool at 2 workers): {res['ray_overhead_per_bag_s'] * 1e3:.1f} ms; "
              f"submit-to-result minus the task's own time: mean {res['ray2']['task_minus_bag_s'] * 1e3:.1f} ms "
              f"(worker start-ups included), median {res['ray2']['task_minus_bag_median_s'] * 1e3:.1f} ms", flush=True)
    res["driver_1e5"] = driver_at_scale(root / "pool2" / "manifest.jsonl", 100_000)
    print("driver bookkeeping for 10^5 bags:", res["driver_1e5"], flush=True)
    if not args.skip_exact:
        res["exact"] = exact(bags, root / "pool2")
        print("bit-exact vs replay():", res["exact"], flush=True)
    (root / "results.json").write_text(json.dumps(res, indent=1))
    print(f"wrote {root / 'results.json'}")
    return 1 if res.get("exact", {}).get("bags_mismatched") else 0


if __name__ == "__main__":
    sys.exit(main())
