"""Where the per-patch xi error sits: the estimator's xi error per source image of a held-out or tuning set.

The held-out photos (``evaluate.HELDOUT_SETS["photos"]`` and ``["photos_native"]``: matplotlib and PyWavelets
images, 2x downsampled / native) and the tuning crops of the training photographs (``estimator_tuning.py``'s
``tune`` and ``tune_native`` sets) are regenerated bit-exact from their
seeds (or read from ``--cache``); each patch's source image is recorded by the generator (``source_index``).
Per image and part: patches, xi RMS and mean error over every patch, and the coverage and xi RMS of the
patches the confidence head accepts (``measurable``), plus the median true sigma_image.

Usage: .venv/bin/python bench/estimator_per_image.py [--sets photos tune (photos_native tune_native)] [--parts a b c] [--patch-size 64]
       [--cache out/estimator_eval] [--weights W.pt]
Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from estimator_tuning import tuning_set

from noise_monitor.estimator import images
from noise_monitor.estimator.data import metas_of
from noise_monitor.estimator.evaluate import heldout, per_image
from noise_monitor.estimator.inference import FullMetaEstimator, PaperEstimator, load

NAMES = {"photos": images.MATPLOTLIB_PHOTOS + images.PYWAVELETS_PHOTOS,
         "photos_native": images.MATPLOTLIB_PHOTOS + images.PYWAVELETS_PHOTOS,
         "tune": images.SKIMAGE_PHOTOS, "tune_native": images.SKIMAGE_PHOTOS}
HELDOUT = ("photos", "photos_native")
N = 600


def dataset(name: str, part: str, size: int, cache: Path, n: int | None = None) -> dict[str, np.ndarray]:
    """The set's data of a part (``n`` patches of a held-out set, default ``N``; a tuning set has ``N``),
    regenerated when the cached copy predates ``source_index``."""
    n = n or N
    def make() -> dict[str, np.ndarray]:
        if name in HELDOUT:
            return heldout(part, n, size, cache, progress=False, heldout_set=name)
        return tuning_set(name, part, size, cache)
    data = make()
    if "source_index" not in data:
        for path in cache.glob(f"{name}_{part}_p{size}_n{n}.npz"):
            path.unlink()
        data = make()
    return data


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if x.size else float("nan")


def add_common_arguments(ap: argparse.ArgumentParser) -> None:
    """The options of the per-image benches: sets, parts, patch size, data cache and weights."""
    ap.add_argument("--sets", nargs="+", default=["photos", "tune"], choices=list(NAMES))
    ap.add_argument("--parts", nargs="+", default=["a", "b", "c"], choices=["a", "b", "c"])
    ap.add_argument("--patch-size", type=int, default=64)
    ap.add_argument("--cache", type=Path, default=Path("out/estimator_eval"))
    ap.add_argument("--weights", default=None, help="full_meta weights (default: the shipped ones)")


def estimator(args: argparse.Namespace) -> FullMetaEstimator | PaperEstimator:
    """The full_meta estimator of ``args.weights`` on one CPU thread (and the data cache made)."""
    args.cache.mkdir(parents=True, exist_ok=True)
    return load("full_meta", device="cpu", weights=args.weights, threads=1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_common_arguments(ap)
    args = ap.parse_args()
    est = estimator(args)
    for name in args.sets:
        for part in args.parts:
            d = dataset(name, part, args.patch_size, args.cache)
            pred = est.predict(d["noisy"], metas_of(d))
            err = pred["xi"] - d["truth_xi"]
            ok = np.asarray(pred["measurable"], dtype=bool)
            print(f"== {name} ({part}), {args.patch_size} px: all xi RMS {rms(err):.3f} DN; accepted {ok.mean():.0%}, "
                  f"xi RMS {rms(err[ok]):.3f} DN")
            print(f"   {'source image':32s} {'n':>4s} {'xi RMS':>7s} {'mean':>7s} {'accepted':>9s} {'acc. RMS':>9s} "
                  f"{'sigma med':>9s}")
            for row in per_image(pred, d, part):
                k = row["image"]
                acc = float("nan") if row["xi_rms_accepted"] is None else row["xi_rms_accepted"]
                sigma = np.median(d["truth_sigma_image"][d["source_index"] == k])
                print(f"   {NAMES[name][k]:32s} {row['patches']:4d} {row['xi_rms']:7.3f} {row['xi_mean_error']:+7.3f} "
                      f"{row['coverage']:9.0%} {acc:9.3f} {sigma:9.2f}", flush=True)


if __name__ == "__main__":
    main()
