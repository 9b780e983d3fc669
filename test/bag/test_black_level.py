"""A camera whose images keep a black level (pedestal): stated in its profile, it comes off every image before the
model reads it (node, replay, lab), and the simulator's camera of that profile adds it."""
from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

from noise_monitor.bag.reader import BagReader
from noise_monitor.bag.replay import replay
from noise_monitor.bag.simulate import load_truth, simulate_bag
from noise_monitor.cli import main as cli_main
from noise_monitor.monitor import MonitorConfig
from noise_monitor.monitor.patches import select_patches
from noise_monitor.paths import share_dir
from noise_monitor.physics import CameraProfile, load_profile

torch.set_num_threads(1)
BLACK = 16.0  # a 10-bit sensor's 64 codes on the 8-bit scale


@pytest.fixture(scope="module")
def pedestal() -> CameraProfile:
    return dataclasses.replace(load_profile("ev76c661"), name="EV76C661 pedestal", black_level_dn=BLACK)


@pytest.fixture(scope="module")
def estimator():
    from noise_monitor.estimator import load

    return load("full_meta", device="cpu")


def test_the_simulated_camera_adds_its_black_level(tmp_path: Path, pedestal: CameraProfile) -> None:
    """The same seed with and without the pedestal: the images differ by the black level (to the 8-bit rounding
    and the ADC's clipping at 255), and the frames read with that profile have it taken off again."""
    plain = simulate_bag(tmp_path / "plain.mcap", "ev76c661", "static", frames=3, width=64, height=64, seed=2)
    raised = simulate_bag(tmp_path / "raised.mcap", pedestal, "static", frames=3, width=64, height=64, seed=2)
    assert load_truth(raised)["black_level_dn"] == BLACK and "black_level_dn" not in load_truth(plain)
    a = [f.image_dn for f in BagReader(plain).frames(load_profile("ev76c661"))]
    b = [f for f in BagReader(raised).frames(pedestal)]
    below = 0
    for x, f in zip(a, b):
        assert f.black_level_dn == BLACK
        unclipped = (x > 0.5) & (x < 255.0 - BLACK - 0.5)
        np.testing.assert_array_equal(f.image_dn[unclipped], x[unclipped])
        assert np.all(f.image_dn[x < 0.5] <= 0.0)  # the noise the camera without a pedestal clips at black ...
        below += int(np.sum(f.image_dn < 0.0))  # ... the pedestal keeps
    assert below > 0


def test_patches_clip_at_the_adcs_limits_above_the_black_level() -> None:
    """With the black level taken off, the ADC saturates at 255 - black: such pixels still make a patch
    saturated, and a dark patch is judged by its signal above the black level."""
    cfg = MonitorConfig(patches_per_frame=4)
    img = np.full((128, 128), 100.0, dtype=np.float32) + np.random.default_rng(0).normal(0.0, 2.0, (128, 128))
    img[:64, :64] = 255.0 - BLACK  # saturated codes, black level off
    sel = select_patches(img, 64, cfg, black_level=BLACK)
    assert sel.rejected["saturated"] == 1 and (0, 0) not in sel.corners
    assert select_patches(img, 64, cfg).rejected["saturated"] == 0  # read as if the ADC clipped at 255


def test_a_stated_black_level_keeps_xi_unbiased(tmp_path: Path, pedestal: CameraProfile, estimator) -> None:
    """A held-out campaign of that camera: replayed with its profile, xi is as without a pedestal (mean -0.01 DN);
    with a profile that does not state it, the pedestal is read as signal with shot noise that is not there
    (mean xi +0.15 DN on 100 frames, 2026-11-29). The noise the pedestal keeps below black is read clipped at black,
    as the model clips it (before, such patches stopped the replay with a ValueError of the estimator)."""
    bag = simulate_bag(tmp_path / "ped.mcap", pedestal, "campaign_heldout", frames=40, width=320, height=256,
                       fps=10.0, seed=33)
    kw = {"estimator": estimator, "progress": False, "plot": False}
    stated, unstated = replay(bag, pedestal, None, **kw), replay(bag, "ev76c661", None, **kw)
    assert stated["frames_processed"] == unstated["frames_processed"] == 40
    assert abs(stated["xi"]["mean"]) <= 0.05 and unstated["xi"]["mean"] >= 0.1


