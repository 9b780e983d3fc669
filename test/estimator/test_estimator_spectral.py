"""The optional spectral input (``features.spectral_scale``, ``train --spectral``): a noise scale that a pixel-scale
grating does not move, and weights without it (with or without the shape trend) widened to take it without
changing a reading, under torch and ONNX Runtime."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from noise_monitor.estimator.data import generate
from noise_monitor.estimator.features import N_SCALARS, N_SHAPE_TREND, N_SPECTRAL, compact_inputs
from noise_monitor.estimator.inference import FullMetaEstimator
from noise_monitor.estimator.networks import network_from_checkpoint
from noise_monitor.estimator.physics_prior import PhysicsPrior
from noise_monitor.estimator.train import TrainSettings, train
from noise_monitor.physics import NoiseModel, load_profile

META = load_profile("icx285").metadata(gain_db=6.0, exposure_time_s=0.01, sensor_temperature_c=30.0)
CPU = torch.device("cpu")


def _gratings(period: float, amplitude: float, n: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """64 px sine gratings at 100 DN (random orientations and phases) with the paper model's noise, seeded; and the
    true sigma of each patch's noise."""
    rng = np.random.default_rng(5)
    yy, xx = np.mgrid[0:64, 0:64]
    model = NoiseModel()
    noisy, truth = [], []
    for a in rng.uniform(0, np.pi, n):
        clean = 100.0 + amplitude * np.sin(2 * np.pi * (np.cos(a) * xx + np.sin(a) * yy) / period + rng.uniform(0, 6.3))
        img, sig = model.simulate(clean.astype(np.float32), META, rng, mode="sequential")
        noisy.append(img)
        truth.append(sig["total"])
    return np.stack(noisy).astype(np.float32), np.array(truth)


def _spectral_sigma(noisy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the spectral scale in DN: exp of the scalar times the reference scale, the reference scale)."""
    tables = PhysicsPrior(NoiseModel()).tables(META)[None]
    _, scalars, phys = compact_inputs(noisy, tables, np.zeros(len(noisy), np.int64), spectral=True)
    assert scalars.shape == (len(noisy), N_SCALARS + N_SPECTRAL)
    return np.exp(scalars[:, -1]) * phys["reference"], phys["reference"]


@pytest.mark.parametrize("period, amplitude", [(2.0, 40.0), (3.0, 15.0), (4.0, 40.0)])
def test_spectral_scale_reads_the_noise_under_a_fine_grating(period, amplitude):
    """Gratings of 2-4 px periods the reference scale reads as twice the noise or more on average: the spectral
    scale within 10 % of the true noise on every patch; on flat patches it agrees with the truth (and, within both estimates' scatter, the reference)."""
    noisy, truth = _gratings(period, amplitude)
    sigma, reference = _spectral_sigma(noisy)
    assert np.mean(reference / truth) > 2.0 and np.all(np.abs(sigma / truth - 1.0) < 0.1)
    flat, flat_truth = _gratings(5.0, 0.0)
    sigma, reference = _spectral_sigma(flat)
    assert np.all(np.abs(sigma / reference - 1.0) < 0.15) and np.all(np.abs(sigma / flat_truth - 1.0) < 0.1)


@pytest.fixture(scope="module")
def weights(tmp_path_factory: pytest.TempPathFactory):
    """Weights with the shape trend and a confidence head but no spectral input (2 steps each)."""
    out = tmp_path_factory.mktemp("no_spectral")
    data = generate(16, 32, seed=9, group=8, progress=False)
    base = train(TrainSettings("full_meta", steps=2, batch=4, shape_trend=True), data, out / "m", threads=1,
                 progress=False)
    head = train(TrainSettings("full_meta", steps=2, batch=4, confidence=True), data, out / "h", threads=1,
                 progress=False, init=base)
    return data, head


def test_weights_widened_for_the_spectral_input_read_as_before(weights, widened_reads_as_before):
    """``with_new_inputs`` after the trend's columns: every patch reads as before, torch and ONNX alike (ONNX
    Runtime tells trend and spectral inputs from the scalar width)."""
    ck = torch.load(weights[1], weights_only=True)
    cfg = replace(network_from_checkpoint(ck).cfg, spectral=True)
    widened_reads_as_before(ck, cfg, cfg.n_pooled + N_SCALARS + N_SHAPE_TREND, N_SPECTRAL, _gratings(3.0, 15.0, n=4)[0],
                            META, (True, True))


def test_training_with_the_spectral_input_widens_the_init(tmp_path, weights):
    """``TrainSettings.spectral`` from weights without it: the first MLP layer gains one column after the trend's
    (zero at the start, trained after); a head trained on the result keeps it."""
    data, path = weights
    before = torch.load(path, weights_only=True)
    out = train(TrainSettings("full_meta", steps=2, batch=4, spectral=True), data, tmp_path / "m", threads=1,
                progress=False, init=path)
    after = torch.load(out, weights_only=True)
    assert after["config"]["spectral"] is True and after["config"]["shape_trend"] is True
    w0, w1 = before["state_dict"]["mlp.0.weight"], after["state_dict"]["mlp.0.weight"]
    assert w1.shape == (w0.shape[0], w0.shape[1] + N_SPECTRAL)
    at = network_from_checkpoint(after).cfg.n_pooled + N_SCALARS + N_SHAPE_TREND
    assert torch.count_nonzero(w1[:, at:at + N_SPECTRAL]) > 0
    head = train(TrainSettings("full_meta", steps=2, batch=4, confidence=True), data, tmp_path / "h", threads=1,
                 progress=False, init=out)
    est = FullMetaEstimator(torch.load(head, weights_only=True), CPU, backend="onnx")
    assert est._extra_scalars == (True, True) and np.all(np.isfinite(est.predict(_gratings(2.0, 5.0, 2)[0], META)["sigma_image"]))
