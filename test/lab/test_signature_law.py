"""The residual's law for a fixed pattern measured across camera poses: each cell's fixed variance is a cross energy
with other views, a_here x a_partner, so for a pattern of variance ~ I^n it grows as (I_here I_partner)^(n/2). Fitted
against the cell's own intensity (as it was), a PRNU (n = 2) read as "proportional to the intensity" and the plug-in
skeleton written from it had the wrong law."""
from __future__ import annotations

from pathlib import Path

import pytest
import torch

from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.lab import analyze
from noise_monitor.lab.signature import cross_view_condition

torch.set_num_threads(1)


def test_a_cross_view_condition_is_the_geometric_mean_over_the_views() -> None:
    exposure = {0: 0.01, 1: 0.04, 2: 0.16}
    assert cross_view_condition(exposure, 0, {1: 1.0}) == pytest.approx(0.02)
    assert cross_view_condition(exposure, 0, {1: 0.5, 2: 0.5}) == pytest.approx((0.01 * (0.04 * 0.16) ** 0.5) ** 0.5)


def test_a_prnu_reads_as_growing_with_the_intensity_squared(tmp_path: Path) -> None:
    """A 2 % PRNU on a 64-frame campaign (holds at several poses): before, intensity power 1, amplitude 4.8 DN^2 at
    128 DN (truth 6.55) and a skeleton with ``(v / 128) ** 1``; now power 2 and the skeleton's law with it."""
    bag = simulate_bag(tmp_path / "prnu.mcap", "ev76c661", "campaign", frames=64, width=160, height=128, seed=3,
                       effects=["prnu=2"], fps=10.0)
    skeleton = tmp_path / "skeleton.py"
    lab = analyze(bag, "ev76c661", estimator=None, write_plugin_skeleton=skeleton)
    crossed = [r for r in lab["cells"] if "cross_view" in r]
    assert crossed and all(r["cross_view"]["partners"] for r in crossed)
    law = lab["unexplained"]["law"]
    assert lab["unexplained"]["dominant_component"] == "fixed" and not lab["unexplained"]["scene_may_explain"]
    assert (law["intensity_power"], law["exposure_power"], law["gain_power"]) == (2, 0, 0)
    assert law["amplitude_dn2"] == pytest.approx((0.02 * 128.0) ** 2, rel=0.2)
    assert "law = (v / 128) ** 2" in skeleton.read_text()


def test_a_skeletons_structure_follows_the_line_traits_beside_a_pixel_wise_dominant_component():
    """A single view's residual (no hold to split it): the dominant component is pixel-wise ('single') but rows are
    significant; the skeleton said "Seen: ...; rows" with ``structure = "pixel"`` until 2026-12-04."""
    from noise_monitor.lab.signature import LINE_TRAITS, _suggest

    sig = {"traits": [LINE_TRAITS["row"]], "dominant_component": "single", "sign": "excess", "kind": "fixed",
           "spatial": None}
    assert _suggest(sig)["structure"] == "row"
    both = {**sig, "traits": [LINE_TRAITS["row"], LINE_TRAITS["column"]]}
    assert _suggest(both)["structure"] == "pixel"  # rows and columns: no one line structure
    assert _suggest({**sig, "dominant_component": "column"})["structure"] == "column"


def test_a_recording_without_a_still_view_names_the_scene_as_an_alternative(tmp_path):
    """A clean camera that never held still (vibrating by 4 px): every component is a single frame's, where scene
    texture reads as noise; until 2026-12-04 the lab reported "unexplained: fixed noise ... rows" without a word of
    the scene (rms error 0.000 DN), and until later that day counted it as unexplained and wrote a plug-in skeleton for
    it: now it is not established (an effect or the scene), and the skeleton waits for a recording that tells."""
    bag = simulate_bag(tmp_path / "vib.mcap", "ev76c661", "campaign", frames=40, width=160, height=128,
                       vibration_px=4.0)
    lab = analyze(bag, "ev76c661", estimator=None, write_plugin_skeleton=tmp_path / "skel.py")
    un = lab["unexplained"]
    assert un["residual_significant"] and un["scene_may_explain"] and not un["significant"]
    assert "the recording holds no still view" in un["reading"]
    assert not (tmp_path / "skel.py").exists() and "scene's texture" in lab["plugin_skeleton_not_written"]
