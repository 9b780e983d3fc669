"""False alarms and hits of the node's per-patch rule as its clear-decision margin changes.

A measurable patch alarms when |xi| > 1 DN; a declined one when | |xi| - 1 DN | > k predicted errors on the alarm
side with its relative error within the limit (``inference.clear_decisions``, shipped k = 2); and any patch whose
image-only bound proves the alarm (``xi_lower`` > 1 DN). Per set: the false alarms on part (a) and the hits on (b)
/ (c) (|xi_true| > 2 DN, the right sign) for each k. Run from the repository root.

Usage: .venv/bin/python experiments/reading_checks/clear_margin.py [--sets tune photos] [--k 0 0.5 1 1.5 2 3]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
import estimator_per_image as epi  # noqa: E402

from noise_monitor.estimator.data import metas_of  # noqa: E402
from noise_monitor.estimator.evaluate import ALARM_DN, HIT_TRUTH_DN  # noqa: E402
from noise_monitor.estimator.inference import MEASURABLE_RELATIVE_ERROR  # noqa: E402


def alarms(p: dict, k: float) -> tuple[np.ndarray, np.ndarray]:
    """Per patch: alarm under margin ``k``, and the xi it alarms with (the bound's where it proves the alarm)."""
    xi, err = np.asarray(p["xi"], float), np.asarray(p["sigma_image_error"], float)
    sure = (np.abs(xi) - ALARM_DN > k * err) & (err <= MEASURABLE_RELATIVE_ERROR * np.asarray(p["sigma_image"], float))
    proven = np.asarray(p["xi_lower"], float) > ALARM_DN
    measured = np.asarray(p["measurable"], bool) & (np.abs(xi) > ALARM_DN)
    return measured | (~np.asarray(p["measurable"], bool) & sure) | proven, np.where(proven, np.maximum(xi, p["xi_lower"]), xi)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", nargs="+", default=["tune", "photos"], choices=list(epi.NAMES))
    ap.add_argument("--k", nargs="+", type=float, default=[0.0, 0.5, 1.0, 1.5, 2.0, 3.0])
    ap.add_argument("--cache", type=Path, default=Path("out/estimator_eval"))
    args = ap.parse_args()
    est = epi.load("full_meta", device="cpu", weights=None, threads=1)
    for name in args.sets:
        rates: dict[float, dict[str, float]] = {k: {} for k in args.k}
        for part in "abc":
            d = epi.dataset(name, part, 64, args.cache, 3000 if name in epi.HELDOUT else None)
            p = est.predict(d["noisy"], metas_of(d))
            truth = np.asarray(d["truth_xi"], float)
            for k in args.k:
                alarm, xi = alarms(p, k)
                cand = np.abs(truth) > HIT_TRUTH_DN
                rates[k][part] = float(alarm.mean()) if part == "a" else float((alarm & (np.sign(xi) == np.sign(truth)))[cand].mean())
        print(f"== {name}")
        for k, r in rates.items():
            print(f"  k {k:.1f}: false alarms {100 * r['a']:.1f} %, hits (b) {100 * r['b']:.1f} %, (c) {100 * r['c']:.1f} %")


if __name__ == "__main__":
    main()
