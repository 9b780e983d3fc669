"""Claims by forward selection: a candidate significant alone is claimed only if it is significant beyond the
explanations claimed before it. Two effects present together are both claimed; a built-in that only
partly reproduces the residual of an effect outside the library (with the user's plug-in for it) is
not, and is reported as explained by the plug-in, in the JSON, the CLI and the HTML report. An effect that
its residual masks alone (10 e- of read noise beside a DSNU) is claimed beyond the first claim."""
from __future__ import annotations

import json
from pathlib import Path
from types import ModuleType

import pytest
import torch

from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.cli import main
from noise_monitor.lab import analyze

torch.set_num_threads(1)

PROFILE = "ev76c661"
#: a small campaign: 64 frames of 160x128 (about 6 holds), seeded
SMALL = {"frames": 64, "width": 160, "height": 128, "seed": 1}

pytestmark = pytest.mark.usefixtures("builtins_only")


@pytest.mark.parametrize("hidden", [("prnu=1", "column_offsets=2"), ("extra_read_noise=15", "dsnu=0.3")])
def test_two_effects_present_together_are_both_claimed(hidden: tuple[str, str], tmp_path: Path) -> None:
    bag = simulate_bag(tmp_path / "pair.mcap", PROFILE, "campaign", effects=list(hidden), fps=10.0, **SMALL)
    cands = analyze(bag, PROFILE, estimator=None)["candidates"]
    names = [h.split("=")[0] for h in hidden]
    claimed = [c for c in cands if c["significant"]]
    assert set(names) <= {c["effect"] for c in claimed}, [(c["effect"], c["rank"], c["beyond"]) for c in cands[:6]]
    ranks = {c["rank"] for c in cands if c["effect"] in names}
    assert {c["rank"] for c in claimed} == ranks  # nothing else, but for candidates equivalent to them
    assert all(c["significant_alone"] and not c["explained_by"] for c in claimed)
    second = max(ranks)
    later = next(c for c in claimed if c["rank"] == second)
    assert later["beyond"]["significant"] and later["beyond"]["reading"].startswith("significant beyond ")
    assert later["beyond"]["given"] == [next(c["effect"] for c in claimed if c["rank"] == min(ranks))]


def test_an_effect_masked_by_the_first_is_claimed_beyond_it(tmp_path: Path) -> None:
    """10 e- of extra read noise beside a DSNU of 0.3: alone the read noise is not significant (the DSNU's
    residual dominates every cell), on top of the claimed DSNU it is, and fitted right."""
    bag = simulate_bag(tmp_path / "masked.mcap", PROFILE, "campaign", effects=["extra_read_noise=10", "dsnu=0.3"],
                       fps=10.0, **SMALL)
    cands = {c["effect"]: c for c in analyze(bag, PROFILE, estimator=None)["candidates"]}
    dsnu, read = cands["dsnu"], cands["extra_read_noise"]
    assert dsnu["rank"] == 1 and dsnu["significant"] and dsnu["significant_alone"]
    assert read["significant"] and not read["significant_alone"] and not read["explained_by"]
    assert read["beyond"]["given"] == ["dsnu"] and read["beyond"]["params"]["sigma_e"] == pytest.approx(10.0, rel=0.1)
    assert read["beyond"]["reading"].endswith("though not alone: its residual masked it")


@pytest.mark.parametrize("effect, partial", [("nonlinearity", "gain_error")])
def test_a_partial_explanation_is_not_claimed(outside: ModuleType, effect: str, partial: str, tmp_path: Path,
                                              capsys: pytest.CaptureFixture) -> None:
    """A lower gain reproduces part of a compressing response's missing noise: significant alone, nothing
    beyond the plug-in. (A PRNU standing for telegraph pixels below the outlier threshold, the other partial
    explanation met on these campaigns, is contradicted by the fixed pattern's shape: test_fixed_shape.py.)"""
    name = outside.PLUGIN_TRUTH[effect][0]
    bag = outside.campaign_bag(tmp_path / f"{effect}.mcap", effect, **SMALL)
    plugin = tmp_path / f"{effect}_plugin.py"
    plugin.write_text(outside.PLUGINS[effect])
    assert main(["analyze", str(bag), "--profile", PROFILE, "--effect-plugin", str(plugin), "--quiet",
                 "--no-estimator", "--report", str(tmp_path / "report")]) == 0
    out = capsys.readouterr().out
    summary = json.loads((tmp_path / "report" / "summary.json").read_text())
    cands = {c["effect"]: c for c in summary["candidates"]}
    assert summary["candidates"][0]["effect"] == name
    assert [c["effect"] for c in summary["candidates"] if c["significant"]] == [name]
    part = cands[partial]
    assert part["significant_alone"] and not part["significant"] and part["explained_by"] == [name]
    beyond = part["beyond"]
    assert not beyond["significant"] and {"F-test", "explained fraction"} & set(beyond["failed"])
    assert beyond["chi2_given"] == pytest.approx(cands[name]["chi2"], abs=1e-3)
    reading = f"significant alone, but partly reproduces the same residual as {name}; nothing significant beyond it"
    assert beyond["reading"].startswith(reading)
    assert summary["diagnosis"] == f"most likely missing effect: {cands[name]['reading']}"
    assert reading in (tmp_path / "report" / "report.html").read_text()
    assert f"~ {partial}: {reading}" in out
