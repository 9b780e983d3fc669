"""Throughput of the estimator variants: ms per patch and patches/s at batch 1/16/64 (CPU).

Measures the shipped Full-Meta end to end (physics prior + compact network, one metadata per call as in
a camera frame), the network part under torch eager and ONNX Runtime, the trained paper-family
variants, and the paper-size network (64 features, 2x5 convolutions, untrained: speed only) at the
same patch area and at the paper's 128x128. The headline ratio (issue 15: >= 50x at the node's patch size)
is measured with the two called alternately, fastest call of each, so that the machine's drifting speed
weighs on both alike.

Usage: .venv/bin/python bench/bench_estimator.py [--threads 2] [--reps 5] [--json out/bench_estimator.json]
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

from noise_monitor.estimator import load
from noise_monitor.estimator.inference import NAMES, WEIGHTS_DIR, onnx_session
from noise_monitor.estimator.networks import PaperConfig, PaperNet
from noise_monitor.physics import load_profile

BATCHES = (1, 16, 64)


def timeit(fn, reps: int) -> float:
    """Median seconds of ``reps`` calls after one warm-up call."""
    fn()
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def row(name: str, size: int, batch: int, seconds: float) -> dict:
    return {"variant": name, "patch": f"{size}x{size}", "area_px": size * size, "batch": batch,
            "ms_per_patch": round(1000.0 * seconds / batch, 3), "patches_per_s": round(batch / seconds, 1)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    meta = load_profile("ev76c661").metadata(gain_db=12.0, exposure_time_s=0.02, sensor_temperature_c=45.0)
    rng = np.random.default_rng(0)
    rows: list[dict] = []

    ests = {bk: load("full_meta", device="cpu", backend=bk) for bk in ("onnx", "torch")}
    fm = ests["torch"]
    size = fm.patch_size
    sizes = sorted({size, 128})  # native size and the paper's 128x128 (the net is size-agnostic)
    for bk, est in ests.items():
        est.predict(np.full((1, size, size), 100.0, np.float32), meta)  # build the metadata's tables once
        for psize in sizes:
            for b in BATCHES:
                x = rng.uniform(0, 255, (b, psize, psize)).astype(np.float32)
                rows.append(row(f"full_meta (end to end, {bk})", psize, b, timeit(lambda: est.predict(x, meta), args.reps)))

    # network part only: torch eager vs ONNX Runtime
    from noise_monitor.estimator.features import compact_inputs

    for b in BATCHES:
        x = rng.uniform(0, 255, (b, size, size)).astype(np.float32)
        tables = fm.prior.tables(meta)[None]
        evidence = bool(fm.net.cfg.evidence)  # the confidence head's texture evidence (third input)
        extra = {"trend": fm.net.cfg.shape_trend, "spectral": fm.net.cfg.spectral}  # the optional scalars
        maps, scalars, phys = compact_inputs(x, tables, np.zeros(b, np.int64), evidence=evidence, **extra)
        arrays = (maps, scalars) + ((phys["evidence"],) if evidence else ())
        tensors = tuple(torch.from_numpy(a) for a in arrays)
        with torch.inference_mode():
            rows.append(row("full_meta net only (torch eager)", size, b, timeit(lambda: fm.net(*tensors), args.reps)))
        sess, names = onnx_session(fm.net, tensors, args.threads)
        feed = dict(zip(names, arrays))
        rows.append(row("full_meta net only (onnxruntime)", size, b, timeit(lambda: sess.run(None, feed), args.reps)))
        rows.append(row("full_meta physics+features only", size, b, timeit(
            lambda: compact_inputs(x, tables, np.zeros(b, np.int64), evidence=evidence, **extra), args.reps)))

    for name in NAMES[1:]:
        if not (WEIGHTS_DIR / f"{name}.pt").is_file():
            continue
        est = load(name, device="cpu")
        for b in BATCHES:
            x = rng.uniform(0, 255, (b, est.patch_size, est.patch_size)).astype(np.float32)
            rows.append(row(f"{name} (trained size)", est.patch_size, b, timeit(lambda: est.predict(x, meta), args.reps)))

    paper = PaperNet(PaperConfig(variant="full_meta_paper")).eval()
    for psize in sizes:
        for b in BATCHES:
            x = torch.rand(b, 1, psize, psize)
            m = torch.rand(b, 11)
            reps = max(1, args.reps // (2 if b > 1 else 1))
            with torch.inference_mode():
                rows.append(row("paper-size full_meta_paper (345k, torch)", psize, b, timeit(lambda: paper(x, m), reps)))

    print(f"threads={args.threads}  shipped full_meta patch {size}x{size} ({size * size} px)")
    print(f"{'variant':<44} {'patch':>8} {'batch':>5} {'ms/patch':>10} {'patches/s':>10}")
    for r in rows:
        print(f"{r['variant']:<44} {r['patch']:>8} {r['batch']:>5} {r['ms_per_patch']:>10.3f} {r['patches_per_s']:>10.1f}")
    speedup = {}
    for psize in sizes:
        best = {name: min(r["ms_per_patch"] for r in rows if r["variant"].startswith(name) and r["area_px"] == psize**2)
                for name in ("full_meta (end to end, onnx)", "paper-size")}  # ms/patch: patches/s are rounded
        speedup[f"{psize}x{psize}"] = round(best["paper-size"] / best["full_meta (end to end, onnx)"], 1)
        print(f"speed-up of shipped full_meta over the paper-size network at {psize}x{psize}: "
              f"{speedup[f'{psize}x{psize}']:.0f}x (best batch each, measured apart)")
    # the headline ratio: both at their best batch, measured alternately so that the machine's speed, which
    # drifts by 20-30 % on a shared VM over a run, weighs on both alike; fastest call of each
    interleaved = {}
    for psize in sizes:
        xs = {b: rng.uniform(0, 255, (b, psize, psize)).astype(np.float32) for b in BATCHES}
        xp = {b: (torch.rand(b, 1, psize, psize), torch.rand(b, 11)) for b in BATCHES}
        ours = {b: [] for b in BATCHES}
        theirs = {b: [] for b in BATCHES}
        with torch.inference_mode():
            for _ in range(args.reps * 2):
                for b in BATCHES:
                    t0 = time.perf_counter()
                    ests["onnx"].predict(xs[b], meta)
                    ours[b].append((time.perf_counter() - t0) / b)
                    t0 = time.perf_counter()
                    paper(*xp[b])
                    theirs[b].append((time.perf_counter() - t0) / b)
        mo, bo = min((min(v), b) for b, v in ours.items())
        mt, bt = min((min(v), b) for b, v in theirs.items())
        # per round, both at their best batch of that round: the drift cancels in each ratio
        paired = np.array([min(v[r] for v in theirs.values()) / min(v[r] for v in ours.values())
                           for r in range(args.reps * 2)])
        lo, med, hi = np.percentile(paired, [10, 50, 90])
        interleaved[f"{psize}x{psize}"] = {"full_meta_ms": round(1e3 * mo, 3), "full_meta_batch": bo,
                                           "paper_ms": round(1e3 * mt, 2), "paper_batch": bt, "speedup": round(mt / mo, 1),
                                           "paired_speedup_p10_p50_p90": [round(float(v), 1) for v in (lo, med, hi)]}
        print(f"interleaved at {psize}x{psize} (fastest call of each batch, {args.reps * 2} rounds): full_meta "
              f"{1e3 * mo:.3f} ms/patch (batch {bo}), paper-size {1e3 * mt:.2f} ms/patch (batch {bt}): {mt / mo:.0f}x; "
              f"per round {med:.0f}x (p10-p90 {lo:.0f}-{hi:.0f}x)")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"threads": args.threads, "rows": rows, "speedup_vs_paper_size": speedup,
                                         "interleaved": interleaved}, indent=2))


if __name__ == "__main__":
    main()
