"""Held-out benchmark: parts (a) clean metadata, (b) the paper's gain corruption, (c) +N(0, 5 DN).

Held-out images come from other packages than training: the benchmark uses matplotlib's sample
images plus dead-leaves images (most of its patches), the ``photos`` set matplotlib's and PyWavelets'
sample images only (2x downsampled like every photograph), ``photos_native`` the same images at their
native resolution (an unknown camera's scale may be either); noise and crops come from seeds never used in training.
A user's own clean images make a set too (:func:`image_set_data`, ``user_images``), scored per image (:func:`per_image`). Metrics are the paper's:
Bias = |mean(est - truth)|, Std = std(est - truth), RMS = sqrt(Bias^2 + Std^2). Alarms: false alarms = |xi| > 1 DN on (a); hits on
(b)/(c) = |xi| > 1 DN with the true sign, among patches with |xi_true| > 2 DN. Peers measure sigma_image
(xi = physics sigma_model - their estimate). With a confidence output (``measurable``), ``declined``
scores the same patches with the unmeasurable ones declined: coverage, xi on the accepted patches, and
alarm rates where a declined patch is never a false alarm nor a hit (hits also among accepted candidates);
``decided`` counts alarms also on the unmeasurable patches whose alarm decision is clear given their
predicted error (``inference.clear_decisions``: | |xi| - 1 DN | > 2 errors, relative error within the limit): a noisy
patch measured to 0.6 DN with xi = -4 DN alarms whatever its error; and those whose image-only bound proves
the alarm (``xi_lower`` > 1 DN: the model predicts more noise than the patch can hold, whatever its
content; :mod:`.bound`), alarming with xi = max(xi, xi_lower). The top-level figures stay those of every
patch. Every alarm rate and xi RMS carries a 95 % interval (``*_ci95``: Wilson for rates, a seeded percentile
bootstrap over the patches for the RMS): on 600 patches a rate of 3 % is known to about +-1.5 points, so
smaller differences between two weights are not evidence. Those intervals treat the patches as independent
draws; they are not when the set has few source images, each with its own content and so its own error (the
``photos`` set: 6). Where the data records each patch's image (``source_index``) every interval also comes over
the images (``*_ci95_images``: the standard error from a bootstrap that resamples the images with replacement,
all patches of each drawn one, and Student's t; see ``image_ci``): how far the figure could move on other images
of the same kind.
"""
from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np
from tqdm import tqdm

from ..physics import CameraMetadata, NoiseModel
from ..physics.sensitivity import SWEEP_INTENSITIES, SWEEPS, reference_metadata
from .data import PARTS, DamagedDataset, generate, load, metas_of, save
from .inference import clear_decisions
from .peers import PEERS
from .physics_prior import SOURCES, PhysicsPrior, box_smooth
from .user_images import SEEDS, ImageSet


class HeldoutSet(NamedTuple):
    split: str  # images.SPLITS
    seeds: dict[str, int]  # per part
    description: str  # for reports


HELDOUT_SETS = {
    "benchmark": HeldoutSet("heldout", {"a": 1001, "b": 1002, "c": 1003}, "matplotlib sample images + unseen dead leaves"),
    "photos": HeldoutSet("photos", {"a": 2001, "b": 2002, "c": 2003},
                         "matplotlib + PyWavelets sample images only (no dead leaves)"),
    "photos_native": HeldoutSet("photos_native", {"a": 2201, "b": 2202, "c": 2203},
                                "matplotlib + PyWavelets sample images at native resolution (no 2x downsample, "
                                "no dead leaves)"),
}
ALARM_DN = 1.0
HIT_TRUTH_DN = 2.0
SENSITIVITY_FLAG_DN = 1.0
#: Level of the intervals ``score`` reports, and the bootstrap resamples of the RMS interval.
CI_LEVEL = 0.95
BOOTSTRAP = 1000


