"""The estimator's tuning sets and their scores: what the confidence head and its limits were chosen on.

Five sets, 600 patches per part (a) / (b) / (c) (``data.PARTS``), never the held-out ones:
- ``tune``: new crops of the training photographs (scikit-image, at their fixed 2x), seeds 3001-3003;
- ``proc``: procedural images of pixel-scale structure only (``procedural.procedural_images``, 30 images),
  seeds 3101-3103;
- ``manmade``: man-made procedural scenes only (``procedural.manmade_images``, 30 images: dead leaves of
  polygons, periodic bars), seeds 3201-3203;
- ``tune_native``: new crops of the training photographs at their native resolution (no downsample),
  seeds 3301-3303;
- ``grain``: grainy procedural pictures only (``procedural.grain_images``, 30 images: near-white grain as
  scene content), seeds 3401-3403.
Generated once into ``--cache`` (``<set>_<part>_p<size>_n600.npz``), then scored with a weights file: xi RMS
and alarm rates over every patch, over the measurable ones, and with clear decisions (``evaluate.score``).

Usage: .venv/bin/python bench/estimator_tuning.py [--weights W.pt] [--sets tune proc manmade tune_native grain]
       [--patch-size 64] [--cache out/estimator_eval] [--json out/tuning.json]
Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from unittest import mock

import numpy as np

from noise_monitor.estimator import data as D
from noise_monitor.estimator.evaluate import score
from noise_monitor.estimator.images import skimage_originals, skimage_photos
from noise_monitor.estimator.inference import load
from noise_monitor.estimator.procedural import grain_images, manmade_images, procedural_images

SETS = {"tune": ((3001, 3002, 3003), lambda rng: skimage_photos()),
        "proc": ((3101, 3102, 3103), lambda rng: procedural_images(rng, 30)),
        "manmade": ((3201, 3202, 3203), lambda rng: manmade_images(rng, 30)),
        "tune_native": ((3301, 3302, 3303), lambda rng: skimage_originals()),
        "grain": ((3401, 3402, 3403), lambda rng: grain_images(rng, 30))}
N = 600


def tuning_set(name: str, part: str, size: int, cache: Path, effects: dict | None = None,
               sensor: dict | None = None) -> dict[str, np.ndarray]:
    """A tuning set's part, from ``cache`` when it has it; ``effects`` / ``sensor``: simulated with that camera
    (a profile's effects and sensor fields, as ``train --profile``) instead of the paper's, not cached."""
    camera = bool(effects or sensor)
    path = cache / f"{name}_{part}_p{size}_n{N}.npz"
    if path.is_file() and not camera:
        return D.load(path)
    seeds, images = SETS[name]
    with mock.patch.object(D, "source_images", lambda split, rng, **_: images(rng)):
        d = D.generate(N, size, seeds["abc".index(part)], "train", D.PARTS[part], progress=False, effects=effects,
                       sensor=sensor)
    if not camera:
        D.save(d, path)
    return d


def _rate(r: dict) -> str:
    if "false_alarm_rate" in r:
        return f"false alarms {100 * r['false_alarm_rate']:.1f} %"
    acc = r.get("hit_rate_accepted")
    return f"hits {100 * r['hit_rate']:.1f} %" + ("" if acc is None else f" (accepted {100 * acc:.0f} %)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--weights", default=None, help="full_meta weights (default: the shipped ones)")
    ap.add_argument("--sets", nargs="+", default=["tune", "proc"], choices=list(SETS))
    ap.add_argument("--patch-size", type=int, default=64)
    ap.add_argument("--cache", type=Path, default=Path("out/estimator_eval"))
    ap.add_argument("--json", type=Path, default=None, help="write the scores here ({set: {part: score}})")
    args = ap.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    est = load("full_meta", device="cpu", weights=args.weights, threads=1)
    scores: dict[str, dict[str, dict]] = {}
    for name in args.sets:
        for part in "abc":
            d = tuning_set(name, part, args.patch_size, args.cache)
            sc = score(est.predict(d["noisy"], D.metas_of(d)), d, part)
            scores.setdefault(name, {})[part] = sc
            line = f"{name} ({part}) {args.patch_size} px: all xi RMS {sc['xi']['rms']:.3f} DN, {_rate(sc)}"
            for key, label in (("declined", "measurable"), ("decided", "+ clear decisions")):
                r = sc.get(key)
                if r is not None:
                    xi = "-" if r["xi"] is None else f"{r['xi']['rms']:.3f} DN"
                    line += f" | {label}: coverage {100 * r['coverage']:.0f} %, xi RMS {xi}, {_rate(r)}"
            print(line, flush=True)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(scores, indent=1))


if __name__ == "__main__":
    main()
