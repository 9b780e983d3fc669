"""`noise-monitor evaluate`: the held-out benchmark of the estimators, classical peers and the sweep; with
``--images``, the same parts drawn from a user's own clean images, scored per image too."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from .card import declined_alarms, rate_cell, rms_cell, write_card
from .data import PARTS
from .evaluate import (
    HELDOUT_SETS,
    heldout,
    image_set_data,
    paired_difference,
    peer_predictions,
    per_image,
    score,
    sensitivity_sweep,
    timed_predict,
)
from .inference import NAMES, WEIGHTS_DIR, load
from .physics_prior import PhysicsPrior
from .user_images import ImageSet, load_image_set, own_noise_floor
from .user_images_plot import plot_image_set

#: The ``--heldout`` name of a user's own images (``--images``).
IMAGES = "images"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--variants", nargs="+", default=None, choices=NAMES,
                   help="estimators to evaluate (default: every one with weights)")
    p.add_argument("--weights-dir", type=Path, default=WEIGHTS_DIR)
    p.add_argument("--compare", nargs="+", default=[], metavar="LABEL=WEIGHTS",
                   help="also evaluate these full_meta weights in the same run, reported as LABEL (e.g. "
                        "full_meta_old=old/full_meta.pt: old and new weights side by side on the same data), each "
                        "also minus full_meta paired on the same patches, with 95 %% intervals")
    p.add_argument("--patches", type=int, default=600, help="held-out patches per part")
    p.add_argument("--patch-size", type=int, nargs="+", default=None,
                   help="evaluate every variant on patches of this size, one benchmark per size given (default: each "
                        "variant's training size; the paper's protocol is 128)")
    p.add_argument("--parts", nargs="+", default=list(PARTS), choices=list(PARTS))
    p.add_argument("--heldout", nargs="+", default=None, choices=list(HELDOUT_SETS),
                   help="held-out sets: benchmark (matplotlib images + dead leaves), photos (matplotlib + PyWavelets "
                        "images only, 2x downsampled) and/or photos_native (the same at native resolution); one run per "
                        "set and patch size (default: benchmark, or none with --images)")
    p.add_argument("--images", nargs="+", type=Path, default=None, metavar="PATH",
                   help="also (or, without --heldout, only) evaluate on your own clean images: files or directories of "
                        "PNG / JPEG / TIFF / BMP / PGM / NPY images of the scenes your camera sees; scored per image too, "
                        "with each image's own noise floor")
    p.add_argument("--image-downsample", type=int, default=2,
                   help="area-downsample --images by this factor first (1-4; default 2, as the bundled photographs)")
    p.add_argument("--plot", type=Path, default=None, metavar="PNG",
                   help="with --images: a plot of the noise read against the noise put in, per image and part")
    p.add_argument("--no-peers", action="store_true", help="skip the classical peers")
    p.add_argument("--no-sweep", action="store_true", help="skip the metadata sensitivity sweep")
    p.add_argument("--cache", type=Path, default=Path("out/estimator_eval"), help="held-out data cache directory")
    p.add_argument("--device", default="auto")
    p.add_argument("--json", type=Path, default=None, help="write the results here")
    p.add_argument("--cards", action="store_true", help="write the model card <weights-dir>/<variant>.md of each variant")


def run(args: argparse.Namespace) -> int:
    if args.patches < 10:
        raise ValueError("--patches must be >= 10")
    if any(size < 16 for size in args.patch_size or []):
        raise ValueError("--patch-size must be >= 16")
    if args.images and args.cards:
        raise ValueError("--cards writes the model cards from the bundled held-out sets; leave out --images")
    if args.plot and not args.images:
        raise ValueError("--plot draws the per-image figures of --images; give --images")
    if args.cards and args.weights_dir.resolve() == WEIGHTS_DIR.resolve():
        # the shipped cards state the full benchmark's figures (until 2026-12-04 any run's were written over them)
        small = [flag for flag, given in (("--patches below 600", args.patches < 600),
                                          ("--parts " + " ".join(args.parts), list(args.parts) != list(PARTS)),
                                          ("--no-sweep", args.no_sweep)) if given]
        if small:
            raise ValueError(f"--cards writes the shipped model cards from the full benchmark; {', '.join(small)} would "
                             "put a smaller run's figures in them (give --weights-dir for a copy's)")
    if args.json is not None and args.json.is_dir():
        raise ValueError(f"--json {args.json} is a folder; give a file path")
    sets = args.heldout or ([] if args.images else ["benchmark"])
    names = args.variants or [n for n in NAMES if (args.weights_dir / f"{n}.pt").is_file()]
    if not names:
        raise FileNotFoundError(f"no estimator weights in {args.weights_dir}")
    estimators = {n: load(n, args.device, weights=args.weights_dir / f"{n}.pt") for n in names}
    labels = compared(args.compare, names)
    for label, path in labels.items():
        estimators[label] = load("full_meta", args.device, weights=path)
    for label, est in estimators.items():  # the held-out sets are made with the paper's sources alone
        effects = sorted(getattr(est, "trained_effects", None) or {})
        if effects and args.cards:
            raise ValueError(f"--cards: {label} was fine-tuned for a camera with {', '.join(effects)}, which the "
                             "benchmark's data lack: its figures here are biased, not the weights' own")
        if effects:
            print(f"note: {label} was fine-tuned for a camera with {', '.join(effects)}; the held-out sets hold none "
                  "of them, so its sigma_model and xi here are biased (evaluate it on that camera's data)",
                  file=sys.stderr)
    largest = max(args.patch_size or [e.patch_size for e in estimators.values()])
    args.image_set = load_image_set(args.images, args.image_downsample, largest) if args.images else None
    runs = {_label(size, hs): evaluate(estimators, args, size, hs, list(labels))
            for hs in sets + ([IMAGES] if args.images else []) for size in args.patch_size or [None]}
    for label, results in runs.items():
        print(f"== patches {label}\n{_table(results)}")
        if results["heldout"] == IMAGES:
            print(_image_table(results))
            if args.plot:
                print(f"plot: {_plot_images(args, estimators[BASELINE if BASELINE in estimators else names[0]], results, len(runs))}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(next(iter(runs.values())) if len(runs) == 1 else {"runs": runs}, indent=2))
    if args.cards:
        sizes = f" --patch-size {' '.join(map(str, args.patch_size))}" if args.patch_size else ""
        held = f" --heldout {' '.join(sets)}" if sets != ["benchmark"] else ""
        command = f"noise-monitor evaluate --patches {args.patches} --parts {' '.join(args.parts)}{sizes}{held}"
        for name in names:
            print(f"model card: {write_card(name, args.weights_dir, runs, command)}")
    return 0


#: What ``--compare`` weights are compared with, patch by patch.
BASELINE = "full_meta"


def compared(specs: list[str], names: list[str]) -> dict[str, Path]:
    """``LABEL=WEIGHTS`` pairs of ``--compare`` (labels distinct from the evaluated names; files must exist)."""
    out: dict[str, Path] = {}
    for spec in specs:
        label, sep, path = spec.partition("=")
        if not sep or not label or not path:
            raise ValueError(f"--compare wants LABEL=WEIGHTS, got {spec!r}")
        if label in names or label in out or label in NAMES:
            raise ValueError(f"--compare label {label!r} is already used; choose another")
        if not Path(path).is_file():
            raise FileNotFoundError(f"--compare: weights {path} not found")
        out[label] = Path(path)
    return out


def _label(size: int | None, heldout_set: str) -> str:
    return ("native" if size is None else f"{size}x{size}") + ("" if heldout_set == "benchmark" else f", {heldout_set}")


def evaluate(estimators: dict, args: argparse.Namespace, patch_size: int | None, heldout_set: str = "benchmark",
             compared_labels: list[str] | None = None) -> dict:
    """Scores of every estimator (and the peers) on each part of a held-out set, the throughput and (on
    the benchmark) full_meta's metadata sweep; each of ``compared_labels`` (``--compare``) also minus the
    evaluated full_meta, paired on the same patches (``minus_full_meta``)."""
    size_of = {n: patch_size or e.patch_size for n, e in estimators.items()}
    results: dict = {"heldout": heldout_set, "patches_per_part": args.patches, "patch_size": size_of, "parts": {},
                     "ms_per_patch": {}}
    prior = PhysicsPrior()
    image_set: ImageSet | None = None
    if heldout_set == IMAGES:
        image_set = args.image_set
        if image_set is None:
            raise ValueError("the images set needs --images")
        results["images"] = [{"name": name, "size": [int(im.shape[1]), int(im.shape[0])],
                              "own_noise_floor_dn": round(own_noise_floor(im, min(size_of.values())), 3)}
                             for name, im in zip(image_set.names, image_set.images)]
    for part in args.parts:
        results["parts"][part] = {}
        for size in sorted(set(size_of.values())):
            data = (heldout(part, args.patches, size, args.cache, heldout_set=heldout_set) if image_set is None
                    else image_set_data(part, args.patches, size, image_set, args.cache))
            preds = {}
            for name, est in estimators.items():
                if size_of[name] != size:
                    continue
                preds[name], dt = timed_predict(est, data)
                results["parts"][part][name] = score(preds[name], data, part)
                if image_set is not None and "xi" in preds[name]:
                    results["parts"][part][name]["per_image"] = per_image(preds[name], data, part,
                                                                          len(image_set.names))
                results["ms_per_patch"].setdefault(name, []).append(1000.0 * dt / len(data["noisy"]))
            for label in compared_labels or []:
                if label in preds and BASELINE in preds:
                    results["parts"][part][label][f"minus_{BASELINE}"] = paired_difference(
                        preds[label], preds[BASELINE], data, part)
            if not args.no_peers:
                for peer, pred in peer_predictions(data, prior).items():
                    results["parts"][part][f"{peer}@{size}"] = score(pred, data, part)
    results["ms_per_patch"] = {k: round(float(np.mean(v)), 3) for k, v in results["ms_per_patch"].items()}
    if not args.no_sweep and "full_meta" in estimators and heldout_set == "benchmark":
        fm = estimators["full_meta"]
        results["sensitivity_full_meta"] = sensitivity_sweep(
            lambda x, m: fm.predict(x, m)["total"][0], size_of["full_meta"], model=fm.prior.model)
    return results


def _plot_images(args: argparse.Namespace, estimator, results: dict, n_runs: int) -> Path:
    """``--plot`` of one ``--images`` run (a file per patch size when there are several runs)."""
    size = results["patch_size"][estimator.name]
    data = {part: image_set_data(part, args.patches, size, args.image_set, args.cache, progress=False)
            for part in args.parts}
    floors = [im["own_noise_floor_dn"] for im in results["images"]]
    path = args.plot if n_runs == 1 else args.plot.with_name(f"{args.plot.stem}_{size}{args.plot.suffix}")
    return plot_image_set(estimator, args.image_set, data, floors, path)


def _image_table(results: dict) -> str:
    """Per image of ``--images``: each estimator's xi error, the accepted share and their error, the alarm rates
    (declined patches never alarming / with the clear decisions) and the image's own noise floor."""
    info = results["images"]
    lines = [f"per image ({len(info)}; own floor: the clean image's own noise-like content, DN, counted as scene by "
             "the truth: where it is near the noise, the error is the image's)"]
    for part, rows in results["parts"].items():
        rate = "false alarms" if part == "a" else "hits"
        for name, r in rows.items():
            if "per_image" not in r:
                continue
            lines.append(f"part ({part}) {name}: image | patches | xi RMS / mean error DN | accepted | accepted xi RMS DN "
                         f"| {rate}: declined never alarm / + clear decisions | own floor DN")
            for row in r["per_image"]:
                im = info[row["image"]]
                if not row["patches"]:
                    lines.append(f"  {im['name']:<30}     0 | no patch drawn (raise --patches) | own floor "
                                 f"{im['own_noise_floor_dn']:.2f}")
                    continue
                acc = "-" if row.get("coverage") is None else f"{100 * row['coverage']:.0f} %"
                acc_rms = "-" if row.get("xi_rms_accepted") is None else f"{row['xi_rms_accepted']:.3f}"
                key = "false_alarm_rate" if part == "a" else "hit_rate"
                alarm = " / ".join("-" if row.get(f"{key}_{rule}") is None else f"{100 * row[f'{key}_{rule}']:.1f} %"
                                   for rule in ("accepted", "decided"))
                lines.append(f"  {im['name']:<30} {row['patches']:5d} | {row['xi_rms']:.3f} / {row['xi_mean_error']:+.3f} "
                             f"| {acc} | {acc_rms} | {alarm} | {im['own_noise_floor_dn']:.2f}")
    return "\n".join(lines)


