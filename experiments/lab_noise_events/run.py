"""The lab on campaigns with an intermittent fault: +S DN white noise added to frames 60-84 (seeded).

Simulates the campaigns (ev76c661, 120 frames at 10 Hz, 320x256: tuned seeds 1-4, held-out 21-24), adds the noise,
and prints per bag the lab's cuts, the segments around the fault, what it set apart (span, extra white sigma) and the
model's rms error on what it compares. Runs on versions without the cut too (for before/after):

    PYTHONPATH=. python experiments/lab_noise_events/run.py [--sigma 4] [--out DIR] [--tuned-seeds ...] [--heldout-seeds ...]
        [--effect NAME=VALUE]
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import tempfile
from pathlib import Path

import numpy as np

from noise_monitor.bag.reader import open_bag
from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.lab.analyze import analyze
from noise_monitor.lab.measure import measure_frames

LO, HI = 60, 85


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sigma", type=float, default=4.0, help="white noise added to frames 60-84 (DN)")
    ap.add_argument("--out", type=Path, default=None, help="where the bags go (default: a temporary directory)")
    ap.add_argument("--tuned-seeds", type=int, nargs="*", default=[1, 2, 3, 4], help="seeds of the `campaign` scenario")
    ap.add_argument("--heldout-seeds", type=int, nargs="*", default=[21, 22, 23, 24],
                    help="seeds of the `campaign_heldout` scenario")
    ap.add_argument("--effect", default=None, help="a hidden effect of the camera too (e.g. extra_read_noise=10)")
    args = ap.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="lab_noise_events_"))
    bags = [("campaign", s) for s in args.tuned_seeds] + [("campaign_heldout", s) for s in args.heldout_seeds]
    for scenario, seed in bags:
        bag = out / f"{scenario}_{seed}{'_' + args.effect if args.effect else ''}.mcap"
        if not bag.exists():
            simulate_bag(bag, "ev76c661", scenario, effects=[args.effect] if args.effect else [], frames=120, width=320,
                         height=256, seed=seed, fps=10.0)
        rng = np.random.default_rng(11)
        with open_bag(bag) as r:
            frames = list(r.frames(None))
        for i, f in enumerate(frames):
            if LO <= i < HI and f.image_dn is not None:
                noisy = f.image_dn + rng.normal(0.0, args.sigma, f.image_dn.shape)
                frames[i] = dataclasses.replace(f, image_dn=np.rint(np.clip(noisy, 0, 255)).astype(np.float32))
        meas = measure_frames(frames)
        near = [(s.frames[0], s.frames[-1]) for s in meas.segments if s.frames[0] <= HI and s.frames[-1] >= LO - 5]
        summary = analyze(frames, estimator=None)
        apart = [(e["from_s"], e["to_s"], round(math.sqrt(max(e["excess_var_dn2"]["temporal"]["dn2"], 0.0)), 2))
                 for e in summary.get("set_apart", [])]
        print(f"{scenario} seed {seed}: cuts at {[c.frame for c in getattr(meas, 'noise_changes', [])]}, "
              f"segments near the fault {near}, set apart (from s, to s, extra sigma DN) {apart}, "
              f"rms error {summary['rms_error_dn']:.3f} DN, {summary['diagnosis']}", flush=True)


if __name__ == "__main__":
    main()
