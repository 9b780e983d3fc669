"""Closing the loop on the estimator (issue 6): a camera with an effect the paper's model lacks.

1. simulate a bag of a camera with a hidden effect (default: column offsets of 2 DN);
2. the lab finds the effect, fits it and writes the extended profile (``analyze --add-effect NAME=fit
   --write-profile``);
3. replay with the shipped Full-Meta and the paper's model, then with the extended profile;
4. fine-tune Full-Meta on that profile (``train --profile camera.yaml --init full_meta.pt``), once plain and
   once with ``--anchor W`` (same data and seed);
5. replay with the fine-tuned weights and the extended profile.

Prints xi (the monitor's, DN) at every stage, the cost (data generation and training time), and how far each
fine-tune moved the reading of texture: sigma_image error RMS on the crops of the training photographs
(``estimator_tuning.py``'s ``tune`` set, part (a), 600 patches at 64 px; simulated with the paper's camera and
with the extended profile's) split by the shipped head's decision.

Usage: .venv/bin/python bench/finetune_effect.py [--effect column_offsets=2.0] [--patches 8000]
       [--steps 1500] [--lr 1e-3] [--photo-variants 0] [--anchor 100] [--threads 2] [--out out/finetune]
       [--cache out/estimator_eval] [--json out/finetune/summary.json]
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from estimator_tuning import tuning_set

from noise_monitor.bag.replay import replay
from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.estimator.data import Scheme, generate, metas_of
from noise_monitor.estimator.inference import load, weights_path
from noise_monitor.estimator.train import TrainSettings, train
from noise_monitor.estimator.train_cmd import camera
from noise_monitor.lab.analyze import analyze


def replay_xi(bag: Path, profile: str, weights: Path | None = None) -> dict:
    """Mean xi, |xi| and sigma_image / sigma_model of a replay (the monitor's numbers)."""
    s = replay(bag, profile=profile, out_dir=None, weights=weights, progress=False, plot=False)
    return {"xi_mean_dn": s["xi"]["mean"], "xi_p5_dn": s["xi"]["p5"], "xi_p95_dn": s["xi"]["p95"],
            "sigma_image_dn": s["sigma_image"]["mean"], "sigma_model_dn": s["sigma_model"]["mean"],
            "alarm_frames": s["frames_total"] - s["levels"]["OK"]}


def texture_drift(weights: dict[str, Path], cache: Path, effects: dict | None = None,
                  sensor: dict | None = None) -> dict[str, dict[str, float]]:
    """sigma_image error RMS (DN) of each weights on the tuning crops (a) (simulated with ``effects`` /
    ``sensor`` when given), on the patches the shipped head declines and on those it accepts."""
    d = tuning_set("tune", "a", 64, cache, effects, sensor)
    metas = metas_of(d)
    preds = {k: load("full_meta", device="cpu", weights=w, threads=1).predict(d["noisy"], metas) for k, w in weights.items()}
    declined = ~preds["shipped"]["measurable"]
    out = {}
    for k, p in preds.items():
        err = p["sigma_image"] - d["truth_sigma_image"]
        out[k] = {"declined_rms_dn": float(np.sqrt(np.mean(err[declined] ** 2))),
                  "accepted_rms_dn": float(np.sqrt(np.mean(err[~declined] ** 2)))}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--effect", default="column_offsets=2.0", help="hidden effect spec (simulate-bag --effect)")
    ap.add_argument("--profile", default="ev76c661")
    ap.add_argument("--patches", type=int, default=8000, help="fine-tuning patches")
    ap.add_argument("--steps", type=int, default=1500)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--photo-variants", type=int, default=0, help="fine-tuning imagery (train --photo-variants)")
    ap.add_argument("--anchor", type=float, default=100.0, help="weight of the anchored fine-tune (train --anchor)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--out", type=Path, default=Path("out/finetune"))
    ap.add_argument("--cache", type=Path, default=Path("out/estimator_eval"), help="tuning-set cache")
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
    data = generate(args.patches, 64, args.seed, "train", Scheme(), effects=effects, sensor=sensor, progress=False,
                    photo_variants=args.photo_variants)
    data_s = time.perf_counter() - t0
    settings = TrainSettings("full_meta", steps=args.steps, batch=32, lr=args.lr, seed=args.seed)
    t0 = time.perf_counter()
    tuned = train(settings, data, args.out / "weights", threads=args.threads, progress=False,
                  init=weights_path("full_meta"))
    train_s = time.perf_counter() - t0
    stages["extended profile, fine-tuned weights"] = replay_xi(bag, str(extended), tuned)
    anchored = train(TrainSettings("full_meta", steps=args.steps, batch=32, lr=args.lr, seed=args.seed, anchor=args.anchor),
                     data, args.out / "weights_anchored", threads=args.threads, progress=False,
                     init=weights_path("full_meta"))
    stages[f"extended profile, fine-tuned, anchor {args.anchor:g}"] = replay_xi(bag, str(extended), anchored)
    compared = {"shipped": weights_path("full_meta"), "fine-tuned": tuned, f"fine-tuned, anchor {args.anchor:g}": anchored}
    drift = {"paper camera": texture_drift(compared, args.cache),
             "this camera": texture_drift(compared, args.cache, effects, sensor)}

    print(f"\n{'stage':40s} {'xi mean':>8s} {'p5..p95':>15s} {'sigma_image':>11s} {'sigma_model':>11s}  DN")
    for stage, r in stages.items():
        print(f"{stage:40s} {r['xi_mean_dn']:+8.3f} {r['xi_p5_dn']:+7.3f}..{r['xi_p95_dn']:+.3f} "
              f"{r['sigma_image_dn']:11.3f} {r['sigma_model_dn']:11.3f}")
    print(f"cost: {args.patches} patches generated in {data_s:.0f} s, {args.steps} steps trained in {train_s:.0f} s "
          f"({args.threads} thread(s))")
    print("\nsigma_image error RMS on the training-photo crops (a), 64 px, by the shipped head's decision (DN):")
    for camera_name, rows in drift.items():
        for k, r in rows.items():
            print(f"  {camera_name:12s} {k:32s} declined {r['declined_rms_dn']:.3f}  accepted {r['accepted_rms_dn']:.3f}")
    summary = {"effect": args.effect, "lab_top_candidate": top["effect"], "fitted": lab.get("added_effects"),
               "rms_error_before_dn": lab["rms_error_before_dn"], "rms_error_after_dn": lab["rms_error_after_dn"],
               "stages": stages, "texture_drift": drift, "anchor": args.anchor, "photo_variants": args.photo_variants, "patches": args.patches, "steps": args.steps, "threads": args.threads,
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