def stats(est: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    err = np.asarray(est, dtype=float) - np.asarray(truth, dtype=float)
    bias, std = abs(float(err.mean())), float(err.std())
    return {"bias": round(bias, 4), "std": round(std, 4), "rms": round(float(np.hypot(bias, std)), 4)}


def rate_ci(events: np.ndarray) -> list[float]:
    """Wilson interval (``CI_LEVEL``) of the rate of a boolean array."""
    from scipy.stats import binomtest

    ci = binomtest(int(np.count_nonzero(events)), len(events)).proportion_ci(CI_LEVEL, method="wilson")
    return [round(float(ci.low), 4), round(float(ci.high), 4)]


def rms_ci(err: np.ndarray, seed: int = 0) -> list[float]:
    """Percentile bootstrap interval (``CI_LEVEL``, ``BOOTSTRAP`` resamples of the patches, seeded) of the
    RMS of ``err``."""
    sq = np.square(np.asarray(err, dtype=float))
    idx = np.random.default_rng(seed).integers(0, len(sq), (BOOTSTRAP, len(sq)))
    lo, hi = np.quantile(np.sqrt(sq[idx].mean(axis=1)), [(1 - CI_LEVEL) / 2, (1 + CI_LEVEL) / 2])
    return [round(float(lo), 4), round(float(hi), 4)]


def image_ci(num: np.ndarray, den: np.ndarray, images: np.ndarray, root: bool = False, rate: bool = False,
             seed: int = 0) -> list[float] | None:
    """Interval (``CI_LEVEL``) of sum(num) / sum(den) (its square root with ``root``: an RMS from squared errors)
    over the source images: the standard error from a bootstrap that draws as many images as there are, with
    replacement, all patches of each (``BOOTSTRAP`` resamples, seeded), scaled by sqrt(K / (K - 1)) for K images,
    times Student's t at K - 1 degrees of freedom; clipped at 0 (and at 1 for a ``rate``). With few images it is
    still too narrow (simulated, image errors N(0, 0.5) and patch errors N(0, 0.3) DN: an RMS covered ~86 % of the
    time with 6 images, 87 % with 12, 90 % with 30; a rate 72 / 81 / 86 %). None with fewer than two images."""
    from scipy.stats import t

    ids, inv = np.unique(np.asarray(images), return_inverse=True)
    k = len(ids)
    s_k = np.bincount(inv, weights=np.asarray(num, dtype=float), minlength=k)
    n_k = np.bincount(inv, weights=np.asarray(den, dtype=float), minlength=k)
    if k < 2 or n_k.sum() <= 0:
        return None
    w = np.random.default_rng(seed).multinomial(k, np.full(k, 1.0 / k), BOOTSTRAP)
    with np.errstate(invalid="ignore", divide="ignore"):  # a resample without a counted patch: NaN, dropped
        r = (w @ s_k) / (w @ n_k)
    r = r[np.isfinite(r)]
    point = s_k.sum() / n_k.sum()
    if root:
        r, point = np.sqrt(r), np.sqrt(point)
    if len(r) < 2:
        return None
    half = float(t.ppf((1 + CI_LEVEL) / 2, k - 1) * r.std(ddof=1) * np.sqrt(k / (k - 1)))
    hi = point + half
    return [round(float(max(point - half, 0.0)), 4), round(float(min(hi, 1.0) if rate else hi), 4)]


def xi_stats(xi: np.ndarray, xi_true: np.ndarray, images: np.ndarray | None = None) -> dict:
    """``stats`` of xi with the interval of its RMS (``rms_ci95``; over the source images too, ``rms_ci95_images``,
    when ``images`` gives each patch's)."""
    err = np.asarray(xi, dtype=float) - np.asarray(xi_true, dtype=float)
    out = {**stats(xi, xi_true), "rms_ci95": rms_ci(err)}
    if images is not None:
        out["rms_ci95_images"] = image_ci(np.square(err), np.ones(len(err)), images, root=True)
    return out


def image_set_data(part: str, n: int, patch_size: int, image_set: ImageSet, cache_dir: Path | None = None,
                   progress: bool = True) -> dict[str, np.ndarray]:
    """A part of a user's own images as a held-out set (``user_images``), cached as
    ``images-<key>_<part>_p<size>_n<n>.npz`` in ``cache_dir`` (the key covers the pixels and the downsampling)."""
    if part not in PARTS:
        raise ValueError(f"part must be one of {tuple(PARTS)}, got {part!r}")
    path = None if cache_dir is None else Path(cache_dir) / f"images-{image_set.key}_{part}_p{patch_size}_n{n}.npz"
    return _cached(path, lambda: generate(n, patch_size, SEEDS[part], "images", PARTS[part], progress=progress,
                                          images=image_set.images))


def _cached(path: Path | None, make: Callable[[], dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """The dataset at ``path`` if it is there and readable, else ``make()`` (saved there); a damaged file (an older
    run interrupted while writing it: a traceback on every later run until 2026-12-04) is made again, said."""
    if path is not None and path.is_file():
        try:
            return load(path)
        except DamagedDataset as exc:
            print(f"note: {exc}; generating it again", file=sys.stderr)
    data = make()
    if path is not None:
        save(data, path)
    return data


def heldout(part: str, n: int, patch_size: int, cache_dir: Path | None = None, progress: bool = True,
            heldout_set: str = "benchmark") -> dict[str, np.ndarray]:
    """The held-out data of a part of a set (``HELDOUT_SETS``), cached as
    ``<split>_<part>_p<size>_n<n>.npz`` in ``cache_dir``."""
    if part not in PARTS:
        raise ValueError(f"part must be one of {tuple(PARTS)}, got {part!r}")
    if heldout_set not in HELDOUT_SETS:
        raise ValueError(f"held-out set must be one of {tuple(HELDOUT_SETS)}, got {heldout_set!r}")
    hs = HELDOUT_SETS[heldout_set]
    path = cache_dir / f"{hs.split}_{part}_p{patch_size}_n{n}.npz" if cache_dir else None
    return _cached(path, lambda: generate(n, patch_size, hs.seeds[part], hs.split, PARTS[part], progress=progress))


def score(pred: dict[str, np.ndarray], data: dict[str, np.ndarray], part: str) -> dict:
    """Bias/Std/RMS per available output and the alarm rates of a part."""
    out: dict = {}
    for s in SOURCES:
        if s in pred:
            out[s] = stats(pred[s], data[f"truth_{s}"])
    if "sigma_image" in pred:
        out["sigma_image"] = stats(pred["sigma_image"], data["truth_sigma_image"])
    if "xi" in pred:
        xi, xi_true = pred["xi"], data["truth_xi"]
        images = data.get("source_index")
        out["xi"] = xi_stats(xi, xi_true, images)
        out.update(_alarm_rates(xi, xi_true, np.ones(len(xi), dtype=bool), part, images=images))
        if part != "a":
            out["n_hit_candidates"] = int(np.count_nonzero(np.abs(xi_true) > HIT_TRUTH_DN))
        if "measurable" in pred:
            ok = np.asarray(pred["measurable"], dtype=bool)
            out["declined"] = _declined(xi, xi_true, ok, part, images)
            if "sigma_image_error" in pred:
                xi_d, decided = _decided(pred)
                out["decided"] = _declined(xi_d, xi_true, decided, part, images)
    return out


def _decided(pred: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(xi, which patches decide) under the ``decided`` rule: the measurable ones, the declined ones with a clear
    decision, and those whose image-only bound proves the alarm (xi raised to ``xi_lower`` there)."""
    xi, ok = np.asarray(pred["xi"], dtype=float), np.asarray(pred["measurable"], dtype=bool)
    lower = pred.get("xi_lower", np.full(len(xi), -np.inf))
    proven = ~ok & (lower > ALARM_DN)  # the image-only bound proves the alarm
    return np.where(proven, np.maximum(xi, lower), xi), ok | clear_decisions(pred, ALARM_DN) | proven


def per_image(pred: dict[str, np.ndarray], data: dict[str, np.ndarray], part: str, n_images: int | None = None) -> list[dict]:
    """Scores of each source image (``source_index``) of a part: patches, xi RMS and mean error over every patch,
    and with a confidence output the accepted share, the accepted patches' xi RMS and the alarm rates (false
    alarms on (a), hits among the candidates on (b) / (c)) with the declined patches never alarming
    (``*_accepted``) and under the ``decided`` rule (``*_decided``: what the node's frame takes). With
    ``n_images``, a row for every image, one that drew no patch with ``patches`` 0 and nothing else."""
    xi, xi_true = np.asarray(pred["xi"], dtype=float), np.asarray(data["truth_xi"], dtype=float)
    src = np.asarray(data["source_index"])
    confident = "measurable" in pred and "sigma_image_error" in pred
    if confident:
        ok = np.asarray(pred["measurable"], dtype=bool)
        xi_d, decided = _decided(pred)
    out: list[dict] = []
    for k in range(n_images) if n_images is not None else np.unique(src):
        m = src == k
        if not m.any():
            out.append({"image": int(k), "patches": 0})
            continue
        err = xi[m] - xi_true[m]
        row: dict = {"image": int(k), "patches": int(m.sum()), "xi_rms": round(float(np.sqrt(np.mean(err**2))), 4),
                     "xi_mean_error": round(float(err.mean()), 4)}
        if confident:
            acc = ok[m]
            row["coverage"] = round(float(acc.mean()), 4)
            row["xi_rms_accepted"] = round(float(np.sqrt(np.mean(err[acc] ** 2))), 4) if acc.any() else None
            for rule, (x, use) in {"accepted": (xi[m], acc), "decided": (xi_d[m], decided[m])}.items():
                alarm, hit, big = _alarms(x, xi_true[m], use)
                if part == "a":
                    row[f"false_alarm_rate_{rule}"] = round(float(alarm.mean()), 4)
                else:
                    row[f"hit_rate_{rule}"] = round(float(hit[big].mean()), 4) if big.any() else None
                    row["hit_candidates"] = int(big.sum())
        out.append(row)
    return out


def _declined(xi: np.ndarray, xi_true: np.ndarray, ok: np.ndarray, part: str, images: np.ndarray | None = None) -> dict:
    """Scores with the unmeasurable patches declined (see the module docstring)."""
    out: dict = {"coverage": round(float(ok.mean()), 4),
                 "xi": xi_stats(xi[ok], xi_true[ok], None if images is None else images[ok]) if ok.any() else None}
    return {**out, **_alarm_rates(xi, xi_true, ok, part, among_accepted=True, images=images)}


def _alarm_rates(xi: np.ndarray, xi_true: np.ndarray, ok: np.ndarray, part: str, among_accepted: bool = False,
                 images: np.ndarray | None = None) -> dict:
    """False alarms on (a), hits on (b) / (c) (``among_accepted``: also among the ``ok`` candidates), with
    their intervals (over the source images too when ``images`` gives each patch's); a patch not ``ok`` never
    alarms."""
    alarm, hit, big = _alarms(xi, xi_true, ok)
    out: dict = {"hit_rate": None}
    if part == "a":
        out = {"false_alarm_rate": round(float(alarm.mean()), 4), "false_alarm_ci95": rate_ci(alarm)}
        if images is not None:
            out["false_alarm_ci95_images"] = image_ci(alarm, np.ones(len(alarm)), images, rate=True)
        return out
    if big.any():
        out = {"hit_rate": round(float(hit[big].mean()), 4), "hit_ci95": rate_ci(hit[big])}
        if images is not None:
            out["hit_ci95_images"] = image_ci(hit & big, big, images, rate=True)
    if among_accepted:
        out["hit_rate_accepted"] = round(float(hit[big & ok].mean()), 4) if (big & ok).any() else None
    return out


def _alarms(xi: np.ndarray, xi_true: np.ndarray, ok: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per patch: an alarm (accepted and |xi| > ``ALARM_DN``), a hit (an alarm of the true sign) and a hit
    candidate (|xi_true| > ``HIT_TRUTH_DN``)."""
    alarm = ok & (np.abs(xi) > ALARM_DN)
    return alarm, alarm & (np.sign(xi) == np.sign(xi_true)), np.abs(xi_true) > HIT_TRUTH_DN


def paired_difference(pred: dict[str, np.ndarray], base: dict[str, np.ndarray], data: dict[str, np.ndarray],
                      part: str, seed: int = 0) -> dict[str, list[float]]:
    """``pred`` minus ``base`` on the same patches, each difference with its interval (``CI_LEVEL``) from one
    bootstrap of the patches shared by both, so the patches' own variation cancels: xi RMS over every patch
    and over each one's accepted patches (``measurable``), and the alarm rate with declined patches never
    alarming (false alarms on (a), hits among the candidates on (b) / (c)). {metric: [difference, low,
    high]}; the training's own randomness (another data seed) is not in these intervals."""
    xi_true = np.asarray(data["truth_xi"], dtype=float)
    n = len(xi_true)
    rows = {"all": np.arange(n)[None], "resampled": np.random.default_rng(seed).integers(0, n, (BOOTSTRAP, n))}
    a, b = (_resampled_scores(p, xi_true, part, rows) for p in (pred, base))
    out = {}
    for key in a["all"]:
        d = a["resampled"][key] - b["resampled"][key]
        d = d[np.isfinite(d)]
        point = a["all"][key][0] - b["all"][key][0]
        if d.size and np.isfinite(point):
            lo, hi = np.quantile(d, [(1 - CI_LEVEL) / 2, (1 + CI_LEVEL) / 2])
            out[key] = [round(float(point), 4), round(float(lo), 4), round(float(hi), 4)]
    return out


def _resampled_scores(pred: dict[str, np.ndarray], xi_true: np.ndarray, part: str,
                      rows: dict[str, np.ndarray]) -> dict[str, dict[str, np.ndarray]]:
    """The metrics of ``paired_difference`` on each set of patch rows ((resamples, n) indices)."""
    xi = np.asarray(pred["xi"], dtype=float)
    sq = np.square(xi - xi_true)
    ok = np.asarray(pred.get("measurable", np.ones(len(xi), bool)), dtype=bool)
    alarm, hit, big = _alarms(xi, xi_true, ok)
    hit = hit & big
    out = {}
    with np.errstate(invalid="ignore", divide="ignore"):  # no accepted patch / candidate in a resample: NaN
        for name, idx in rows.items():
            m = {"xi_rms": np.sqrt(sq[idx].mean(axis=1)),
                 "xi_rms_accepted": np.sqrt((sq * ok)[idx].sum(axis=1) / ok[idx].sum(axis=1))}
            if part == "a":
                m["false_alarm_rate"] = alarm[idx].mean(axis=1)
            else:
                m["hit_rate"] = hit[idx].sum(axis=1) / big[idx].sum(axis=1)
            out[name] = m
    return out


def peer_predictions(data: dict[str, np.ndarray], prior: PhysicsPrior, progress: bool = True) -> dict[str, dict[str, np.ndarray]]:
    """sigma_image and xi of each classical peer (sigma_model from the physics on the smoothed patch)."""
    sigma_model = prior.predict(box_smooth(data["noisy"]), metas_of(data))["total"]
    out = {}
    for name, fn in PEERS.items():
        est = np.array([fn(p) for p in tqdm(data["noisy"], desc=name, disable=not progress, leave=False)])
        out[name] = {"sigma_image": est, "xi": sigma_model - est}
    return out


def timed_predict(estimator, data: dict[str, np.ndarray], batch: int = 64) -> tuple[dict[str, np.ndarray], float]:
    metas = metas_of(data)
    parts: list[dict[str, np.ndarray]] = []
    t0 = time.perf_counter()
    for i in range(0, len(data["noisy"]), batch):
        parts.append(estimator.predict(data["noisy"][i:i + batch], metas[i:i + batch]))
    dt = time.perf_counter() - t0
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}, dt


# --- the paper's metadata sensitivity sweep ------------------------------------------------------
def sensitivity_sweep(predict_total: Callable[[np.ndarray, CameraMetadata], float], patch_size: int,
                      seed: int = 2024, model: NoiseModel | None = None) -> dict:
    """Estimator total vs the noise model on flat patches (128 DN unless the intensity is swept).

    The model reference is the sequential protocol's total (what the estimators are trained on) on the
    flat clean patch; the estimator sees one simulated noisy flat patch per cell. The thermal-white-noise
    row is for a CCD (the paper's footnote).
    """
    model = model or NoiseModel()
    rng = np.random.default_rng(seed)
    base = reference_metadata()
    rows: dict[str, dict] = {}
    cells = [("mean_intensity_dn", v, base) for v in SWEEP_INTENSITIES]
    for field, values in SWEEPS.items():
        swept = base.replace(sensor_type="ccd") if field == "thermal_white_noise_v_per_sqrt_hz" else base
        cells += [(field, v, swept.replace(**{field: float(v)})) for v in values]
    for field, value, meta in tqdm(cells, desc="sensitivity", leave=False):
        level = float(value) if field == "mean_intensity_dn" else 128.0
        clean = np.full((patch_size, patch_size), level, dtype=np.float32)
        noisy, _ = model.simulate(clean, meta, rng, mode="sequential")
        ref = float(model.predict(level, meta, mode="sequential")["total"])
        est = float(predict_total(noisy[None], meta))
        row = rows.setdefault(field, {"values": [], "model": [], "estimator": [], "flagged": []})
        row["values"].append(float(value))
        row["model"].append(round(ref, 3))
        row["estimator"].append(round(est, 3))
        row["flagged"].append(bool(abs(est - ref) > SENSITIVITY_FLAG_DN))
    worst = max(abs(e - m) for r in rows.values() for e, m in zip(r["estimator"], r["model"]))
    return {"rows": rows, "max_abs_diff_dn": round(worst, 3),
            "flagged_cells": int(sum(sum(r["flagged"]) for r in rows.values()))}
