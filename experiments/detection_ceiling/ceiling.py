"""Could any per-patch rule meet issue 15's per-patch alarm targets on the held-out photos if it had seen
each photograph's own texture? A diagnostic, never shipped (README in this folder).

Each held-out photograph (the ``photos`` split: 2x) is cut in two halves across its longer side, so the halves
share the photograph's kind of texture and no pixel. On each half, ``--n`` patches of 64 px per benchmark part
((a) correct metadata, (b) the paper's gain corruption, (c) + N(0, 5 DN); ``data.PARTS``; data seeds
``7300 + 10 * image + 3 * half + part``). Per patch: the shipped estimator's outputs, its confidence head's
standardised inputs (trunk features, scalars, texture evidence) and multi-scale classical statistics (Immerkaer
block energies at 1x and 2x binning, radial periodogram bands). Two detectors, each scored on one half after
training on the other (both ways), with its alarm thresholds picked *on the scored half* for the most hits
within 2 % false alarms (an oracle threshold per image and sign, as ``bench/estimator_ceiling.py``'s):

- ``reading``: the shipped xi (alarm when xi < -t1 or xi > t2);
- ``learned``: an MLP on all the features (3 classes: no alarm due, xi_true < -1, xi_true > +1), trained on the
  photograph's other half (``per-image``) or on the other halves of all six (``pooled``).

Hits: candidates of (b) and (c) (|xi_true| > 2 DN) alarmed with the right sign; false alarms: (a) patches alarmed.
``--cnn IMAGE``: instead, a CNN on the raw pixels of one photograph's half (high-pass over the stated sigma_model,
and log sigma_model), trained to tell (a) from (c) (``--n`` patches per part and half; data seeds ``7500 + 10 *
image + 3 * half + part``), scored on the other half's (a) and (c) candidates: whether the features above miss a
tell that the pixels hold.
Usage: .venv/bin/python experiments/detection_ceiling/ceiling.py [--n 1500] [--cache out/s37/ceiling] [--cnn hillshade]
Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "experiments/head_generalization"))
from probe import Features, _head  # noqa: E402

from noise_monitor.estimator import data as D  # noqa: E402
from noise_monitor.estimator import images  # noqa: E402
from noise_monitor.estimator.evaluate import ALARM_DN, HIT_TRUTH_DN  # noqa: E402
from noise_monitor.estimator.inference import CLEAR_DECISION_K, is_measurable  # noqa: E402
from noise_monitor.estimator.residuals import block_energies, immerkaer, quantiles  # noqa: E402

NAMES = ("grace_hopper", "MRI", "hillshade", "Minduka", "aero", "ascent")
FALSE_ALARMS = 0.02
BANDS = ((0.1, 0.2), (0.2, 0.3), (0.3, 0.4), (0.4, 0.5), (0.5, 0.75))


def halves(im: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The image cut in two across its longer side."""
    if im.shape[0] >= im.shape[1]:
        h = im.shape[0] // 2
        return im[:h], im[h:]
    w = im.shape[1] // 2
    return im[:, :w], im[:, w:]


def half_data(k: int, half: int, im: np.ndarray, part: str, n: int, cache: Path, base: int = 7300) -> dict[str, np.ndarray]:
    path = cache / f"{NAMES[k]}_h{half}_{part}_n{n}_s{base}.npz"
    if path.is_file():
        return D.load(path)
    seed = base + 10 * k + 3 * half + "abc".index(part)
    d = D.generate(n, 64, seed, "photos", D.PARTS[part], progress=False, images=[im])
    D.save(d, path)
    return d


