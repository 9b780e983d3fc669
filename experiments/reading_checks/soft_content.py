"""Does the reading under-read soft content? Training photographs blurred before the noise (tuning data only).

The MRI and Minduka held-out photographs read 7-11 % low (`flat_content.py`). If soft content (structure at the
scale of several pixels and none at one) were what the reading under-reads, the training photographs blurred by a
Gaussian of 1-3 px would read as low. Per blur: 600 patches of parts (a) and (c) (data seeds 8101 + 10 x blur + part),
the mean / std of sigma_image's relative error over every patch and the accepted ones, the accepted share and xi RMS.

Usage: .venv/bin/python experiments/reading_checks/soft_content.py
"""
from __future__ import annotations

import cv2
import numpy as np

from noise_monitor.estimator import images
from noise_monitor.estimator.data import PARTS, generate, metas_of
from noise_monitor.estimator.inference import load


def main() -> None:
    est = load("full_meta", device="cpu")
    photos = images.skimage_photos()
    for blur in (0, 1, 2, 3):
        clean = [cv2.GaussianBlur(p, (0, 0), blur) if blur else p for p in photos]
        for k, part in enumerate("ac"):
            d = generate(600, 64, 8101 + 10 * blur + k, "train", PARTS[part], progress=False, images=clean)
            p = est.predict(d["noisy"].astype(np.float32), metas_of(d))
            truth = np.asarray(d["truth_sigma_image"], float)
            rel = (np.asarray(p["sigma_image"], float) - truth) / truth
            acc = np.asarray(p["measurable"], bool)
            xi = np.asarray(p["xi"], float) - np.asarray(d["truth_xi"], float)
            print(f"blur {blur} px ({part}): every patch {rel.mean():+.3f} / {rel.std():.3f}; accepted {acc.mean():.2f}: "
                  f"{rel[acc].mean():+.3f} / {rel[acc].std():.3f}, xi RMS {np.sqrt(np.mean(xi[acc] ** 2)):.3f} DN")


if __name__ == "__main__":
    main()
