"""The confidence head's generalisation across photographs, on the training photographs alone.

The 19 scikit-image photographs in four groups (index mod 4). Per group, a head is trained (measurement frozen:
the shipped weights' ``init``, ``--confidence`` as in the shipped head's recipe, 24,000 patches, 3,000 steps) on
data whose photographs exclude the group, and a control head on the same recipe with every photograph; both are
scored on the tuning crops (``bench/estimator_tuning.py``'s ``tune`` set, 600 per part) of the group's images.
If the left-out heads read as well as the control, the head carries over to a photograph it was not trained on
and the held-out photos' gap is their content's; if not, the tuning crops are in-sample for the head.

Usage: .venv/bin/python experiments/head_generalization/leave_images_out.py [--out out/head_loio] [--patches 24000]
       [--recipe shipped|measurement] [--no-control] [--physics-inputs]
Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from unittest import mock

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))
from estimator_per_image import rms  # noqa: E402
from estimator_tuning import tuning_set  # noqa: E402

from noise_monitor.estimator import data as D  # noqa: E402
from noise_monitor.estimator import images  # noqa: E402
from noise_monitor.estimator import train as training  # noqa: E402
from noise_monitor.estimator.images import Imagery  # noqa: E402
from noise_monitor.estimator.inference import load, weights_path  # noqa: E402
from noise_monitor.estimator.train import TrainSettings, train  # noqa: E402

GROUPS = 4
#: the shipped head's imagery, and the measurement's own (S7: photographs also at native scale, rotated, JPEG)
RECIPES = {"shipped": Imagery(photo_scales=(1.5, 4.0), manmade=96, charts=48, gratings=72),
           "measurement": Imagery(photo_scales=(1.0, 4.0), photo_native=0.25, photo_rotate=0.5, jpeg=0.2, manmade=96,
                                  charts=48, gratings=72)}


def physics_inputs_only(net, data, dev, n: int = 4096) -> None:  # noqa: ANN001
    """``train.fit_confidence_inputs``, then the trunk's pooled features and the MLP's last hidden layer masked
    out of the head (standardised to 0: an infinite scale): the head sees the scalars, mu and the evidence."""
    fit_inputs(net, data, dev, n)
    cfg = net.cfg
    learned = list(range(cfg.n_pooled)) + list(range(cfg.n_pooled + cfg.n_scalars, cfg.n_pooled + cfg.n_scalars + cfg.hidden[-1]))
    net.conf_std[learned] = 1e12


fit_inputs = training.fit_confidence_inputs


def head(out: Path, name: str, keep: list[int] | None, patches: int, seed: int, recipe: Imagery,
         physics_only: bool = False) -> Path:
    """A head trained on the recipe's data with only the photographs ``keep`` (None: all)."""
    weights = out / name / "full_meta.pt"
    if weights.is_file():
        return weights
    originals = images.skimage_originals()
    subset = originals if keep is None else [originals[i] for i in keep]
    with mock.patch.object(images, "skimage_originals", lambda: subset):
        data = D.generate(patches, 64, seed, "train", D.Scheme(unexpected_shapes=(0.0, 0.5, 1.0)), progress=False,
                          photo_variants=3, procedural=160, imagery=recipe)
    settings = TrainSettings(variant="full_meta", steps=3000, batch=256, lr=0.003, seed=0, confidence=True)
    with mock.patch.object(training, "fit_confidence_inputs", physics_inputs_only if physics_only else fit_inputs):
        train(settings, data, out / name, device="cpu", threads=2, progress=False, init=weights_path("full_meta"))
    return weights


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "out/head_loio")
    ap.add_argument("--patches", type=int, default=24000)
    ap.add_argument("--recipe", choices=list(RECIPES), default="shipped", help="the heads' training imagery")
    ap.add_argument("--no-control", action="store_true", help="only the left-out heads")
    ap.add_argument("--physics-inputs", action="store_true",
                    help="heads that see only the scalars, the measurement and the evidence (not the learned features)")
    args = ap.parse_args()
    n, recipe = len(images.SKIMAGE_PHOTOS), RECIPES[args.recipe]
    out = args.out / args.recipe if args.recipe != "shipped" else args.out
    out = out / "physics_inputs" if args.physics_inputs else out
    control = None if args.no_control else load("full_meta", device="cpu",
                                                weights=head(out, "all", None, args.patches, 7200, recipe,
                                                             args.physics_inputs))
    sets = {p: tuning_set("tune", p, 64, ROOT / "out/estimator_eval") for p in "abc"}
    metas = {p: D.metas_of(d) for p, d in sets.items()}
    rows = {"control (all photos)": {p: [] for p in "abc"}, "left out": {p: [] for p in "abc"}}
    for g in range(GROUPS):
        left = [i for i in range(n) if i % GROUPS == g]
        est = load("full_meta", device="cpu",
                   weights=head(out, f"without_{g}", [i for i in range(n) if i % GROUPS != g], args.patches, 7201 + g,
                                recipe, args.physics_inputs))
        for p, d in sets.items():
            m = np.isin(d["source_index"], left)
            for label, e in (("control (all photos)", control), ("left out", est)):
                if e is None:
                    continue
                o = e.predict(d["noisy"][m], [metas[p][i] for i in np.flatnonzero(m)])
                rows[label][p].append((o, d["truth_xi"][m]))
        print(f"group {g} ({', '.join(images.SKIMAGE_PHOTOS[i] for i in left)}) done", flush=True)
    for label, parts in rows.items():
        if not parts["a"]:
            continue
        cells = []
        for p, chunks in parts.items():
            acc = np.concatenate([o["measurable"] for o, _ in chunks])
            err = np.concatenate([o["xi"] - t for o, t in chunks])
            cell = f"({p}) coverage {acc.mean():.2f}, accepted xi RMS {rms(err[acc]):.3f}"
            if p == "a":
                xi = np.concatenate([o["xi"] for o, _ in chunks])
                cell += f", false alarms {100 * np.mean(acc & (np.abs(xi) > 1)):.1f} %"
            cells.append(cell)
        print(f"{label:22s} " + "; ".join(cells))


if __name__ == "__main__":
    main()
