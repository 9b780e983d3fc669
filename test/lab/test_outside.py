"""Effects outside the library (issue 14, items 3 and 4): four effects the library does not have, simulated
in numpy apart from the plug-in API (``outside_effects.py``). Without a plug-in the summary names the
residual's traits and claims no built-in; with the plug-in a user writes for it, the plug-in ranks first,
is the only significant candidate, recovers the effect and cuts rms_error_dn by >= 70 %."""
from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import pytest
import torch

from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.cli import main
from noise_monitor.lab import analyze
from noise_monitor.lab.compare import Comparison, baseline_effects
from noise_monitor.lab.diagnose import EffectSpec, fit
from noise_monitor.lab.measure import measure_frames
from noise_monitor.physics import NoiseModel, load_plugin_file, load_profile
from noise_monitor.physics.effects import registry

torch.set_num_threads(1)

_spec = importlib.util.spec_from_file_location("outside_effects", Path(__file__).with_name("outside_effects.py"))
outside = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(outside)
PLUGIN_TRUTH, PLUGINS, TRUTH, simulate = outside.PLUGIN_TRUTH, outside.PLUGINS, outside.TRUTH, outside.simulate

PROFILE = load_profile("ev76c661")


@pytest.fixture(autouse=True)
def _restore_registry(monkeypatch: pytest.MonkeyPatch) -> None:
    """Plug-ins registered here must not leak into other tests of the session."""
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))


def _plugin(tmp_path: Path, effect: str) -> Path:
    path = tmp_path / f"{effect}_plugin.py"
    path.write_text(PLUGINS[effect])
    return path


#: what the signature must say about each effect (before any plug-in exists)
def _check_signature(effect: str, un: dict) -> None:
    traits = " ".join(un["traits"])
    sug = un["suggested"]
    if effect == "amp_glow":
        assert un["kind"] == "temporal" and "top-right corner" in traits
        assert un["spatial"]["shape"] == "top-right corner" and un["spatial"]["significant"]
        assert un["law"]["exposure_power"] == 1 and un["law"]["gain_power"] == 2  # electrons, growing with t
        assert sug["spatial"] and sug["temporal"]
    elif effect == "row_noise":
        assert un["kind"] == "temporal" and "rows changing from frame to frame" in traits
        assert un["dominant_component"] == "temporal_row" and un["law"]["gain_power"] == 0  # in DN
        assert sug == {**sug, "distribution": "gaussian", "temporal": True, "structure": "row"}
    elif effect == "nonlinearity":
        assert un["sign"] == "deficit" and "reduces variance" in traits
        assert sug["distribution"] == "response"
    elif effect == "rts":
        assert un["kind"] == "temporal and fixed"
        assert "isolated pixels blinking from frame to frame" in traits
        assert "isolated pixels offset in every frame" in traits
        assert sug["distribution"] == "mixture" and sug["temporal_share"] == "both"


@pytest.mark.parametrize("effect", sorted(TRUTH))
def test_outside_effect_signature_and_plugin(effect: str, tmp_path: Path) -> None:
    name, param, truth = PLUGIN_TRUTH[effect]
    summary = analyze(simulate(PROFILE, effect), PROFILE, plugins=[_plugin(tmp_path, effect)],
                      add_effects=[f"{name}=fit"], estimator=None)
    un = summary["unexplained"]
    assert un["residual_significant"], un["reading"]
    _check_signature(effect, un)
    best = summary["candidates"][0]
    assert best["effect"] == name, [(c["effect"], c["delta_bic"]) for c in summary["candidates"][:3]]
    claimed = [c["effect"] for c in summary["candidates"] if c["significant"]]
    assert claimed == [name], claimed  # no built-in is claimed as the explanation
    assert un["explained_by"] == [name] and not un["significant"]
    assert summary["rms_error_after_dn"] <= 0.3 * summary["rms_error_before_dn"]
    fitted = summary["added_effects"][0]["fitted"]
    err = summary["added_effects"][0]["param_errors"]
    if effect == "rts":  # the frame-to-frame variance fraction x q (1 - q) x amplitude^2 is what is measured
        q = TRUTH["rts"]["q"]
        assert fitted["fraction"] * fitted["amplitude_dn"] ** 2 == pytest.approx(
            TRUTH["rts"]["fraction"] * TRUTH["rts"]["amplitude_dn"] ** 2, rel=0.3)
        assert q == 0.5
    else:
        assert fitted[param] == pytest.approx(truth, rel=0.1)
        assert 0.0 < err[param] < 0.1 * truth


