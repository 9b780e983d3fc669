"""Pixel-scale gratings: does the confidence head decline what the measurement misreads?

Two sets at the suite's camera setting (icx285, 12 dB, 50 ms, 40 degC), simulated with the sequential model:
- ``suite``: the 36 gratings of ``test_confidence.py::test_pixel_scale_gratings_are_declined_or_measured_right``
  (2-6 px periods, 5 / 15 / 40 DN, two random orientations each, on 100 DN; seed 11) and its three flat patches:
  the suite requires every grating declined or read within 0.5 DN of the true xi, the flat ones measurable;
- ``plain``: 64 px crops (four per image) of ``procedural.plain_grating`` images (the training kind: one or two
  1.5-6 px gratings of 2-60 DN on a flat or ramped background), seeds ``--seed`` (images) and ``--seed`` + 1
  (noise): a larger sample of the same question, so that a head's rate of accepted misreads has an interval
  rather than the suite's pass / fail on 36 patches.
Per weights file (side by side in one run): misread (|xi - true xi| > 0.5 DN) among all, accepted, accepted and
misread (rate among the accepted with its Wilson interval), and the accepted misreads' errors against their
predicted errors.

Usage: .venv/bin/python bench/estimator_gratings.py [--weights W.pt ...] [--images 40] [--seed 4242]
Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse

import numpy as np

from noise_monitor.estimator import load
from noise_monitor.estimator.evaluate import rate_ci
from noise_monitor.estimator.procedural import plain_grating_images, sine_grating
from noise_monitor.physics import load_profile

MISREAD_DN = 0.5
SIZE = 64
CROPS = ((10, 10), (100, 150), (180, 40), (60, 90))


def suite_set() -> tuple[list[np.ndarray], list[str], np.random.Generator]:
    """The suite test's 36 gratings and 3 flat patches (clean, DN), their labels, and the generator in the
    state the test simulates the noise with."""
    rng = np.random.default_rng(11)
    clean, labels = [], []
    for period in (2.0, 2.5, 3.0, 4.0, 5.0, 6.0):
        for amp in (5.0, 15.0, 40.0):
            for a in rng.uniform(0, np.pi, 2):
                clean.append(sine_grating(SIZE, period, amp, a, rng.uniform(0, 6.3)))
                labels.append(f"{period:g} px {amp:g} DN")
    levels = (30.0, 100.0, 200.0)
    return clean + [np.full((SIZE, SIZE), v) for v in levels], labels + [f"flat {v:g} DN" for v in levels], rng


def plain_set(images: int, seed: int) -> tuple[list[np.ndarray], list[str], np.random.Generator]:
    """Four 64 px crops of each of ``images`` plain-grating images (clean, DN), labels, the noise generator."""
    clean = [im[y:y + SIZE, x:x + SIZE] for im in plain_grating_images(np.random.default_rng(seed), images, 256)
             for (y, x) in CROPS]
    return clean, [f"image {i // len(CROPS)} crop {i % len(CROPS)}" for i in range(len(clean))], np.random.default_rng(seed + 1)


def score(weights: str | None, clean: list[np.ndarray], labels: list[str], rng: np.random.Generator,
          n_flat: int = 0) -> str:
    """One weights file on one set: the summary lines."""
    meta = load_profile("icx285").metadata(gain_db=12.0, exposure_time_s=0.05, sensor_temperature_c=40.0)
    est = load("full_meta", device="cpu", weights=weights, threads=1)
    sims = [est.prior.model.simulate(c.astype(np.float32), meta, rng, mode="sequential") for c in clean]
    out = est.predict(np.stack([s[0] for s in sims]), meta)
    err = out["xi"] - (out["sigma_model"] - np.array([s[1]["total"] for s in sims]))
    n = len(clean) - n_flat
    acc, wrong = out["measurable"][:n], np.abs(err[:n]) > MISREAD_DN
    bad = np.flatnonzero(acc & wrong)
    lines = [f"  misread {wrong.sum()} of {n}, accepted {acc.sum()}, accepted and misread {len(bad)}"
             + (f" ({100 * len(bad) / acc.sum():.1f} % of the accepted, 95 % CI "
                f"{', '.join(f'{100 * v:.1f}' for v in rate_ci(wrong[acc]))} %)" if acc.any() else "")]
    if n_flat:
        lines[0] += f"; flat patches measurable {int(out['measurable'][n:].sum())} of {n_flat}"
    lines += [f"    {labels[i]}: xi error {err[i]:+.2f} DN at predicted {out['sigma_image_error'][i]:.2f} DN"
              for i in bad[:12]]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--weights", nargs="+", default=[None], help="full_meta weights (default: the shipped ones)")
    ap.add_argument("--images", type=int, default=40, help="plain-grating images (four crops each)")
    ap.add_argument("--seed", type=int, default=4242, help="seed of the plain-grating images (noise: seed + 1)")
    args = ap.parse_args()
    for w in args.weights:
        print(f"== {w or 'shipped weights'}")
        print("suite (36 gratings, 3 flat patches):")
        clean, labels, rng = suite_set()
        print(score(w, clean, labels, rng, n_flat=3))
        print(f"plain gratings ({4 * args.images} crops of {args.images} images, seed {args.seed}):")
        print(score(w, *plain_set(args.images, args.seed)))


if __name__ == "__main__":
    main()