def _differences(diff: dict[str, list[float]]) -> str:
    """Paired differences with their intervals (DN; rates in points)."""
    names = {"xi_rms": ("xi RMS", 1.0, "DN"), "xi_rms_accepted": ("on accepted", 1.0, "DN"),
             "false_alarm_rate": ("false alarms", 100.0, "pt"), "hit_rate": ("hits", 100.0, "pt")}
    cells = []
    for key, (label, scale, unit) in names.items():
        if key in diff:
            d, lo, hi = (scale * v for v in diff[key])
            cells.append(f"{label} {d:+.3f} [{lo:+.3f}, {hi:+.3f}] {unit}" if unit == "DN"
                         else f"{label} {d:+.1f} [{lo:+.1f}, {hi:+.1f}] {unit}")
    return ", ".join(cells)


def _table(results: dict) -> str:
    lines = []
    for part, rows in results["parts"].items():
        lines.append(f"part ({part})  RMS in DN: {'pn':>6} {'dcsn':>6} {'rn':>6} {'s_img':>6} {'xi':>6}  alarms")
        for name, r in rows.items():
            cells = " ".join(f"{r[k]['rms']:6.3f}" if k in r else "     -" for k in ("pn", "dcsn", "rn", "sigma_image", "xi"))
            rate = r.get("false_alarm_rate", r.get("hit_rate"))
            ci = r.get("false_alarm_ci95", r.get("hit_ci95"))
            by_image = r.get("false_alarm_ci95_images", r.get("hit_ci95_images"))
            xi_ci, xi_images = r.get("xi", {}).get("rms_ci95"), r.get("xi", {}).get("rms_ci95_images")
            xi_cell = "" if not xi_ci else f"  (xi RMS {xi_ci[0]:.3f}-{xi_ci[1]:.3f}" + (
                f"; images {xi_images[0]:.3f}-{xi_images[1]:.3f})" if xi_images else ")")
            lines.append(f"  {name:<28} {cells}  {'' if rate is None else rate_cell(rate, ci, by_image)}{xi_cell}")
            d = r.get("declined")
            if d is not None:
                lines.append(f"  {'  declined unmeasurable':<28} coverage {100 * d['coverage']:.1f} %, xi RMS on accepted "
                             f"{rms_cell(d['xi'])}, {declined_alarms(d)}")
            c = r.get("decided")
            if c is not None:
                lines.append(f"  {'  + clear decisions':<28} coverage {100 * c['coverage']:.1f} %, {declined_alarms(c)}")
            diff = r.get(f"minus_{BASELINE}")
            if diff:
                lines.append(f"  {f'  minus {BASELINE}, paired':<28} {_differences(diff)}")
    sens = results.get("sensitivity_full_meta")
    if sens:
        lines.append(f"sensitivity sweep (full_meta): max |estimator - model| = {sens['max_abs_diff_dn']} DN, "
                     f"{sens['flagged_cells']} cells > 1 DN")
    return "\n".join(lines)
