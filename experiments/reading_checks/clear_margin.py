"""False alarms and hits of the node's per-patch rule as its clear-decision margin changes.

The evaluation's ``decided`` rule (``evaluate.score``: a measurable patch alarms when |xi| > 1 DN, a declined one
when its decision is clear, ``inference.clear_decisions``: | |xi| - 1 DN | > k predicted errors, shipped k =
``CLEAR_DECISION_K`` = 2, and any patch whose image-only bound proves the alarm) with k set in turn. Per set: the
false alarms on part (a) and the hits on (b) / (c) (|xi_true| > 2 DN, the right sign) for each k. Run from the
repository root.

Usage: .venv/bin/python experiments/reading_checks/clear_margin.py [--sets tune photos] [--k 0 0.5 1 1.5 2 3]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
import estimator_per_image as epi  # noqa: E402

from noise_monitor.estimator import inference  # noqa: E402
from noise_monitor.estimator.data import metas_of  # noqa: E402
from noise_monitor.estimator.evaluate import score  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", nargs="+", default=["tune", "photos"], choices=list(epi.NAMES))
    ap.add_argument("--k", nargs="+", type=float, default=[0.0, 0.5, 1.0, 1.5, 2.0, 3.0])
    ap.add_argument("--cache", type=Path, default=Path("out/estimator_eval"))
    args = ap.parse_args()
    est = epi.load("full_meta", device="cpu", weights=None, threads=1)
    shipped = inference.CLEAR_DECISION_K
    for name in args.sets:
        rates: dict[float, dict[str, float]] = {k: {} for k in args.k}
        for part in "abc":
            d = epi.dataset(name, part, 64, args.cache, 3000 if name in epi.HELDOUT else None)
            p = est.predict(d["noisy"], metas_of(d))
            for k in args.k:  # the evaluation's own ``decided`` rule with the margin k
                inference.CLEAR_DECISION_K = k
                decided = score(p, d, part)["decided"]
                rates[k][part] = decided["false_alarm_rate" if part == "a" else "hit_rate"]
            inference.CLEAR_DECISION_K = shipped
        print(f"== {name}")
        for k, r in rates.items():
            print(f"  k {k:.1f}: false alarms {100 * r['a']:.1f} %, hits (b) {100 * r['b']:.1f} %, (c) {100 * r['c']:.1f} %")


if __name__ == "__main__":
    main()
