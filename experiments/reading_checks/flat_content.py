"""How sigma_image reads content without texture, and the held-out photos by their clipped pixels.

1. Synthetic content with Gaussian noise of the held-out photos' (c) patches' true levels, each with those patches'
   metadata: one level (128 DN), a sharp or soft step, a ramp (1 DN/px), a disk, smooth sinusoids; the relative error
   of sigma_image against the empirical noise per level band (seeded, 400 patches per content).
2. Per held-out photograph (``photos``, parts (a) and (c)): the relative error of sigma_image on the patches with more
   / at most 1 % of their pixels at 0 or 255 DN (the node's ``max_clipped_fraction``: it never measures the former).
3. The held-out photos' per-patch scores (``evaluate.score``, clear decisions) on every patch and on the patches the
   node's selection accepts (``monitor.patches``' black / saturated / flat rules with the default parameters).

Usage: .venv/bin/python experiments/reading_checks/flat_content.py
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
import estimator_per_image as epi  # noqa: E402

from noise_monitor.estimator.data import metas_of  # noqa: E402
from noise_monitor.estimator.evaluate import score  # noqa: E402
from noise_monitor.monitor.config import MonitorConfig  # noqa: E402
from noise_monitor.monitor.patches import _HIGH, _LOW, _reject_reasons  # noqa: E402

CACHE = Path("out/estimator_eval")
YY, XX = np.mgrid[0:64, 0:64].astype(np.float32)


def content(kind: str, rng: np.random.Generator) -> np.ndarray:
    """One 64 x 64 clean patch of ``kind``."""
    angle, offset = rng.uniform(0, np.pi), rng.uniform(-10, 10)
    across = (XX - 32) * np.cos(angle) + (YY - 32) * np.sin(angle) - offset
    if kind == "one level":
        return np.full((64, 64), 128.0)
    if kind == "sharp step":
        return np.where(across > 0, 90.0, 150.0)
    if kind == "soft step":
        return 90.0 + 60.0 / (1 + np.exp(-across / 0.5))
    if kind == "ramp":
        return 128.0 + across
    if kind == "disk":
        return np.where((XX - rng.uniform(20, 44)) ** 2 + (YY - rng.uniform(20, 44)) ** 2 < rng.uniform(5, 15) ** 2, 80.0, 140.0)
    return 120 + 30 * np.sin(XX / rng.uniform(5, 12) + rng.uniform(0, 6)) * np.cos(YY / rng.uniform(5, 12))


def main() -> None:
    est = epi.load("full_meta", device="cpu", weights=None, threads=1)
    d = epi.dataset("photos", "c", 64, CACHE, 3000)
    metas, levels = metas_of(d)[:400], np.asarray(d["truth_sigma_image"], float)[:400]
    rng = np.random.default_rng(11)
    print("1. content without texture: relative error of sigma_image, mean / std (measurable share)")
    for kind in ("one level", "sharp step", "soft step", "ramp", "disk", "sinusoids"):
        clean = np.stack([content(kind, rng) for _ in metas]).astype(np.float32)
        noisy = np.clip(np.rint(clean + rng.normal(size=clean.shape) * levels[:, None, None]), 0, 255).astype(np.float32)
        truth = (noisy - clean).reshape(len(clean), -1).std(axis=1)
        p = est.predict(noisy, metas)
        rel = (np.asarray(p["sigma_image"], float) - truth) / truth
        print(f"   {kind:10s} {rel.mean():+.3f} / {rel.std():.3f} ({np.mean(p['measurable']):.2f})")
    print("2. held-out photos: relative error of sigma_image by clipped share, mean (patches)")
    for part in "ac":
        d = epi.dataset("photos", part, 64, CACHE, 3000)
        noisy = d["noisy"].astype(np.float32)
        p = est.predict(noisy, metas_of(d))
        truth = np.asarray(d["truth_sigma_image"], float)
        rel = (np.asarray(p["sigma_image"], float) - truth) / truth
        clipped = ((noisy <= _LOW) | (noisy >= _HIGH)).reshape(len(noisy), -1).mean(axis=1) > MonitorConfig().max_clipped_fraction
        for k, name in enumerate(epi.NAMES["photos"]):
            on = d["source_index"] == k
            cells = [f"{lab} {rel[on & sel].mean():+.3f} ({int((on & sel).sum())})" for lab, sel in
                     (("> 1 % clipped", clipped), ("<= 1 %", ~clipped)) if (on & sel).any()]
            print(f"   ({part}) {name:32s} " + ", ".join(cells))
    selected_scores(est)


def usable(noisy: np.ndarray, cfg: MonitorConfig) -> np.ndarray:
    """Per patch: the node's selection would measure it (``patches._reject_reasons`` on each patch's statistics as
    the selection computes them over a frame; no black level)."""
    n = len(noisy)
    flat = noisy.reshape(n, -1)
    equal = ((noisy[:, :, 1:] == noisy[:, :, :-1]).reshape(n, -1).sum(axis=1)
             + (noisy[:, 1:] == noisy[:, :-1]).reshape(n, -1).sum(axis=1)) / (2.0 * flat.shape[1])
    stats = {"mean": flat.mean(axis=1), "low": (flat <= _LOW).mean(axis=1), "high": (flat >= _HIGH).mean(axis=1),
             "equal": equal}
    return _reject_reasons(stats, cfg) < 0


def selected_scores(est) -> None:
    """Part 3 of the module docstring."""
    print("3. held-out photos, clear decisions: every patch / the patches the node's selection accepts")
    for part in "abc":
        d = epi.dataset("photos", part, 64, CACHE, 3000)
        p = est.predict(d["noisy"], metas_of(d))
        n = len(d["noisy"])
        for label, keep in (("every patch", np.ones(n, bool)), ("selected", usable(d["noisy"].astype(np.float32), MonitorConfig()))):
            cut = {k: (np.asarray(v)[keep] if np.ndim(v) >= 1 and len(v) == n else v) for k, v in {**d, **p}.items()}
            sc = score({k: cut[k] for k in p}, {k: cut[k] for k in d}, part)
            rate = sc["decided"]["false_alarm_rate" if part == "a" else "hit_rate"]
            print(f"   ({part}) {label:11s} {int(keep.sum()):5d} patches: accepted xi RMS {sc['declined']['xi']['rms']:.3f} DN, "
                  f"{'false alarms' if part == 'a' else 'hits'} {100 * rate:.1f} %")


if __name__ == "__main__":
    main()