def test_clean_camera_leaves_nothing_unexplained() -> None:
    summary = analyze(simulate(PROFILE, None), PROFILE, estimator=None)
    assert not [c["effect"] for c in summary["candidates"] if c["significant"]]
    un = summary["unexplained"]
    assert not un["significant"] and not un["residual_significant"], un["reading"]


def test_unexplained_summary_and_plugin_skeleton_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """A bag with temporal row noise (simulated through the plug-in's default row sampler): the CLI says
    what is unexplained, writes a skeleton, and the skeleton as written fits and cuts the error."""
    load_plugin_file(_plugin(tmp_path, "row_noise"))
    bag = simulate_bag(tmp_path / "rows.mcap", "ev76c661", "lab", effects=["temporal_row_noise=2"], frames=48,
                       width=160, height=128, seed=3)
    registry._REGISTRY.pop("temporal_row_noise")  # the user's analysis does not know the effect yet
    skeleton, js = tmp_path / "my_rows.py", tmp_path / "s.json"
    assert main(["analyze", str(bag), "--profile", "ev76c661", "--write-plugin-skeleton", str(skeleton),
                 "--json", str(js), "--no-estimator", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "no candidate effect is significant" in out and "unexplained: temporal noise" in out
    summary = json.loads(js.read_text())
    assert summary["unexplained"]["significant"] and summary["plugin_skeleton_written"] == str(skeleton)
    source = skeleton.read_text()
    assert 'structure = "row"' in source and "temporal = True" in source and 'distribution = "gaussian"' in source
    assert load_plugin_file(skeleton) == ["unexplained_effect"]
    after = analyze(bag, "ev76c661", plugins=[skeleton], add_effects=["unexplained_effect=fit"], estimator=None)
    assert after["candidates"][0]["effect"] == "unexplained_effect" and after["candidates"][0]["significant"]
    # the model's error (net of the measurement's scatter) falls by >= 70 %; the raw rms falls by >= 69 %:
    # its floor (0.18 DN) is the measurement's own scatter on this 48-frame lab bag
    assert after["rms_error_after_dn"] <= 0.3 * after["rms_error_before_dn"]
    assert after["rms_error_after_raw_dn"] <= 0.31 * after["rms_error_before_raw_dn"]
    print(f"skeleton fit: net {after['rms_error_before_dn']:.4f} -> {after['rms_error_after_dn']:.4f} DN, raw "
          f"{after['rms_error_before_raw_dn']:.4f} -> {after['rms_error_after_raw_dn']:.4f} DN")
    assert after["added_effects"][0]["fitted"]["amplitude"] == pytest.approx(2.0, rel=0.1)


def test_skeleton_needs_a_significant_residual(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """A clean camera: no skeleton, said so; the analysis and its JSON stand (until 2026-12-04 exit 2, all lost)."""
    bag = simulate_bag(tmp_path / "clean.mcap", "ev76c661", "lab", frames=16, width=96, height=64, seed=1)
    js = tmp_path / "clean.json"
    assert main(["analyze", str(bag), "--profile", "ev76c661", "--write-plugin-skeleton", str(tmp_path / "x.py"),
                 "--no-estimator", "--quiet", "--json", str(js)]) == 0
    out = capsys.readouterr().out
    assert "no plug-in skeleton written: the residual is within the measurement's uncertainty" in out
    assert not (tmp_path / "x.py").exists() and "plugin_skeleton_not_written" in js.read_text()


def test_degenerate_fit_reports_the_range_not_a_tight_error(tmp_path: Path) -> None:
    """Telegraph pixels at q = 0.5 with the fraction and amplitude both free on a bag without them: the
    fit sits at zero amplitude where the fraction is unidentified; its error spans the allowed range."""
    load_plugin_file(_plugin(tmp_path, "rts"))
    meas = measure_frames(simulate(PROFILE, None, frames_per_condition=3))
    comp = Comparison(meas, NoiseModel(baseline_effects(PROFILE, meas.segments[0].meta, True)))
    res = fit(comp, [EffectSpec(registry.effect_class("telegraph_pixels"), {"amplitude_dn": 0.0}, ("fraction",))])
    assert res.degenerate == {"telegraph_pixels": ["fraction"]}
    assert res.errors["telegraph_pixels"]["fraction"] >= 0.05  # a quarter of the range or more, not ~0
    assert math.isfinite(res.chi2)

