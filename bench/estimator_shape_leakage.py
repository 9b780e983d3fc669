"""How far sigma_image leans on the stated model's per-pixel shape: the image fixed, an effect added to the stated model.

``test_sigma_image_does_not_follow_the_stated_model`` bounds the leakage of a stated *gain* change (the shape kept).
Here the stated model gains an effect that changes the shape (PRNU: sigma grows with the signal), on patches
noised *with* it: per patch kind, the noise actually added (RMS of noisy - clean), sigma_image read with the stated
model without and with the effect, sigma_model both ways and the leakage d sigma_image / d sigma_model. Patches of
one intensity (the shape is flat either way) and 64 px horizontal ramps (from 0.4x to 1.25x the level); icx285 at
6 dB, 10 ms, 30 degC; 3 % PRNU; 16 noise draws per patch kind (seeded). Then the lab's estimator view of the bag
of ``test/lab/test_cli.py`` (a hidden 3 % PRNU): xi, sigma_image and sigma_model means before / after the effect is
added (``noise-monitor analyze --add-effect prnu=fit``). ``--campaign PCT``: besides, the node on held-out photo
campaigns (``campaign_heldout``, or the tuned-on ``campaign`` with ``--scenario``; ev76c661, 320x256, 100 frames
at 10 Hz, ``--seeds``) with a hidden PCT % PRNU, replayed
with the paper's model and with the PRNU stated: per-frame xi against the truth (sigma_model without - with the
PRNU, same patches), with the node's parameters (``config/node.yaml``: static holds fuse the temporal measurement,
which a fixed pattern does not enter) and single-image (``temporal_frames: 0``).

Usage: .venv/bin/python bench/estimator_shape_leakage.py [--weights W.pt ...] [--no-lab] [--campaign 4 --seeds 21 22 --scenario campaign_heldout]
Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import json
import tempfile
from pathlib import Path

import numpy as np

from noise_monitor.bag.replay import replay
from noise_monitor.bag.results import FrameTable
from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.cli import main as cli_main
from noise_monitor.estimator import load
from noise_monitor.monitor import MonitorConfig
from noise_monitor.physics import NoiseModel, load_profile

LEVELS = (40.0, 120.0, 200.0)
PRNU = {"prnu": {"sigma_pct": 3.0}}
DRAWS = 16


def clean_patch(kind: str, level: float) -> np.ndarray:
    if kind == "flat":
        return np.full((64, 64), level, np.float32)
    return np.tile(np.linspace(0.4 * level, min(1.25 * level, 245.0), 64, dtype=np.float32), (64, 1))


def patches(weights: str | None) -> None:
    truth, base = NoiseModel(extra=PRNU), NoiseModel()
    meta = load_profile("icx285").metadata(gain_db=6.0, exposure_time_s=0.01, sensor_temperature_c=30.0)
    without = load("full_meta", device="cpu", model=base, weights=weights, threads=1)
    with_effect = load("full_meta", device="cpu", model=truth, weights=weights, threads=1)
    rng = np.random.default_rng(3)
    print(f"{'patch':12s} {'added':>6s} {'image: without / with PRNU stated':>34s} {'model: without / with':>22s} {'leakage':>8s}")
    for kind in ("flat", "ramp"):
        leaks = []
        for level in LEVELS:
            clean = clean_patch(kind, level)
            noisy = np.stack([np.clip(truth.simulate(clean, meta, rng)[0], 0, 255) for _ in range(DRAWS)]).astype(np.float32)
            a, b = without.predict(noisy, meta), with_effect.predict(noisy, meta)
            added = float(np.mean([np.std(n - clean) for n in noisy]))
            d_model = float(np.mean(b["sigma_model"] - a["sigma_model"]))
            leaks.append(float(np.mean(b["sigma_image"] - a["sigma_image"])) / d_model)
            print(f"{kind} {level:5.0f} DN {added:6.2f} {a['sigma_image'].mean():20.2f} / {b['sigma_image'].mean():.2f} "
                  f"{a['sigma_model'].mean():15.2f} / {b['sigma_model'].mean():.2f} {leaks[-1]:+8.2f}")
        print(f"{kind}: mean leakage {np.mean(leaks):+.3f}")


def lab_view(weights: str | None) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        bag = simulate_bag(Path(tmp) / "prnu.mcap", "icx285", "lab", effects=["prnu=3"], frames=40, width=128, height=96,
                           seed=5)
        out = Path(tmp) / "analysis.json"
        with contextlib.redirect_stdout(io.StringIO()):  # the analysis report: only the estimator view is wanted here
            cli_main(["analyze", str(bag), "--profile", "icx285", "--add-effect", "prnu=fit", "--json", str(out),
                      "--quiet", *(["--weights", weights] if weights else [])])
        view = json.loads(out.read_text())["estimator"]
    b, a = view["before"], view["after"]
    print("lab view (hidden 3 % PRNU), before -> after the effect is added, means over 40 frames (DN): "
          f"xi {b['xi_dn']['mean']:+.3f} -> {a['xi_dn']['mean']:+.3f}, sigma_image {b['sigma_image_dn']['mean']:.3f} -> "
          f"{a['sigma_image_dn']['mean']:.3f}, sigma_model {b['sigma_model_dn']['mean']:.3f} -> {a['sigma_model_dn']['mean']:.3f}")


def campaign(weights: str | None, pct: float, seeds: list[int], scenario: str) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        stated = Path(tmp) / "with_prnu.yaml"
        stated.write_text(dataclasses.replace(load_profile("ev76c661"), effects={"prnu": {"sigma_pct": pct}}).to_yaml())
        # the node's parameters (config/node.yaml), and the same monitor with the temporal measurement off
        configs: dict[str, MonitorConfig | None] = {"node": None, "single-image": MonitorConfig(temporal_frames=0)}
        for seed in seeds:
            bag = simulate_bag(Path(tmp) / f"c{seed}.mcap", "ev76c661", scenario, effects=[f"prnu={pct:g}"],
                               frames=100, width=320, height=256, fps=10.0, seed=seed)
            for label, config in configs.items():
                paper, full = FrameTable(), FrameTable()
                for profile, table in (("ev76c661", paper), (str(stated), full)):
                    replay(bag, profile, None, weights=weights, config=config, threads=1, progress=False, table=table)
                ok = paper.column("processed").astype(bool) & full.column("processed").astype(bool)
                xi = paper.numbers("xi").astype(np.float64)[ok]
                truth = (paper.numbers("sigma_model").astype(np.float64) - full.numbers("sigma_model").astype(np.float64))[ok]
                big = np.abs(truth) >= 1.0
                ratio = f"{np.median(xi[big] / truth[big]):.2f}" if big.any() else "-"
                print(f"{scenario} seed {seed}, {pct:g} % PRNU hidden, {label:12s}: true xi mean {truth.mean():+.2f} DN (|xi| >= 1 "
                      f"on {big.mean():.0%} of {ok.sum()} frames), read {xi.mean():+.2f} DN, read / true there {ratio}, "
                      f"alarm on {paper.column('alarm').astype(bool)[ok].mean():.0%}; PRNU stated: xi mean "
                      f"{full.numbers('xi').astype(np.float64)[ok].mean():+.2f} DN")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--weights", nargs="+", default=[None], help="full_meta weights (default: the shipped ones)")
    ap.add_argument("--no-lab", action="store_true", help="skip the lab view (about a minute)")
    ap.add_argument("--campaign", type=float, default=None, metavar="PCT", help="also campaigns with a hidden PCT %% PRNU")
    ap.add_argument("--seeds", type=int, nargs="+", default=[21, 22], help="campaign seeds")
    ap.add_argument("--scenario", default="campaign_heldout", choices=["campaign_heldout", "campaign"],
                    help="held-out photographs (matplotlib, PyWavelets) or the tuned-on ones (scikit-image)")
    args = ap.parse_args()
    for w in args.weights:
        print(f"== {w or 'shipped weights'}")
        patches(w)
        if not args.no_lab:
            lab_view(w)
        if args.campaign is not None:
            campaign(w, args.campaign, args.seeds, args.scenario)


if __name__ == "__main__":
    main()