def test_the_black_level_as_a_node_parameter(tmp_path: Path, pedestal: CameraProfile, estimator) -> None:
    """The node parameter ``black_level_dn`` (a driver's setting; -1 = the profile's) does what the profile's key
    does: the pedestal camera replayed with the plain profile and the parameter reads as with the pedestal profile."""
    bag = simulate_bag(tmp_path / "ped.mcap", pedestal, "campaign_heldout", frames=12, width=192, height=128,
                       fps=10.0, seed=33)
    params = yaml.safe_load((share_dir() / "config" / "node.yaml").read_text())
    params["/**"]["ros__parameters"]["black_level_dn"] = BLACK
    (tmp_path / "node.yaml").write_text(yaml.safe_dump(params))
    kw = {"estimator": estimator, "progress": False, "plot": False}
    by_param = replay(bag, "ev76c661", None, config=tmp_path / "node.yaml", **kw)
    by_profile = replay(bag, pedestal, None, **kw)
    assert by_param["frames_processed"] == by_profile["frames_processed"] == 12
    assert by_param["xi"] == by_profile["xi"] and by_param["sigma_model"] == by_profile["sigma_model"]
    assert by_param["black_level_contradicted"] is None and by_profile["black_level_contradicted"] is None


def test_a_black_level_stated_above_the_cameras_is_reported(tmp_path: Path, estimator) -> None:
    """A camera without a pedestal replayed with a stated black level of 16 DN: its dark pixels read 16 DN below
    zero, far beyond its dark noise; such frames are processed and report it (WARN, the share of pixels below, the
    bound the image puts on the camera's black level: 8.1 DN over 60 frames of seed 3, 2026-11-29), and the summary
    names it. Before, the patches below zero stopped the replay with a ValueError of the estimator."""
    bag = simulate_bag(tmp_path / "plain.mcap", "ev76c661", "campaign_heldout", frames=20, width=320, height=256,
                       fps=10.0, seed=3)
    params = yaml.safe_load((share_dir() / "config" / "node.yaml").read_text())
    params["/**"]["ros__parameters"]["black_level_dn"] = BLACK
    (tmp_path / "node.yaml").write_text(yaml.safe_dump(params))
    out = replay(bag, "ev76c661", tmp_path / "out", config=tmp_path / "node.yaml", estimator=estimator,
                 progress=False, plot=False)
    assert out["frames_processed"] == 20
    black = out["black_level_contradicted"]
    assert black["frames"] >= 5 and black["stated_dn"] == BLACK and black["stated_by"] == "parameter"
    assert 0.0 <= black["camera_at_most_dn"] < 10.0
    rows = list(csv.DictReader((tmp_path / "out" / "replay.csv").open()))
    below = [r for r in rows if float(r["pixels_below_black_pct"]) > 0.2]
    assert len(below) == black["frames"] and all(int(r["level"]) >= 1 for r in below)


def test_the_lab_finds_a_hidden_effect_beside_an_unstated_black_level(tmp_path: Path, pedestal: CameraProfile) -> None:
    """Extra read noise of 8 e- on the pedestal camera: with its black level stated the lab claims it (8.1 e-);
    without, the pedestal's phantom shot noise and the extra read noise partly cancel, neither is significant alone
    (``black_level`` first at 13.0 DN fails the own-component cut), and the two are claimed together, fitted jointly:
    16.0 DN and 8.1 e- (truth 16 and 8; before 2026-11-29 nothing was claimed)."""
    bag = simulate_bag(tmp_path / "ped.mcap", pedestal, "campaign_heldout", effects=["extra_read_noise=8"],
                       frames=120, width=320, height=256, fps=10.0, seed=34)
    (tmp_path / "ped.yaml").write_text(pedestal.to_yaml())
    labs = {}
    for name, prof in (("stated", str(tmp_path / "ped.yaml")), ("unstated", "ev76c661")):
        out = tmp_path / f"{name}.json"
        assert cli_main(["analyze", str(bag), "--profile", prof, "--no-estimator", "--quiet", "--json", str(out),
                         "--add-effect", "extra_read_noise=fit"]) == 0
        labs[name] = json.loads(out.read_text())
    stated = {c["effect"]: c for c in labs["stated"]["candidates"] if c["significant"]}
    assert list(stated) == ["extra_read_noise"] and stated["extra_read_noise"]["params"]["sigma_e"] == pytest.approx(
        8.0, abs=1.0)
    unstated = {c["effect"]: c for c in labs["unstated"]["candidates"] if c["significant"]}
    assert set(unstated) == {"black_level", "extra_read_noise"}
    assert not any(c["significant_alone"] for c in unstated.values())
    assert all(c["beyond"]["together"] and not c["beyond"]["alternatives"] for c in unstated.values())
    assert unstated["black_level"]["beyond"]["params"]["offset_dn"] == pytest.approx(BLACK, abs=0.5)
    assert unstated["extra_read_noise"]["beyond"]["params"]["sigma_e"] == pytest.approx(8.0, abs=0.5)
    assert labs["unstated"]["diagnosis"].startswith("most likely missing effects, together")


