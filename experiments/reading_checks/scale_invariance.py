"""Would the scale invariance of natural images' kurtosis measure the noise where the texture hides it? (tuning data only)

Zoran & Weiss (ICCV 2009, "Scale invariance and noise in natural images"): the kurtosis of a natural image's
band-pass (8x8 DCT) channels is nearly the same in every channel, while white noise of variance s^2 adds variance to
each channel and pulls its kurtosis towards 3: kappa_k - 3 = (kappa - 3) (1 - s^2 / var_k)^2. So sqrt(kappa_k - 3)
is linear in 1 / var_k, and its intercept a and slope b give s^2 = -b / a, with no assumption that any part of the
patch is flat. The camera's noise grows with the intensity; a mixture of variances has a kurtosis of its own, so the
patch is first divided by the model's per-pixel sigma shape (unit RMS over the patch; as the shipped measurement's
inputs are), which makes the noise stationary.

Written before the run (decision rule): the method is a lead for the measurement if, on the training photographs'
patches of parts (a) and (c), its RMS error (DN) is below the classical reference's (the shipped network's starting
point) on the patches the shipped head declines (where texture hides the noise), and below the shipped
sigma_image's there; else it is recorded as not helping and nothing changes. 800 patches per part, data seeds
8201 (a) and 8203 (c).

Usage: .venv/bin/python experiments/reading_checks/scale_invariance.py
"""
from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy.fft import dct

from noise_monitor.estimator import images
from noise_monitor.estimator.data import PARTS, generate, metas_of
from noise_monitor.estimator.features import SIGMA_MODEL_FLOOR, reference_sigma, sigma_shape
from noise_monitor.estimator.inference import load
from noise_monitor.estimator.physics_prior import box_smooth, predict_from_tables

#: DCT block (Zoran & Weiss use 8x8) and the stride of the windows over the patch.
BLOCK, STRIDE = 8, 2


def kurtosis_scale(x: np.ndarray) -> np.ndarray:
    """The white-noise sigma of each patch (N, H, W) from the kurtosis of its AC DCT channels (module docstring)."""
    win = sliding_window_view(x.astype(np.float64), (BLOCK, BLOCK), axis=(1, 2))[:, ::STRIDE, ::STRIDE]
    c = dct(dct(win, axis=-1, norm="ortho"), axis=-2, norm="ortho").reshape(len(x), -1, BLOCK * BLOCK)[:, :, 1:]
    c = c - c.mean(axis=1, keepdims=True)
    var = np.mean(c ** 2, axis=1)
    kurt = np.mean(c ** 4, axis=1) / var ** 2
    y, u = np.sqrt(np.maximum(kurt - 3.0, 0.0)), 1.0 / var
    um, ym = u.mean(axis=1, keepdims=True), y.mean(axis=1, keepdims=True)
    b = np.sum((u - um) * (y - ym), axis=1) / np.sum((u - um) ** 2, axis=1)
    a = ym[:, 0] - b * um[:, 0]
    s2 = np.where(a > 0, -b / np.where(a > 0, a, 1.0), 0.0)
    return np.sqrt(np.clip(s2, SIGMA_MODEL_FLOOR ** 2, var.min(axis=1)))


def shape_of(est, noisy: np.ndarray, metas) -> np.ndarray:
    """The model's per-pixel sigma at the stated metadata, normalised to unit RMS over each patch."""
    prior = est.prior
    uniq = list(dict.fromkeys(metas))
    tables = np.stack([prior.tables(m) for m in uniq])
    group_of = np.array([uniq.index(m) for m in metas])
    return sigma_shape(predict_from_tables(box_smooth(noisy), tables, group_of, with_map=True)["sigma_map"])


def rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e ** 2))) if e.size else float("nan")


def main() -> None:
    est = load("full_meta", device="cpu")
    photos = images.skimage_photos()
    for k, part in enumerate("ac"):
        d = generate(800, 64, 8201 + 2 * k, "train", PARTS[part], progress=False, images=photos)
        noisy, metas = d["noisy"].astype(np.float32), metas_of(d)
        truth = np.asarray(d["truth_sigma_image"], float)
        p = est.predict(noisy, metas)
        shape = shape_of(est, noisy, metas)
        readings = {"reference": reference_sigma(noisy, shape), "shipped sigma_image": np.asarray(p["sigma_image"], float),
                    "kurtosis scale": kurtosis_scale(noisy / shape)}
        acc = np.asarray(p["measurable"], bool)
        print(f"part ({part}): {len(truth)} patches, truth {truth.min():.2f}-{truth.max():.2f} DN, accepted {acc.mean():.2f}")
        for name, r in readings.items():
            e, rel = r - truth, (r - truth) / truth
            print(f"  {name:20s} RMS error all {rms(e):.3f} / accepted {rms(e[acc]):.3f} / declined {rms(e[~acc]):.3f} DN; "
                  f"relative mean {rel.mean():+.3f}, median |rel| all {np.median(np.abs(rel)):.3f}, "
                  f"declined {np.median(np.abs(rel[~acc])):.3f}")


if __name__ == "__main__":
    main()
