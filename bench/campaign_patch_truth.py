"""Where a one-photograph campaign's per-frame xi error comes from: the reading or the model, on the node's patches.

For each held-out photograph and seed, the ``campaign_heldout`` bag whose photo panels all come from that photograph
(as ``bench_stream_detection.py --single-photo``), simulated with a frame hook that keeps every clean frame. Per
frame, the node's own patch selection (``monitor.patches.select_patches``, the node's parameters) on the recorded
image and the estimator on those patches at the stated (here: true) metadata. Per patch, the truth: the recorded
image's noise (std of recorded minus clean) and the model on the clean patch (the estimator's prior, sequential
protocol). Per photograph, over the accepted patches (the confidence head's ``measurable``) and over all: mean and
RMS of sigma_image minus the true noise (the reading), of the image-only reference scale minus the true noise (what
the network corrects), and of sigma_model minus the model on the clean patch (the model's map); the reading's error
is the frame xi's error with the sign flipped.

Usage: .venv/bin/python bench/campaign_patch_truth.py [--seeds 101] [--photos jacksboro_fault_dem.npz ascent]
       [--frames 100] [--params config/node.yaml] [--weights W.pt]
Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from bench_stream_detection import PROFILE

from noise_monitor.bag.reader import BagReader
from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.estimator.features import compact_inputs
from noise_monitor.estimator.images import MATPLOTLIB_PHOTOS, PYWAVELETS_PHOTOS, matplotlib_photos, pywavelets_photos
from noise_monitor.estimator.inference import FullMetaEstimator
from noise_monitor.estimator.user_images import ImageSet
from noise_monitor.monitor.patches import select_patches
from noise_monitor.monitor.runtime import MonitorRuntime
from noise_monitor.physics import CameraMetadata


class KeepClean:
    """Frame hook that records each clean frame and its true metadata, leaving the noisy frame as simulated."""

    truth: dict[str, Any] = {}

    def __init__(self) -> None:
        self.frames: list[tuple[np.ndarray, CameraMetadata]] = []

    def __call__(self, index: int, clean: np.ndarray, noisy: np.ndarray, meta: CameraMetadata) -> np.ndarray:
        self.frames.append((clean.copy(), meta))
        return noisy


def recorded_images(bag: Path) -> list[np.ndarray]:
    """The bag's images (DN) in order, prepared as the node prepares them."""
    reader = BagReader(bag, detect_topics=True)
    try:
        return [np.asarray(f.image_dn, dtype=np.float32) for f in reader.frames(PROFILE)]
    finally:
        reader.close()


def patch_rows(runtime: MonitorRuntime, photo: np.ndarray, seed: int, frames: int) -> np.ndarray:
    """(patches, 7): accepted, sigma_image, reference, true noise, sigma_model, model on the clean patch, gain."""
    hook = KeepClean()
    with tempfile.TemporaryDirectory() as tmp:
        bag = simulate_bag(Path(tmp) / "one_photo.mcap", PROFILE, "campaign_heldout", frames=frames, width=320,
                           height=256, fps=10.0, seed=seed, frame_hook=hook, progress=False,
                           images=ImageSet(("photo",), (photo,), 1))
        images = recorded_images(bag)
    est, size = runtime.estimator, runtime.monitor.patch_size
    if not isinstance(est, FullMetaEstimator):
        raise SystemExit(f"needs full_meta weights (sigma_image and its prior), got {est.name}")
    rows = []
    for (clean, meta), image in zip(hook.frames, images):
        sel = select_patches(image, size, runtime.config)
        patches, cleans = sel.extract(image), sel.extract(clean)
        out = est.predict(patches, meta)
        _, _, phys = compact_inputs(patches, est.prior.tables(meta)[None], np.zeros(len(patches), int))
        truth = np.std(patches.astype(np.float64) - cleans, axis=(1, 2))
        model_clean = est.prior.predict(cleans, [meta] * len(cleans), debias=False)["total"]
        accepted = out.get("measurable", np.ones(len(patches), bool))
        rows.append(np.stack([accepted, out["sigma_image"], phys["reference"], truth, out["sigma_model"], model_clean,
                              np.full(len(patches), meta.gain_db)], axis=1))
    return np.concatenate(rows)


def summary(rows: np.ndarray) -> str:
    ok = rows[:, 0].astype(bool)
    parts = []
    for label, m in (("accepted", ok), ("all", np.ones_like(ok))):
        if not m.any():
            parts.append(f"{label}: none")
            continue
        read, ref, model = (rows[m, 1] - rows[m, 3], rows[m, 2] - rows[m, 3], rows[m, 4] - rows[m, 5])
        parts.append(f"{label} ({m.sum()}): reading {read.mean():+.3f} / {np.sqrt(np.mean(read**2)):.3f}, reference "
                     f"{ref.mean():+.3f} / {np.sqrt(np.mean(ref**2)):.3f}, model {model.mean():+.3f} / "
                     f"{np.sqrt(np.mean(model**2)):.3f}")
    return "; ".join(parts)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    photos = dict(zip(MATPLOTLIB_PHOTOS + PYWAVELETS_PHOTOS, matplotlib_photos() + pywavelets_photos()))
    ap.add_argument("--seeds", type=int, nargs="+", default=[101], help="held-out campaign seeds")
    ap.add_argument("--photos", nargs="+", default=list(photos), choices=list(photos))
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--params", help="node params YAML (default config/node.yaml)")
    ap.add_argument("--weights", help="estimator checkpoint (default: the bundled weights)")
    args = ap.parse_args()
    runtime = MonitorRuntime.from_params_file(args.params, {"profile": PROFILE, "weights": args.weights, "threads": 1})
    print("per patch, mean / RMS (DN): reading = sigma_image - true noise, reference = image-only scale - true noise, "
          "model = sigma_model - model on the clean patch")
    for name in args.photos:
        rows = np.concatenate([patch_rows(runtime, photos[name], seed, args.frames) for seed in args.seeds])
        print(f"{name:32s} {summary(rows)}", flush=True)


if __name__ == "__main__":
    main()