def test_under_every_field_condition_the_pair_replaces_a_weaker_single_claim(tmp_path: Path,
                                                                            pedestal: CameraProfile) -> None:
    """The same two hidden under vibration, PWM light, flicker and auto-exposure hunting at once (held-out seed 74):
    the forward selection alone claims a dark-current law (rank 3, 13 % of the chi-square); the pedestal with a
    partner fitted together explains far more and replaces it. Beside the pedestal, the read noise and a dark-current
    law fit these data about equally well (the two pairs' joint chi-squares within 0.1: 665.1 / 665.2 with the model
    at 16 blocks per cell, 735.0 / 734.9 at 32, 2026-11-29; with each cell's error floored by its segment's spread the
    read noise fits better, 621.6 / 626.8, 2026-11-30): the lab claims one and names the other as the alternative
    where the data cannot tell them apart; the pedestal near 16 DN and the read noise, claimed or named, near 8 e-."""
    bag = simulate_bag(tmp_path / "field.mcap", pedestal, "campaign_heldout", effects=["extra_read_noise=8"],
                       frames=120, width=320, height=256, seed=74, vibration_px=0.3, vibration_hz=100.0,
                       flicker_pct=1.0, banding_pct=60.0, pwm_hz=400.0, pwm_duty=0.4, auto_exposure_pct=10.0)
    out = tmp_path / "lab.json"
    assert cli_main(["analyze", str(bag), "--profile", "ev76c661", "--no-estimator", "--quiet", "--json",
                     str(out)]) == 0
    cands = {c["effect"]: c for c in json.loads(out.read_text())["candidates"]}
    claimed = {e for e, c in cands.items() if c["significant"]}
    equivalent = {"extra_read_noise", "dark_current_law"}
    assert "black_level" in claimed and len(claimed) == 2 and claimed - {"black_level"} <= equivalent
    partner = (claimed - {"black_level"}).pop()
    assert cands["black_level"]["beyond"]["params"]["offset_dn"] == pytest.approx(BLACK, abs=2.0)
    named = cands[partner]["beyond"]["alternatives"]
    assert {a["effect"] for a in named} <= equivalent - {partner}
    assert partner == "extra_read_noise" or named  # the law claimed only with the read noise named beside it
    read = cands[partner]["beyond"]["params"] if partner == "extra_read_noise" else named[0]["params"]
    assert read["sigma_e"] == pytest.approx(8.0, abs=1.0)


def test_the_lab_finds_an_unstated_black_level(tmp_path: Path, pedestal: CameraProfile) -> None:
    """The pedestal camera's clean recording analysed with a profile that does not state its black level: the model
    reads the pedestal as signal (the lab measures "less noise than the model predicts, proportional to the gain",
    0.17 DN) and the lab names the missing effect, the ``black_level`` candidate, at 16.0 DN (the truth 16); with
    the black level stated nothing is missing."""
    bag = simulate_bag(tmp_path / "ped.mcap", pedestal, "campaign_heldout", frames=100, width=320, height=256,
                       fps=10.0, seed=33)
    (tmp_path / "ped.yaml").write_text(pedestal.to_yaml())
    labs = {}
    for name, prof in (("unstated", "ev76c661"), ("stated", str(tmp_path / "ped.yaml"))):
        out = tmp_path / f"{name}.json"
        assert cli_main(["analyze", str(bag), "--profile", prof, "--no-estimator", "--quiet", "--json", str(out)]) == 0
        labs[name] = json.loads(out.read_text())
    top = labs["unstated"]["candidates"][0]
    assert top["effect"] == "black_level" and top["significant"]
    assert top["params"]["offset_dn"] == pytest.approx(BLACK, abs=1.0)
    assert not any(c["significant"] for c in labs["stated"]["candidates"]) and labs["stated"]["rms_error_dn"] < 0.05
