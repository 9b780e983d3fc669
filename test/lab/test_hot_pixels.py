"""Bright hot pixels on a field-like campaign (textured scene, pans between holds, exposures of 2-60 ms at
30-55 degC): the lab recovers their fraction and dark current, and says when the data only bound it."""
from __future__ import annotations

from pathlib import Path

import pytest
import torch

from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.lab import analyze

torch.set_num_threads(1)

PROFILE = "ev76c661"
FRACTION = 0.005


def _fit(tmp: Path, multiplier: float) -> dict:
    """Simulate a 60-frame 160x128 campaign bag with hidden hot pixels and fit them."""
    bag = simulate_bag(tmp / "hot.mcap", PROFILE, "campaign", frames=60, width=160, height=128, fps=10.0, seed=5,
                       effects=[f"hot_pixels:fraction={FRACTION},dark_multiplier={multiplier}"])
    return analyze(bag, PROFILE, add_effects=["hot_pixels=fit"], candidates=["hot_pixels"], estimator=None)


def test_hot_pixels_partly_saturated_are_fitted(tmp_path: Path) -> None:
    """30 x the dark current: 10-40 DN at short exposures, clipped at 255 DN at long ones. Blocks holding a
    hot pixel used to pass the texture test (fraction x 2), and the cross-view and outlier-confirmation
    model mis-sized unsaturated ones (fitted at 1.3 x instead of 30 x)."""
    s = _fit(tmp_path, 30.0)
    fitted = s["added_effects"][0]["fitted"]
    assert fitted["fraction"] == pytest.approx(FRACTION, rel=0.15)
    assert fitted["dark_multiplier"] == pytest.approx(30.0, rel=0.15)
    assert s["added_effects"][0]["degenerate"] == []
    assert s["rms_error_after_dn"] <= 0.4 * s["rms_error_before_dn"]


def test_hot_pixels_saturated_everywhere_give_a_lower_bound(tmp_path: Path) -> None:
    """1000 x the dark current: 255 DN in every hold, so only a lower bound of the dark current is known;
    the fraction is fitted and the multiplier reported as not identified, with the range that fits, in the readings too."""
    s = _fit(tmp_path, 1000.0)
    added = s["added_effects"][0]
    assert added["fitted"]["fraction"] == pytest.approx(FRACTION, rel=0.15)
    assert added["degenerate"] == ["dark_multiplier"]
    low, high = added["param_ranges"]["dark_multiplier"]
    assert 100.0 < low < 1000.0 and high == pytest.approx(1e7)
    assert s["rms_error_after_dn"] <= 0.4 * s["rms_error_before_dn"]
    # the readings say so: the value the fit stopped at is no measurement
    span = f"(not identified by these data: dark_multiplier anywhere from {low:.3g} to {high:.3g} fits as well)"
    assert added["reading"].endswith(span)
    (cand,) = s["candidates"]
    assert cand["significant"] and cand["degenerate"] == ["dark_multiplier"]
    assert s["diagnosis"].startswith("most likely missing effect: ") and "dark_multiplier anywhere from" in s["diagnosis"]
