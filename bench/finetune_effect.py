"""Closing the loop on the estimator (issue 6): a camera with an effect the paper's model lacks.

1. simulate a bag of a camera with a hidden effect (default: column offsets of 2 DN);
2. the lab finds the effect, fits it and writes the extended profile (``analyze --add-effect NAME=fit
   --write-profile``);
3. replay with the shipped Full-Meta and the paper's model, then with the extended profile;
4. fine-tune Full-Meta on that profile (``train --profile camera.yaml --init full_meta.pt``);
5. replay with the fine-tuned weights and the extended profile.

Prints xi (the monitor's, DN) at every stage and the cost (data generation and training time).

Usage: .venv/bin/python bench/finetune_effect.py [--effect column_offsets=2.0] [--patches 8000]
       [--steps 1500] [--lr 1e-3] [--threads 2] [--out out/finetune] [--json out/finetune/summary.json]
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from noise_monitor.bag.replay import replay
from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.estimator.data import Scheme, generate
from noise_monitor.estimator.inference import weights_path
from noise_monitor.estimator.train import TrainSettings, train
from noise_monitor.estimator.train_cmd import camera
from noise_monitor.lab.analyze import analyze


def replay_xi(bag: Path, profile: str, weights: Path | None = None) -> dict:
    """Mean xi, |xi| and sigma_image / sigma_model of a replay (the monitor's numbers)."""
    s = replay(bag, profile=profile, out_dir=None, weights=weights, progress=False, plot=False)
    return {"xi_mean_dn": s["xi"]["mean"], "xi_p5_dn": s["xi"]["p5"], "xi_p95_dn": s["xi"]["p95"],
            "sigma_image_dn": s["sigma_image"]["mean"], "sigma_model_dn": s["sigma_model"]["mean"],
            "alarm_frames": s["frames_total"] - s["levels"]["OK"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--effect", default="column_offsets=2.0", help="hidden effect spec (simulate-bag --effect)")
    ap.add_argument("--profile", default="ev76c661")
    ap.add_argument("--patches", type=int, default=8000, help="fine-tuning patches")
    ap.add_argument("--steps", type=int, default=1500)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--out", type=Path, default=Path("out/finetune"))
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    name = args.effect.split("=")[0].split(":")[0]

    (args.out / "camera.mcap").unlink(missing_ok=True)  # this script's own output of an earlier run
    bag = simulate_bag(args.out / "camera.mcap", args.profile, "gain_sweep", effects=[args.effect],
                       frames=40, width=320, height=256, seed=args.seed)
    extended = args.out / "camera.yaml"
    lab = analyze(bag, profile=args.profile, add_effects=[f"{name}=fit"], write_profile=extended)
    top = lab["candidates"][0]
    print(f"lab: top candidate {top['effect']} (significant {top['significant']}), rms error "
          f"{lab['rms_error_before_dn']:.3f} -> {lab['rms_error_after_dn']:.3f} DN; wrote {extended}")

    stages = {"paper model, shipped weights": replay_xi(bag, args.profile),
              "extended profile, shipped weights": replay_xi(bag, str(extended))}
    effects, sensor = camera(str(extended))
    t0 = time.perf_counter()
    data = generate(args.patches, 64, args.seed, "train", Scheme(), effects=effects, sensor=sensor, progress=False)
    data_s = time.perf_counter() - t0
    settings = TrainSettings("full_meta", steps=args.steps, batch=32, lr=args.lr, seed=args.seed)
    t0 = time.perf_counter()
    tuned = train(settings, data, args.out / "weights", threads=args.threads, progress=False,
                  init=weights_path("full_meta"))
    train_s = time.perf_counter() - t0
    stages["extended profile, fine-tuned weights"] = replay_xi(bag, str(extended), tuned)

    print(f"\n{'stage':40s} {'xi mean':>8s} {'p5..p95':>15s} {'sigma_image':>11s} {'sigma_model':>11s}  DN")
    for stage, r in stages.items():
        print(f"{stage:40s} {r['xi_mean_dn']:+8.3f} {r['xi_p5_dn']:+7.3f}..{r['xi_p95_dn']:+.3f} "
              f"{r['sigma_image_dn']:11.3f} {r['sigma_model_dn']:11.3f}")
    print(f"cost: {args.patches} patches generated in {data_s:.0f} s, {args.steps} steps trained in {train_s:.0f} s "
          f"({args.threads} thread(s))")
    summary = {"effect": args.effect, "lab_top_candidate": top["effect"], "fitted": lab.get("added_effects"),
               "rms_error_before_dn": lab["rms_error_before_dn"], "rms_error_after_dn": lab["rms_error_after_dn"],
               "stages": stages, "patches": args.patches, "steps": args.steps, "threads": args.threads,
               "data_seconds": round(data_s, 1), "train_seconds": round(train_s, 1), "weights": str(tuned),
               "xi_abs_reduction": round(1.0 - abs(stages["extended profile, fine-tuned weights"]["xi_mean_dn"])
                                         / max(abs(stages["extended profile, shipped weights"]["xi_mean_dn"]), 1e-9), 3)}
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(summary, indent=2, default=float))
    print(f"fine-tuning changed mean |xi| by {-summary['xi_abs_reduction']:+.0%} "
          f"(from the extended profile with the shipped weights)")


if __name__ == "__main__":
    main()
