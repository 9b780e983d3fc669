"""Effects outside the library on a field-like campaign (issue 14, item 4): ``simulate-bag --scenario
campaign`` frames (photographic scene, sub-pixel pans between holds of varying length, auto-exposure,
temperature drifting every frame, vignetting) with one outside effect applied through the simulator's frame
hook in sensor coordinates (``outside_effects.campaign_bag``), analysed end to end from the MCAP bag.
Without a plug-in no built-in is claimed and the signature names the effect's traits; with the plug-in a
user writes for it, the plug-in ranks first, is the only claim and cuts rms_error_dn by >= 70 %."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest
import torch

from noise_monitor.bag.simulate import load_truth, simulate_bag
from noise_monitor.cli import main
from noise_monitor.lab import analyze
from noise_monitor.physics.metadata import DYNAMIC_FIELDS

torch.set_num_threads(1)

_spec = importlib.util.spec_from_file_location("outside_effects", Path(__file__).with_name("outside_effects.py"))
outside = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(outside)

#: a small campaign: 64 frames of 160x128 (about 6 holds), seeded
CAMPAIGN = {"scenario": "campaign", "seed": 3, "frames": 64, "width": 160, "height": 128}


pytestmark = pytest.mark.usefixtures("builtins_only")


def test_the_hook_acts_in_sensor_coordinates_with_the_true_metadata(tmp_path: Path) -> None:
    """The effect sees each frame's true metadata (the truth sidecar's) and the sensor's own pixel grid:
    telegraph pixels are the same sensor pixels in every frame while the scene pans under them."""
    hook = outside.SensorEffect("rts", outside.TRUTH["rts"], seed=5)
    bag = simulate_bag(tmp_path / "rts.mcap", "ev76c661", "campaign", frames=24, width=96, height=64, fps=10.0,
                       seed=2, frame_hook=hook)
    truth = load_truth(bag)
    assert [{k: getattr(m, k) for k in DYNAMIC_FIELDS} for m in hook.seen] == [f["true_metadata"] for f in truth["frames"]]
    assert truth["frame_hook"] == {"outside_effect": "rts", "params": outside.TRUTH["rts"], "seed": 5}
    assert len({f["offset_px"][0] for f in truth["frames"]}) > 2  # the scene panned
    assert hook._maps is not None and hook._maps[1].shape == (64, 96)


@pytest.mark.parametrize("effect", ["amp_glow", "row_noise", "rts"])
def test_outside_effect_on_a_field_like_campaign(effect: str, tmp_path: Path) -> None:
    name, param, truth = outside.PLUGIN_TRUTH[effect]
    bag = outside.campaign_bag(tmp_path / f"{effect}.mcap", effect, **CAMPAIGN)
    plugin = tmp_path / f"{effect}_plugin.py"
    plugin.write_text(outside.PLUGINS[effect])
    bare = analyze(bag, "ev76c661", estimator=None)
    claimed = [c["effect"] for c in bare["candidates"] if c["significant"]]
    assert not claimed, [(c["effect"], c["components"]) for c in bare["candidates"] if c["significant"]]
    un = bare["unexplained"]
    assert un["significant"], un["reading"]
    if effect == "amp_glow":  # the corner stays in sensor coordinates while the scene pans
        assert un["kind"] == "temporal" and "a region: towards the top-right corner" in un["traits"]
        assert un["spatial"]["shape"] == "top-right corner" and un["law"]["gain_power"] == 2  # electrons
    elif effect == "row_noise":
        assert un["kind"] == "temporal" and un["traits"] == ["rows changing from frame to frame"]
        assert un["law"]["gain_power"] == 0  # in DN, after the gain
    else:  # fixed sensor pixels under the pans; on this short campaign too few stand out in two other
        # views to be confirmed as offset in every frame (the 120-frame campaign names that trait too)
        assert "isolated pixels blinking from frame to frame" in un["traits"]
        assert un["suggested"]["distribution"] == "mixture"
    written = tmp_path / "extended.yaml"
    summary = analyze(bag, "ev76c661", plugins=[plugin], add_effects=[f"{name}=fit"], estimator=None,
                      write_profile=written)
    # the profile names the plug-in file its effect comes from (2026-11-29: it did not, and loading it without the
    # plug-in said only "unknown effect")
    assert written.read_text().startswith(f"# effects from the plug-in file {plugin}: load it with --effect-plugin")
    names = [c["effect"] for c in summary["candidates"]]
    assert names[0] == name, names[:3]
    assert [c["effect"] for c in summary["candidates"] if c["significant"]] == [name]
    assert summary["rms_error_after_dn"] <= 0.3 * summary["rms_error_before_dn"]
    fitted = summary["added_effects"][0]["fitted"]
    if effect == "rts":  # the frame-to-frame variance fraction x q (1 - q) x amplitude^2 is what is measured; on this
        # short campaign the fraction sits at its upper limit (0.2 for 0.02) and the product reads high: 6.61 (2026-11-30
        # morning), 6.68 once a cell's error is floored by its segment's spread, for 5.12
        t = outside.TRUTH["rts"]
        assert fitted["fraction"] * fitted["amplitude_dn"] ** 2 == pytest.approx(t["fraction"] * t["amplitude_dn"] ** 2,
                                                                                 rel=0.35)
    else:
        assert fitted[param] == pytest.approx(truth, rel=0.15)


def test_a_built_in_standing_for_an_outside_effect_leaves_more_than_the_scatter(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """A compressing response (outside the library) on a short campaign (seed 1): the gain error stands in for it
    (claimed at 0.85), and what that claim leaves is far beyond the measurement's scatter, most of it in the temporal
    noise (a response bends it with the signal, a gain error scales it): the CLI says the diagnosis is not complete
    (`bench_outside_effects.py --sets campaign_short`: 4 of seeds 1-5 so)."""
    bag = outside.campaign_bag(tmp_path / "nonlinearity.mcap", "nonlinearity", **{**CAMPAIGN, "seed": 1})
    js = tmp_path / "out.json"
    assert main(["analyze", str(bag), "--profile", "ev76c661", "--no-estimator", "--quiet", "--json", str(js)]) == 0
    out = capsys.readouterr().out
    left = json.loads(js.read_text())["left_by_claims"]
    assert left["claimed"] == ["gain_error"] and left["significant"] and left["chi2"] > 1.5 * left["dof"]
    comps = left["rms_error_by_component_dn"]
    assert max(comps, key=comps.get) == "temporal" and left["at_limit"] == []
    assert "left by the claims (gain_error)" in out and "the claims do not explain all of it" in out