def _binned(x: np.ndarray) -> np.ndarray:
    n, h, w = x.shape
    return x.reshape(n, h // 2, 2, w // 2, 2).mean(axis=(2, 4), dtype=np.float32)


def classical(x: np.ndarray) -> np.ndarray:
    """Log RMS quantiles (5, 25, 50 %) of the 8x8-block Immerkaer energies at 1x and 2x binning; log median
    periodogram power in radial bands (cycles / px) of the mean-removed, Hann-windowed patch; log mean and std."""
    cols = []
    for y in (x, _binned(x)):
        e = block_energies(immerkaer(y), 8).reshape(len(y), -1)
        cols.append(0.5 * np.log(quantiles(e, (0.05, 0.25, 0.5)) + 1e-6))
    n, h, w = x.shape
    win = np.outer(np.hanning(h), np.hanning(w)).astype(np.float32)
    p = np.abs(np.fft.fft2((x - x.mean(axis=(1, 2), keepdims=True)) * win)) ** 2 / np.square(win).sum()
    fy, fx = np.meshgrid(np.fft.fftfreq(h), np.fft.fftfreq(w), indexing="ij")
    r = np.hypot(fy, fx)
    cols.append(np.stack([np.log(np.median(p[:, (r >= lo) & (r < hi)], axis=1) + 1e-6) for lo, hi in BANDS], 1))
    cols.append(np.stack([np.log(x.mean(axis=(1, 2)) + 1.0), np.log(x.std(axis=(1, 2)) + 1e-3)], 1))
    return np.concatenate(cols, axis=1)


def features(feats: Features, d: dict[str, np.ndarray]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """(all features, the shipped estimator's outputs) of a dataset; the head's own inputs come first."""
    head, out = feats(d)
    log = {k: np.log(np.clip(np.asarray(out[k], dtype=float), 1e-3, 300.0))  # the bound is inf when too clipped
           for k in ("sigma_image", "sigma_image_error", "sigma_image_upper", "sigma_model")}
    own = np.stack([*log.values(), out["xi"], log["sigma_image"] - log["sigma_model"],
                    log["sigma_image_upper"] - log["sigma_model"]], axis=1)
    cl = classical(d["noisy"].astype(np.float32))
    rel = cl[:, :6] - log["sigma_model"][:, None]  # block RMS over the stated model's sigma
    return np.concatenate([head, own, cl, rel], axis=1), out


def labels(xi_true: np.ndarray) -> np.ndarray:
    return np.where(xi_true < -ALARM_DN, 1, np.where(xi_true > ALARM_DN, 2, 0))


def mlp(x: np.ndarray, y: np.ndarray, seed: int, epochs: int = 80) -> tuple[torch.nn.Module, np.ndarray, np.ndarray]:
    """A 3-class MLP (two hidden layers of 128, class-balanced cross-entropy), inputs standardised."""
    torch.manual_seed(seed)
    mean, std = x.mean(axis=0), x.std(axis=0) + 1e-6
    xt, yt = torch.from_numpy(((x - mean) / std).astype(np.float32)), torch.from_numpy(y)
    m = torch.nn.Sequential(torch.nn.Linear(x.shape[1], 128), torch.nn.ReLU(), torch.nn.Dropout(0.1),
                            torch.nn.Linear(128, 128), torch.nn.ReLU(), torch.nn.Linear(128, 3))
    counts = np.bincount(y, minlength=3).astype(np.float32)
    loss_fn = torch.nn.CrossEntropyLoss(weight=torch.from_numpy(counts.sum() / np.maximum(counts, 1) / 3))
    opt = torch.optim.AdamW(m.parameters(), lr=1e-3, weight_decay=1e-3)
    g = torch.Generator().manual_seed(seed)
    for _ in range(epochs):
        for idx in torch.randperm(len(xt), generator=g).split(256):
            opt.zero_grad()
            loss_fn(m(xt[idx]), yt[idx]).backward()
            opt.step()
    return m.eval(), mean, std


def scores(model: tuple[torch.nn.Module, np.ndarray, np.ndarray], x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    m, mean, std = model
    with torch.inference_mode():
        p = torch.softmax(m(torch.from_numpy(((x - mean) / std).astype(np.float32))), 1).numpy()
    return np.log(p[:, 1] + 1e-9) - np.log(p[:, 0] + 1e-9), np.log(p[:, 2] + 1e-9) - np.log(p[:, 0] + 1e-9)


def best_thresholds(neg: np.ndarray, pos: np.ndarray, is_a: np.ndarray, sign: np.ndarray) -> tuple[float, int, int, int]:
    """Thresholds (t1 on ``neg``, t2 on ``pos``) with the most hits within ``FALSE_ALARMS`` on the (a) rows:
    (false-alarm rate, hits, candidates, of which patches). ``sign``: -1 / +1 for a candidate, 0 otherwise."""
    grid = np.quantile
    t1s = grid(neg[is_a], np.linspace(0.9, 1.0, 41))
    t2s = grid(pos[is_a], np.linspace(0.9, 1.0, 41))
    t1s, t2s = np.append(t1s, np.inf), np.append(t2s, np.inf)
    best = (0.0, -1)
    cand = sign != 0
    for t1 in t1s:
        for t2 in t2s:
            an, ap = neg > t1, pos > t2
            alarm_neg = an & (~ap | (neg - t1 >= pos - t2))
            alarm_pos = ap & ~alarm_neg
            fa = float((alarm_neg | alarm_pos)[is_a].mean())
            if fa > FALSE_ALARMS:
                continue
            hits = int(((alarm_neg & (sign < 0)) | (alarm_pos & (sign > 0)))[cand].sum())
            if hits > best[1]:
                best = (fa, hits)
    return best[0], best[1], int(cand.sum()), len(sign)


def cnn_inputs(d: dict[str, np.ndarray]) -> np.ndarray:
    """(N, 2, H, W): the patch minus its 3x3 mean over the stated sigma_model, and log sigma_model."""
    from noise_monitor.estimator.physics_prior import PhysicsPrior, box_smooth

    x = d["noisy"].astype(np.float32)
    s = PhysicsPrior().predict(box_smooth(x), D.metas_of(d))["total"].astype(np.float32)
    hp = x - torch.nn.functional.avg_pool2d(torch.from_numpy(x)[:, None], 3, 1, 1, count_include_pad=False)[:, 0].numpy()
    return np.stack([hp / s[:, None, None], np.broadcast_to(np.log(s)[:, None, None], x.shape)], axis=1)


def cnn_ceiling(k: int, im: np.ndarray, n: int, cache: Path, epochs: int = 10) -> None:
    """Hits of (c) within 2 % false alarms of (a) on each half, by a CNN trained on the other half."""
    data = {(h, p): half_data(k, h, sub, p, n, cache, base=7500) for h, sub in enumerate(halves(im)) for p in "ac"}
    hits = cands = 0
    for h in (0, 1):
        tr_a, tr_c = data[1 - h, "a"], data[1 - h, "c"]
        keep = tr_c["truth_xi"] < -ALARM_DN
        x = np.concatenate([cnn_inputs(tr_a), cnn_inputs(tr_c)[keep]])
        y = np.concatenate([np.zeros(len(tr_a["noisy"])), np.ones(keep.sum())]).astype(np.float32)
        torch.manual_seed(7590 + h)
        net = torch.nn.Sequential(
            torch.nn.Conv2d(2, 16, 3, padding=1), torch.nn.ReLU(), torch.nn.Conv2d(16, 16, 3, padding=1), torch.nn.ReLU(),
            torch.nn.Conv2d(16, 32, 3, stride=2, padding=1), torch.nn.ReLU(), torch.nn.Conv2d(32, 32, 3, padding=1),
            torch.nn.ReLU(), torch.nn.Conv2d(32, 32, 3, stride=2, padding=1), torch.nn.ReLU(),
            torch.nn.AdaptiveAvgPool2d(1), torch.nn.Flatten(), torch.nn.Linear(32, 1))
        opt = torch.optim.AdamW(net.parameters(), lr=1e-3, weight_decay=1e-4)
        xt, yt = torch.from_numpy(x), torch.from_numpy(y)
        g = torch.Generator().manual_seed(7590 + h)
        for _ in range(epochs):
            for idx in torch.randperm(len(xt), generator=g).split(128):
                xb = xt[idx]
                if torch.rand(1, generator=g) < 0.5:  # flips and transposes: the noise has no orientation
                    xb = xb.transpose(2, 3)
                if torch.rand(1, generator=g) < 0.5:
                    xb = xb.flip(3)
                opt.zero_grad()
                torch.nn.functional.binary_cross_entropy_with_logits(net(xb)[:, 0], yt[idx]).backward()
                opt.step()
        net.eval()
        with torch.inference_mode():
            sa = net(torch.from_numpy(cnn_inputs(data[h, "a"])))[:, 0].numpy()
            c = data[h, "c"]
            cand = np.abs(c["truth_xi"]) > HIT_TRUTH_DN
            sc = net(torch.from_numpy(cnn_inputs(c)))[:, 0].numpy()[cand]
        t = np.quantile(sa, 1 - FALSE_ALARMS)
        hits += int((sc > t).sum())
        cands += int(cand.sum())
        print(f"  {NAMES[k]} half {h} (trained on the other): (c) hits {np.mean(sc > t):.1%} of {cand.sum()} "
              f"within {np.mean(sa > t):.1%} false alarms of (a)", flush=True)
    print(f"{NAMES[k]}: CNN on the pixels, (c) hits {hits / cands:.1%} of {cands} candidates")


def feature_rows(photos: list[np.ndarray], n: int, cache: Path) -> dict[tuple[int, int], dict[str, np.ndarray]]:
    """Per (image, half): features, the shipped outputs and the truths of its three parts (cached)."""
    path = cache / f"features_n{n}.npz"
    keys = ("x", "xi", "truth", "part", "sigma", "error", "truth_sigma")
    if path.is_file():
        z = np.load(path)
        return {(k, h): {key: z[f"{k}_{h}_{key}"] for key in keys} for k in range(len(photos)) for h in (0, 1)}
    feats = Features()
    rows: dict[tuple[int, int], dict[str, np.ndarray]] = {}
    for k, im in enumerate(photos):
        for h, sub in enumerate(halves(im)):
            cols: dict[str, list[np.ndarray]] = {key: [] for key in keys}
            for part in "abc":
                d = half_data(k, h, sub, part, n, cache)
                f, out = features(feats, d)
                for key, v in (("x", f), ("xi", out["xi"]), ("truth", d["truth_xi"]),
                               ("part", np.full(len(f), "abc".index(part))), ("sigma", out["sigma_image"]),
                               ("error", out["sigma_image_error"]), ("truth_sigma", d["truth_sigma_image"])):
                    cols[key].append(np.asarray(v))
            rows[k, h] = {key: np.concatenate(v) for key, v in cols.items()}
            print(f"{NAMES[k]} half {h}: {sub.shape}, features {rows[k, h]['x'].shape}", flush=True)
    np.savez(path, **{f"{k}_{h}_{key}": v for (k, h), r in rows.items() for key, v in r.items()})
    return rows


def _rates(r: dict[str, np.ndarray], error: np.ndarray) -> dict[str, float]:
    """Coverage and accepted xi RMS per part, false alarms on (a) (declined never alarm / + clear decisions) and
    hits of (b) / (c) with clear decisions, under the shipped decline rule with predicted errors ``error`` (DN)."""
    ok = is_measurable(error, error / r["sigma"])
    clear = (np.abs(np.abs(r["xi"]) - ALARM_DN) > CLEAR_DECISION_K * error) & (error <= 0.3 * r["sigma"])
    alarm = np.abs(r["xi"]) > ALARM_DN
    out: dict[str, float] = {}
    for p, name in enumerate("abc"):
        m = r["part"] == p
        err = (r["xi"] - r["truth"])[m & ok]
        out[f"coverage_{name}"] = float(ok[m].mean())
        out[f"rms_{name}"] = float(np.sqrt(np.mean(err**2))) if err.size else float("nan")
        if name == "a":
            out["fa"] = float((alarm & ok)[m].mean())
            out["fa_clear"] = float((alarm & (ok | clear))[m].mean())
        else:
            big = m & (np.abs(r["truth"]) > HIT_TRUTH_DN)
            hit = alarm & (ok | clear) & (np.sign(r["xi"]) == np.sign(r["truth"]))
            out[f"hits_{name}"] = float(hit[big].mean())
    return out


def head_ceiling(rows: dict[tuple[int, int], dict[str, np.ndarray]], n_images: int) -> None:
    """Confidence heads (the head's own 90 inputs, Gaussian NLL of the absolute log error; ``probe._head``) trained
    on the other half of the same photograph or the other halves of all six, against the shipped head."""
    n_head = 90

    def inputs(r: dict[str, np.ndarray]) -> np.ndarray:
        # standardised by the shipped head; a few reach 300, which sends the NLL's exp to NaN: clipped at 10
        return np.clip(r["x"][:, :n_head], -10.0, 10.0).astype(np.float32)

    def fit(parts: list[dict[str, np.ndarray]], seed: int) -> torch.nn.Module:
        x = np.concatenate([inputs(r) for r in parts])
        y = np.concatenate([np.abs(np.log(r["sigma"] / r["truth_sigma"])) for r in parts]).astype(np.float32)
        return _head(x, y, seed)

    pooled = {h: fit([rows[k, h] for k in range(n_images)], 7380 + h) for h in (0, 1)}
    scored: dict[str, list[dict[str, np.ndarray]]] = {"shipped": [], "per-image": [], "pooled": []}
    for k in range(n_images):
        own = {h: fit([rows[k, h]], 7300 + 10 * k + h) for h in (0, 1)}
        for h in (0, 1):
            r = rows[k, 1 - h]  # scored: the half the heads did not see
            x = torch.from_numpy(inputs(r))
            with torch.no_grad():
                rel = {"per-image": own[h](x).squeeze(1).exp().numpy(), "pooled": pooled[h](x).squeeze(1).exp().numpy()}
            scored["shipped"].append({**r, "pred": r["error"], "image": np.full(len(r["xi"]), k)})
            for name, v in rel.items():
                scored[name].append({**r, "pred": r["sigma"] * v, "image": np.full(len(r["xi"]), k)})
    print("heads scored on the half they did not see (all six photographs; per image: false alarms / accepted xi RMS "
          "(a) / (c) with (c)'s coverage):")
    for name, parts in scored.items():
        r = {key: np.concatenate([p[key] for p in parts]) for key in ("xi", "truth", "part", "sigma", "pred", "image")}
        t = _rates(r, r["pred"])
        per = [(NAMES[k], _rates({key: v[r["image"] == k] for key, v in r.items()}, r["pred"][r["image"] == k]))
               for k in range(n_images)]
        print(f"  {name:9s} coverage {t['coverage_a']:.0%} / {t['coverage_b']:.0%} / {t['coverage_c']:.0%}, accepted xi "
              f"RMS {t['rms_a']:.3f} / {t['rms_b']:.3f} / {t['rms_c']:.3f} DN, false alarms {t['fa']:.1%} (+ clear "
              f"{t['fa_clear']:.1%}), hits with clear decisions {t['hits_b']:.1%} / {t['hits_c']:.1%}")
        print("            " + "; ".join(f"{nm} {q['fa']:.1%} / {q['rms_a']:.2f} / {q['rms_c']:.2f} ({q['coverage_c']:.0%})"
                                         for nm, q in per), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1500)
    ap.add_argument("--cache", type=Path, default=ROOT / "out/s37/ceiling")
    ap.add_argument("--cnn", choices=NAMES, default=None)
    ap.add_argument("--head", action="store_true", help="confidence heads instead of detectors (see head_ceiling)")
    args = ap.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(2)
    photos = images.matplotlib_photos() + images.pywavelets_photos()
    if args.cnn:
        cnn_ceiling(NAMES.index(args.cnn), photos[NAMES.index(args.cnn)], args.n, args.cache)
        return
    rows = feature_rows(photos, args.n, args.cache)
    if args.head:
        head_ceiling(rows, len(photos))
        return
    pooled = {h: mlp(np.concatenate([rows[k, h]["x"] for k in range(len(photos))]),
                     np.concatenate([labels(rows[k, h]["truth"]) for k in range(len(photos))]), seed=7390 + h)
              for h in (0, 1)}
    totals = {m: np.zeros(2) for m in ("reading", "per-image", "pooled")}
    print(f"per image, both halves scored (hits within {FALSE_ALARMS:.0%} false alarms on the scored half):")
    for k in range(len(photos)):
        res = {m: np.zeros(3) for m in totals}
        for h in (0, 1):
            r = rows[k, h]
            is_a = r["part"] == 0
            sign = np.where(is_a | (np.abs(r["truth"]) <= HIT_TRUTH_DN), 0, np.sign(r["truth"])).astype(int)
            own = mlp(rows[k, 1 - h]["x"], labels(rows[k, 1 - h]["truth"]), seed=7300 + 10 * k + h)
            for m, (neg, pos) in {"reading": (-r["xi"], r["xi"]), "per-image": scores(own, r["x"]),
                                  "pooled": scores(pooled[1 - h], r["x"])}.items():
                fa, hits, cand, _ = best_thresholds(neg, pos, is_a, sign)
                res[m] += (fa / 2, hits, cand)
        line = f"  {NAMES[k]:12s} candidates {int(res['reading'][2]):5d}"
        for m, (fa, hits, cand) in res.items():
            line += f" | {m}: hits {hits / cand:6.1%} at {fa:4.1%}"
            totals[m] += (hits, cand)
        print(line, flush=True)
    print("all six (candidates pooled): " + ", ".join(f"{m} {h / c:.1%}" for m, (h, c) in totals.items()))


if __name__ == "__main__":
    main()
