"""The optional shape-trend input (``features.shape_trend``, ``train --shape-trend``): what it reads on ramps,
and that weights without it are widened to take it without changing a reading (ONNX and torch alike)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from noise_monitor.estimator.data import generate
from noise_monitor.estimator.features import N_SCALARS, N_SHAPE_TREND, compact_inputs
from noise_monitor.estimator.inference import FullMetaEstimator
from noise_monitor.estimator.networks import network_from_checkpoint
from noise_monitor.estimator.physics_prior import PhysicsPrior
from noise_monitor.estimator.train import TrainSettings, train
from noise_monitor.physics import NoiseModel, load_profile

META = load_profile("icx285").metadata(gain_db=6.0, exposure_time_s=0.01, sensor_temperature_c=30.0)
CPU = torch.device("cpu")


@pytest.fixture(scope="module")
def data() -> dict[str, np.ndarray]:
    return generate(16, 32, seed=9, group=8, progress=False)


@pytest.fixture(scope="module")
def no_trend(tmp_path_factory: pytest.TempPathFactory, data: dict[str, np.ndarray]):
    """Weights without the trend input but with a confidence head (a measurement, then its head; 2 steps each)."""
    out = tmp_path_factory.mktemp("no_trend")
    base = train(TrainSettings("full_meta", steps=2, batch=4), data, out / "m", threads=1, progress=False)
    return train(TrainSettings("full_meta", steps=2, batch=4, confidence=True), data, out / "h", threads=1,
                 progress=False, init=base)


def _ramps(model: NoiseModel, n: int = 12) -> np.ndarray:
    """64 px horizontal ramps from 20 to 220 DN (noise-free edges: none) with ``model``'s noise, seeded."""
    rng = np.random.default_rng(11)
    clean = np.tile(np.linspace(20.0, 220.0, 64, dtype=np.float32), (64, 1))
    return np.stack([np.clip(model.simulate(clean, META, rng)[0], 0, 255) for _ in range(n)]).astype(np.float32)


def test_shape_trend_reads_a_noise_steeper_than_stated():
    """On ramps the trend is ~0 when the stated model is the noise's and clearly positive with a 3 % PRNU the
    stated model lacks; the second scalar is the ramp's intensity span (the halves' median ratio ~3.2)."""
    tables = PhysicsPrior(NoiseModel()).tables(META)[None]
    trend = {}
    for name, truth in (("stated", NoiseModel()), ("prnu", NoiseModel(extra={"prnu": {"sigma_pct": 3.0}}))):
        noisy = _ramps(truth)
        _, scalars, _ = compact_inputs(noisy, tables, np.zeros(len(noisy), np.int64), trend=True)
        assert scalars.shape == (len(noisy), N_SCALARS + N_SHAPE_TREND)
        trend[name] = scalars[:, -2:]
    assert abs(np.median(trend["stated"][:, 0])) < 0.15 and np.median(trend["prnu"][:, 0]) > 0.4, trend
    assert np.allclose(trend["stated"][:, 1], trend["prnu"][:, 1], atol=0.05)
    assert np.all(np.abs(trend["stated"][:, 1] - np.log(170.0 / 70.0)) < 0.15)


def test_weights_widened_for_the_trend_read_as_before(no_trend, widened_reads_as_before):
    """``with_new_inputs``: weights with a head widened to take the trend scalars read every patch as before,
    under torch and ONNX Runtime (which tells the input from the session's scalar width)."""
    ck = torch.load(no_trend, weights_only=True)
    assert not ck["config"].get("shape_trend") and ck["config"]["confidence"]
    cfg = replace(network_from_checkpoint(ck).cfg, shape_trend=True)
    widened_reads_as_before(ck, cfg, cfg.n_pooled + N_SCALARS, N_SHAPE_TREND,
                            _ramps(NoiseModel(extra={"prnu": {"sigma_pct": 3.0}}), n=6), META, (True, False))


def test_training_with_the_trend_widens_the_init_and_a_new_head_keeps_it(tmp_path, no_trend, data):
    """``TrainSettings.shape_trend`` from weights without it: the first MLP layer gains the trend's columns (zero
    at the start, trained after), every other weight of the measurement keeps its shape; a head trained alone on
    the result keeps the trend input and the widened weights load for inference."""
    before = torch.load(no_trend, weights_only=True)
    path = train(TrainSettings("full_meta", steps=2, batch=4, shape_trend=True), data, tmp_path / "m", threads=1,
                 progress=False, init=no_trend)
    after = torch.load(path, weights_only=True)
    assert after["config"]["shape_trend"] is True
    w0, w1 = before["state_dict"]["mlp.0.weight"], after["state_dict"]["mlp.0.weight"]
    assert w1.shape == (w0.shape[0], w0.shape[1] + N_SHAPE_TREND)
    at = network_from_checkpoint(after).cfg.n_pooled + N_SCALARS  # pooled features, then the scalars
    assert torch.count_nonzero(w1[:, at:at + N_SHAPE_TREND]) > 0  # the trend's columns started at 0 and trained
    head = train(TrainSettings("full_meta", steps=2, batch=4, confidence=True), data, tmp_path / "h", threads=1,
                 progress=False, init=path)
    ck = torch.load(head, weights_only=True)
    assert ck["config"]["shape_trend"] is True
    est = FullMetaEstimator(ck, CPU, backend="onnx")
    assert est._extra_scalars == (True, False) and np.all(np.isfinite(est.predict(_ramps(NoiseModel(), n=2), META)["sigma_image"]))
