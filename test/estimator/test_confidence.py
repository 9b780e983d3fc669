"""The measurement's confidence head: unmeasurable patches are declined, the measurement itself unchanged."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from noise_monitor.estimator import load
from noise_monitor.estimator.data import generate, metas_of
from noise_monitor.estimator.evaluate import score
from noise_monitor.estimator.inference import MEASURABLE_ERROR_DN, MEASURABLE_RELATIVE_ERROR
from noise_monitor.estimator.networks import N_MAPS, N_SCALARS, CompactConfig, ImageNoiseNet
from noise_monitor.estimator.procedural import sine_grating
from noise_monitor.estimator.train import TrainSettings, train
from noise_monitor.physics import load_profile

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def meta():
    return load_profile("icx285").metadata(gain_db=12.0, exposure_time_s=0.05, sensor_temperature_c=40.0)


def test_confidence_head_leaves_the_measurement_unchanged():
    torch.manual_seed(0)
    cfg = CompactConfig(width=8, heads=2, patch_size=32)
    plain = ImageNoiseNet(cfg).eval()
    with_head = ImageNoiseNet(CompactConfig(width=8, heads=2, patch_size=32, confidence=(8,))).eval()
    missing, unexpected = with_head.load_state_dict(plain.state_dict(), strict=False)
    assert not unexpected and all(k.startswith(("confidence.", "conf_")) for k in missing)
    maps, scalars = torch.rand(5, N_MAPS, 32, 32), torch.rand(5, N_SCALARS)
    out = with_head(maps, scalars)
    assert out.shape == (5, 2) and plain(maps, scalars).shape == (5,)
    assert torch.allclose(out[:, 0], plain(maps, scalars))


def test_confidence_training_freezes_the_measurement(tmp_path, meta):
    data = generate(48, 32, seed=7, group=8, progress=False)
    base = train(TrainSettings("full_meta", steps=2, batch=8), data, tmp_path / "base", threads=1, progress=False)
    with pytest.raises(ValueError, match="--init"):
        train(TrainSettings("full_meta", steps=1, confidence=True), data, tmp_path / "x", threads=1, progress=False)
    path = train(TrainSettings("full_meta", steps=60, batch=16, lr=1e-2, confidence=True), data, tmp_path / "conf",
                 threads=1, progress=False, init=base)
    before, after = torch.load(base, weights_only=True), torch.load(path, weights_only=True)
    assert after["config"]["confidence"] and not before["config"]["confidence"]
    for k, v in before["state_dict"].items():  # the measurement is frozen
        assert torch.equal(v, after["state_dict"][k]), k
    assert not torch.allclose(after["state_dict"]["conf_std"], torch.ones_like(after["state_dict"]["conf_std"]))
    a = load("full_meta", device="cpu", weights=base, backend="torch").predict(data["noisy"], metas_of(data))
    b = load("full_meta", device="cpu", weights=path, backend="onnx").predict(data["noisy"], metas_of(data))
    assert "measurable" not in a and np.allclose(a["sigma_image"], b["sigma_image"], rtol=1e-4)
    assert np.all(b["sigma_image_error"] > 0)
    rel = b["sigma_image_error"] / b["sigma_image"]
    assert np.array_equal(b["measurable"], (b["sigma_image_error"] <= MEASURABLE_ERROR_DN) & (rel <= MEASURABLE_RELATIVE_ERROR + 1e-9))
    # the head learned the size of the measurement's errors (log-space NLL on its training data)
    err = np.log(b["sigma_image"] / data["truth_sigma_image"])
    assert 0.3 < np.sqrt(np.mean(rel**2)) / np.sqrt(np.mean(err**2)) < 3.0


def test_score_with_declined_patches():
    data = {"truth_xi": np.array([0.0, 0.0, 3.0, -3.0, 0.5]), "truth_sigma_image": np.full(5, 2.0)}
    ok = np.array([True, False, True, False, True])
    a = score({"xi": np.array([0.2, 1.5, 0.0, 0.0, 1.2]), "measurable": ok}, data, "a")
    assert a["false_alarm_rate"] == pytest.approx(0.4)  # every patch
    d = a["declined"]
    assert d["coverage"] == pytest.approx(0.6) and d["false_alarm_rate"] == pytest.approx(0.2)  # declined: no alarm
    assert d["xi"]["rms"] == pytest.approx(np.sqrt((0.04 + 9.0 + 0.49) / 3), abs=1e-3)
    b = score({"xi": np.array([0.0, 0.0, -2.5, -1.5, 0.0]), "measurable": ok}, data, "b")
    assert b["hit_rate"] == pytest.approx(0.5)
    assert b["declined"]["hit_rate"] == pytest.approx(0.0) and b["declined"]["hit_rate_accepted"] == pytest.approx(0.0)
    c = score({"xi": np.array([0.0, 0.0, 2.5, -1.5, 0.0]), "measurable": ok}, data, "c")
    assert c["declined"]["hit_rate"] == pytest.approx(0.5) and c["declined"]["hit_rate_accepted"] == pytest.approx(1.0)
    assert "decided" not in c  # no predicted error given
    # clear decisions: patch 3 (xi -4 DN, error 0.5 DN of sigma_image 5 DN) alarms though not measurable;
    # patch 1 (xi 1.5, error 0.5) is not clear (0.5 DN from the threshold) and patch 3's twin with a relative
    # error above the limit neither
    pred = {"xi": np.array([0.0, 1.5, 2.5, -4.0, 0.0]), "measurable": ok, "sigma_image_error": np.array([0.1, 0.5, 0.1, 0.5, 0.1]),
            "sigma_image": np.array([2.0, 3.0, 2.0, 5.0, 2.0])}
    d = score(pred, data, "c")["decided"]
    assert d["coverage"] == pytest.approx(0.8) and d["hit_rate"] == pytest.approx(1.0)
    pred["sigma_image"] = np.array([2.0, 3.0, 2.0, 1.0, 2.0])
    assert score(pred, data, "c")["decided"]["hit_rate"] == pytest.approx(0.5)


def test_shipped_weights_decline_pixel_scale_texture(meta):
    """Flat patches are measurable; patches of pixel-scale texture (the noise's own scale) get a far larger
    predicted error;
    on new crops of the training photographs the accepted patches' xi error is well below all patches'."""
    import cv2

    est = load("full_meta", device="cpu")
    rng = np.random.default_rng(4)
    flat = np.full((4, 64, 64), 100.0, np.float32)
    tex = np.stack([100 + 40 * cv2.GaussianBlur(rng.standard_normal((64, 64)).astype(np.float32), (0, 0), 0.8)
                    for _ in range(4)])
    noisy = np.stack([est.prior.model.simulate(np.clip(c, 5, 250), meta, rng, mode="sequential")[0] for c in (*flat, *tex)])
    out = est.predict(noisy, meta)
    assert np.all(out["measurable"][:4]) and np.all(out["sigma_image_error"][:4] < 0.2)
    assert out["sigma_image_error"][4:].min() > 3 * out["sigma_image_error"][:4].max()
    d = generate(160, 64, seed=41, split="train", photo_variants=3, progress=False)
    p = est.predict(d["noisy"], metas_of(d))
    err, ok = p["xi"] - d["truth_xi"], p["measurable"]
    rms_all, rms_ok = np.sqrt(np.mean(err**2)), np.sqrt(np.mean(err[ok] ** 2))
    print(f"coverage {ok.mean():.2f}, xi RMS accepted {rms_ok:.3f} vs all {rms_all:.3f} DN")
    assert 0.3 < ok.mean() < 0.95 and rms_ok < 0.6 * rms_all


def test_fine_tuning_weights_with_a_head_keeps_it(tmp_path):
    """``--init`` with the shipped weights (which carry a head) trains the measurement and the head together."""
    from noise_monitor.estimator.inference import WEIGHTS_DIR

    data = generate(16, 32, seed=9, group=8, progress=False)
    path = train(TrainSettings("full_meta", steps=2, batch=4), data, tmp_path, threads=1, progress=False,
                 init=WEIGHTS_DIR / "full_meta.pt")
    before = torch.load(WEIGHTS_DIR / "full_meta.pt", weights_only=True)["state_dict"]
    after = torch.load(path, weights_only=True)
    assert tuple(after["config"]["confidence"]) == (32, 32)
    assert not torch.equal(before["mlp.0.weight"], after["state_dict"]["mlp.0.weight"])  # the measurement trains
    assert not torch.equal(before["confidence.0.weight"], after["state_dict"]["confidence.0.weight"])
    assert torch.equal(before["conf_mean"], after["state_dict"]["conf_mean"])


def test_pixel_scale_gratings_are_declined_or_measured_right(meta):
    """The blind spot of the head without texture evidence: a sine grating of 4 px period read as almost no
    noise (xi +2.8 DN) at a predicted error of 0.06 DN. Each of these 36 gratings of 2-6 px period, 5-40 DN
    amplitude and random orientation is now declined or its xi is within 0.5 DN (on gratings in general
    neither the earlier nor the current pair holds this everywhere: ``bench/estimator_gratings.py``); flat
    patches stay measurable. The gratings are hard: an image-only reading (the upper bound) is off by more than
    0.5 DN on most of them."""
    est = load("full_meta", device="cpu")
    rng = np.random.default_rng(11)
    clean = [sine_grating(64, period, amp, a, rng.uniform(0, 6.3))
             for period in (2.0, 2.5, 3.0, 4.0, 5.0, 6.0) for amp in (5.0, 15.0, 40.0) for a in rng.uniform(0, np.pi, 2)]
    clean += [np.full((64, 64), level) for level in (30.0, 100.0, 200.0)]
    sims = [est.prior.model.simulate(c.astype(np.float32), meta, rng, mode="sequential") for c in clean]
    out = est.predict(np.stack([s[0] for s in sims]), meta)
    truth = np.array([s[1]["total"] for s in sims])
    wrong = np.abs(out["xi"] - (out["sigma_model"] - truth)) > 0.5
    assert not np.any(out["measurable"] & wrong), np.flatnonzero(out["measurable"] & wrong)
    assert (out["sigma_image_upper"][:-3] - truth[:-3] > 0.5).sum() >= 10  # hard for any image-only reading
    assert np.all(out["measurable"][-3:])


def test_anchor_keeps_the_reading_of_declined_patches(tmp_path):
    """``anchor`` pulls the fine-tuned measurement toward the init's reading on the patches the init declines.
    The init is a committed experiment's pair (G2, ``experiments/full_meta_more_data``), not the bundled weights,
    so that what 40 steps move does not change with each shipped network."""
    init = Path(__file__).resolve().parents[2] / "experiments" / "full_meta_more_data" / "full_meta.pt"
    data = generate(96, 32, seed=11, group=8, procedural=4, progress=False)
    with pytest.raises(ValueError, match="--init"):
        train(TrainSettings("full_meta", steps=1, anchor=1.0), data, tmp_path / "x", threads=1, progress=False)
    with pytest.raises(ValueError, match="--confidence"):
        train(TrainSettings("full_meta", steps=1, anchor=1.0, confidence=True), data, tmp_path / "x", threads=1,
              progress=False, init=init)
    old = load("full_meta", device="cpu", weights=init, backend="torch").predict(data["noisy"], metas_of(data))
    declined = ~old["measurable"]
    assert 10 <= declined.sum() <= 86
    drift = {}
    for w in (0.0, 100.0):
        path = train(TrainSettings("full_meta", steps=40, batch=32, lr=1e-3, anchor=w), data, tmp_path / f"a{w:g}",
                     threads=1, progress=False, init=init)
        new = load("full_meta", device="cpu", weights=path, backend="torch").predict(data["noisy"], metas_of(data))
        d = np.log(new["sigma_image"] / old["sigma_image"])
        drift[w] = (np.sqrt(np.mean(d[declined] ** 2)), np.sqrt(np.mean(d[~declined] ** 2)))
    assert drift[0.0][0] > 0.2  # without it the truth of the training data moves them (log units)
    assert drift[100.0][0] < 0.3 * drift[0.0][0]  # with it they keep their reading
    assert drift[100.0][1] > 0.2 * drift[0.0][1]  # while the accepted ones still learn
