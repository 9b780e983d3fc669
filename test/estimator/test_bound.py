"""The image-only upper bound of the noise: at its coverage on white noise, above the truth under scene
content, clipped blocks left out, and the bound-proven alarms of the held-out scoring."""
from __future__ import annotations

import numpy as np
import pytest

from noise_monitor.estimator import load
from noise_monitor.estimator.bound import COVERAGE, bound_factor, noise_upper_bound, usable_blocks
from noise_monitor.estimator.data import generate, metas_of
from noise_monitor.estimator.evaluate import score
from noise_monitor.estimator.residuals import block_energies, immerkaer


def _bound(noisy: np.ndarray) -> np.ndarray:
    noisy = noisy.astype(np.float32)
    return noise_upper_bound(noisy, block_energies(immerkaer(noisy)))


@pytest.mark.parametrize("size", [64, 128])
def test_bound_falls_below_white_noise_at_its_coverage(size):
    rng = np.random.default_rng(size)
    sigma = rng.uniform(0.5, 10.0, 1500)
    ub = _bound(128.0 + sigma[:, None, None] * rng.standard_normal((1500, size, size)))
    miss = float(np.mean(ub < sigma))
    assert abs(miss - (1.0 - COVERAGE)) < 0.008, miss  # 1 %, binomial sd 0.26 %
    assert np.median(ub / sigma) < 1.25  # and tight: a low quantile, not a maximum


def test_clipped_blocks_are_left_out():
    rng = np.random.default_rng(1)
    noisy = 128.0 + 4.0 * rng.standard_normal((300, 64, 64))
    noisy[:, :, 32:] = 255.0  # the right half saturated: no noise there
    assert usable_blocks(noisy.astype(np.float32)).sum(axis=1).max() == 8 * 3  # columns 0-23: one pixel from the edge
    ub = _bound(noisy)
    assert np.mean(ub < 4.0) < 0.03 and np.all(np.isfinite(ub))
    assert np.isinf(_bound(np.full((1, 64, 64), 255.0)))[0]
    assert bound_factor(24) < bound_factor(64)  # fewer blocks: a looser bound


def test_bound_holds_under_scene_content():
    """On crops of the photographs (texture, edges, the model's intensity-dependent noise) the bound stays
    above the true noise, and xi_lower = sigma_model - sigma_image_upper."""
    d = generate(240, 64, seed=43, split="train", photo_variants=3, progress=False)
    p = load("full_meta", device="cpu").predict(d["noisy"], metas_of(d))
    miss = p["sigma_image_upper"] < d["truth_sigma_image"]
    print(f"bound below the truth on {miss.mean():.2%}; median bound / truth {np.median(p['sigma_image_upper'] / d['truth_sigma_image']):.2f}")
    assert miss.mean() <= 0.02
    np.testing.assert_allclose(p["xi_lower"], p["sigma_model"] - p["sigma_image_upper"])
    assert np.mean(p["sigma_image"] <= p["sigma_image_upper"]) > 0.97


def test_score_counts_alarms_the_bound_proves():
    """A declined patch whose bound proves xi > 1 DN is decided (an alarm of sign +), at max(xi, xi_lower)."""
    data = {"truth_xi": np.array([3.0, 3.0, -3.0, 0.0]), "truth_sigma_image": np.full(4, 2.0)}
    pred = {"xi": np.array([0.5, 0.5, -0.5, 0.0]), "measurable": np.zeros(4, bool),
            "sigma_image_error": np.full(4, 2.0), "sigma_image": np.full(4, 2.0),
            "xi_lower": np.array([1.4, 0.6, -5.0, -1.0])}
    d = score(pred, data, "b")["decided"]
    assert d["coverage"] == pytest.approx(0.25) and d["hit_rate"] == pytest.approx(1 / 3, abs=1e-4)
    assert d["xi"]["rms"] == pytest.approx(1.6)
