"""Probes of why the confidence head accepts misread patches on the held-out photos (issue 15, per patch).

Subcommands (shipped weights, 64 px; data from ``bench/``'s cached sets, regenerated bit-exact when missing):
- ``ood``: a Mahalanobis out-of-distribution gate on the head's standardised inputs (with the texture evidence),
  fitted on 10,000 training-kind patches (the shipped head's recipe, data seed 7001), thresholds at quantiles of
  2,000 more; coverage and accepted xi RMS with and without it, and the AUC of the distance for accepted patches
  misread by > 0.5 DN (1: misread ones lie farther out).
- ``oracle``: heads trained on the held-out photos' *own* patches (never shipped), random 5-fold and
  leave-one-image-out, against the shipped head: is the tell of a misread patch in the head's inputs, and does it
  carry over to an image not trained on?
- ``truth``: how far the benchmark's truth (the paper's sequential protocol: per-effect clipped stds in quadrature)
  is from the noise actually in each patch, std(noisy - clean), per source image.
- ``jpeg``: the training photographs JPEG-compressed at their native resolution (quality 40-95) and then downsampled
  2x, scored like ``bench/estimator_tuning.py``'s sets (seeds 3501-3503).

Usage: .venv/bin/python experiments/head_generalization/probe.py {ood,oracle,truth,jpeg} [--sets ...]
Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))
import estimator_tuning as tuning  # noqa: E402
from estimator_per_image import dataset, rms  # noqa: E402
from scipy.stats import mannwhitneyu  # noqa: E402

from noise_monitor.estimator import data as D  # noqa: E402
from noise_monitor.estimator import images  # noqa: E402
from noise_monitor.estimator.features import compact_inputs  # noqa: E402
from noise_monitor.estimator.images import Imagery  # noqa: E402
from noise_monitor.estimator.inference import group_by_meta, is_measurable, load  # noqa: E402

CACHE = ROOT / "out/estimator_eval"
HELDOUT_N = 3000


def load_set(name: str, part: str) -> dict[str, np.ndarray]:
    if name in ("photos", "photos_native"):
        return dataset(name, part, 64, CACHE, HELDOUT_N)
    return tuning.tuning_set(name, part, 64, CACHE)


class Features:
    """The shipped estimator's outputs and its confidence head's standardised inputs (with the evidence)."""

    def __init__(self) -> None:
        self.est = load("full_meta", device="cpu", backend="torch")
        self.net = self.est.net.eval()

    def __call__(self, d: dict[str, np.ndarray]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        x, ms = d["noisy"].astype(np.float32), D.metas_of(d)
        out = self.est.predict(x, ms)
        rows = []
        for i in range(0, len(x), 2000):
            groups = group_by_meta(ms[i:i + 2000])
            tables = np.stack([self.est.prior.tables(m) for m in groups])
            group_of = np.empty(len(x[i:i + 2000]), dtype=np.int64)
            for g, idx in enumerate(groups.values()):
                group_of[idx] = g
            trend, spectral = self.est._extra_scalars
            maps, scalars, phys = compact_inputs(x[i:i + 2000], tables, group_of, evidence=True, upper=True,
                                                 trend=trend, spectral=spectral)
            with torch.inference_mode():
                _, z = self.net.confidence_inputs(torch.from_numpy(maps), torch.from_numpy(scalars))
                z = torch.cat([z, torch.from_numpy(phys["evidence"])], dim=1)
                rows.append(((z - self.net.conf_mean) / self.net.conf_std).numpy())
        return np.concatenate(rows).astype(np.float64), out


def ood(sets: list[str]) -> None:
    feats = Features()
    path = CACHE / "trainkind_s7001_n12000.npz"
    if path.is_file():
        d = D.load(path)
    else:
        imagery = Imagery(photo_scales=(1.5, 4.0), manmade=96, charts=48, gratings=72)
        d = D.generate(12000, 64, 7001, "train", D.Scheme(unexpected_shapes=(0.0, 0.5, 1.0)), progress=False,
                       photo_variants=3, procedural=160, imagery=imagery)
        D.save(d, path)
    f, _ = feats(d)
    fit, cal = f[:10000], f[10000:]
    mean = fit.mean(axis=0)
    cov = np.cov(fit, rowvar=False)
    cov = 0.9 * cov + 0.1 * np.trace(cov) / len(cov) * np.eye(len(cov))  # shrinkage: 90 inputs, some collinear
    prec = np.linalg.inv(cov)

    def dist(a: np.ndarray) -> np.ndarray:
        c = a - mean
        return np.einsum("ij,jk,ik->i", c, prec, c)

    thresholds = {q: float(np.quantile(dist(cal), q)) for q in (0.95, 0.99)}
    print(f"{len(mean)} inputs; distance thresholds " + ", ".join(f"q{q}: {t:.0f}" for q, t in thresholds.items()))
    for name in sets:
        for part in "abc":
            dd = load_set(name, part)
            f, out = feats(dd)
            dists, acc = dist(f), out["measurable"]
            err = out["xi"] - dd["truth_xi"]
            line = f"{name} ({part}): accepted {acc.mean():.2f}, xi RMS {rms(err[acc]):.3f}"
            for q, t in thresholds.items():
                kept = acc & (dists <= t)
                line += f" | gate q{q}: {kept.mean():.2f}, {rms(err[kept]):.3f}"
            bad = acc & (np.abs(err) > 0.5)
            if bad.sum() >= 3 and (acc & ~bad).sum() >= 3:
                u = mannwhitneyu(dists[bad], dists[acc & ~bad]).statistic / (bad.sum() * (acc & ~bad).sum())
                line += f" | AUC(misread) {u:.2f} of {bad.sum()}"
            print(line, flush=True)


def _head(x: np.ndarray, y: np.ndarray, seed: int) -> torch.nn.Module:
    """A head like the shipped one's loss (Gaussian NLL of the absolute log error), 64 hidden units."""
    torch.manual_seed(seed)
    m = torch.nn.Sequential(torch.nn.Linear(x.shape[1], 64), torch.nn.ReLU(), torch.nn.Linear(64, 1))
    opt = torch.optim.Adam(m.parameters(), 1e-3, weight_decay=1e-4)
    xt, yt = torch.from_numpy(x), torch.from_numpy(y)
    for _ in range(3000):
        idx = torch.randint(0, len(xt), (256,))
        s = m(xt[idx]).squeeze(1)
        loss = (s + 0.5 * (yt[idx] / s.exp()) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
    return m


def oracle(_: list[str]) -> None:
    feats = Features()
    parts = [(p, load_set("photos", p)) for p in "abc"]
    rows = [(p, d, *feats(d)) for p, d in parts]
    f = np.concatenate([r[2] for r in rows]).astype(np.float32)
    part = np.concatenate([[p] * len(d["noisy"]) for p, d, *_ in rows])
    src = np.concatenate([r[1]["source_index"] for r in rows])
    sigma = np.concatenate([r[3]["sigma_image"] for r in rows])
    xi = np.concatenate([r[3]["xi"] for r in rows])
    xi_true = np.concatenate([r[1]["truth_xi"] for r in rows])
    y = np.abs(np.log(sigma / np.concatenate([r[1]["truth_sigma_image"] for r in rows]))).astype(np.float32)

    def report(name: str, relative: np.ndarray) -> None:
        acc = is_measurable(sigma * relative, relative)
        for p in "abc":
            k = (part == p) & acc
            line = f"{name} ({p}): coverage {k.sum() / np.sum(part == p):.2f}, accepted xi RMS {rms(xi[k] - xi_true[k]):.3f}"
            if p == "a":
                line += f", false alarms {100 * np.mean(np.abs(xi[k]) > 1) * k.sum() / np.sum(part == p):.1f} %"
            print(line, flush=True)

    report("shipped head", np.concatenate([r[3]["sigma_image_error"] / r[3]["sigma_image"] for r in rows]))
    relative = np.empty(len(f), dtype=np.float32)
    fold = np.random.default_rng(0).integers(0, 5, len(f))
    for k in range(5):
        m = _head(f[fold != k], y[fold != k], k)
        with torch.no_grad():
            relative[fold == k] = m(torch.from_numpy(f[fold == k])).squeeze(1).exp().numpy()
    report("oracle head, random 5-fold", relative)
    for k in np.unique(src):
        m = _head(f[src != k], y[src != k], int(k))
        with torch.no_grad():
            relative[src == k] = m(torch.from_numpy(f[src == k])).squeeze(1).exp().numpy()
    report("oracle head, leave-one-image-out", relative)


def truth(sets: list[str]) -> None:
    for name in sets:
        d = load_set(name, "a")
        actual = np.std((d["noisy"].astype(np.float64) - d["clean"]).reshape(len(d["noisy"]), -1), axis=1)
        diff = actual - d["truth_sigma_image"]
        clipped = ((d["noisy"] <= 0) | (d["noisy"] >= 255)).mean(axis=(1, 2)) > 0.01
        print(f"{name} (a): actual - truth mean {diff.mean():+.3f}, RMS {rms(diff):.3f} DN; patches with > 1 % "
              f"clipped pixels {clipped.mean():.0%}: RMS {rms(diff[clipped]):.3f}, others {rms(diff[~clipped]):.3f}")
        for k in np.unique(d["source_index"]):
            m = d["source_index"] == k
            print(f"   image {k}: {m.sum()} patches, mean {diff[m].mean():+.3f}, RMS {rms(diff[m]):.3f} DN")


def jpeg(_: list[str]) -> None:
    def jpeg_then_2x(rng: np.random.Generator) -> list[np.ndarray]:
        lo, hi = images.JPEG_QUALITY
        return [images._downsample(images.jpeg_compress(im, int(rng.integers(lo, hi + 1))))
                for im in images.skimage_originals()]

    tuning.SETS["tune_jpeg"] = ((3501, 3502, 3503), jpeg_then_2x)
    sys.argv = [sys.argv[0], "--sets", "tune", "tune_jpeg", "--cache", str(CACHE)]
    tuning.main()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("probe", choices=["ood", "oracle", "truth", "jpeg"])
    ap.add_argument("--sets", nargs="+", default=["tune", "tune_native", "manmade", "proc", "grain", "photos"])
    args = ap.parse_args()
    {"ood": ood, "oracle": oracle, "truth": truth, "jpeg": jpeg}[args.probe](args.sets)


if __name__ == "__main__":
    main()
