"""Field-like campaigns (simulate-bag --scenario campaign / campaign_heldout) and the lab on them: the
world, the per-frame plan, the bag's truth, and the lab's scene/noise separation with its statements
of what could not be measured."""
from __future__ import annotations

import csv
import json

import cv2
import numpy as np
import pytest
import torch

from noise_monitor.bag import campaign
from noise_monitor.bag.replay import replay
from noise_monitor.bag.simulate import load_truth, simulate_bag
from noise_monitor.cli import main as cli_main
from noise_monitor.lab.compare import Comparison, Views, baseline_effects
from noise_monitor.lab.measure import NOT_HELD, measure_frames
from noise_monitor.monitor.frame import Frame
from noise_monitor.physics import NoiseModel, load_profile, make_effect

torch.set_num_threads(1)
PROFILE = load_profile("ev76c661")


@pytest.mark.parametrize("variant", campaign.VARIANTS)
def test_world_is_mostly_texture_with_small_flat_patches(variant: str) -> None:
    world = campaign.make_world(np.random.default_rng(0), 128, 160, variant)
    assert world.shape == (round(128 * 1.6), round(160 * 1.8)) and world.dtype == np.float32
    gy, gx = np.gradient(world)
    flat = (np.abs(gx) < 1e-3) & (np.abs(gy) < 1e-3)
    assert 0.005 < flat.mean() < 0.15  # the chart patches: small flat areas only
    assert np.percentile(np.hypot(gx, gy), 50) > 0.5  # texture over most of the frame
    assert world.min() >= 0 and world.max() <= 255 and np.ptp(world) > 150


def test_plan_holds_pans_auto_exposure_and_temperature() -> None:
    plans = campaign.plan(np.random.default_rng(1), 120, "tuned")
    assert len(plans) == 120
    holds = {p.hold for p in plans if p.hold >= 0}
    assert len(holds) >= 6
    lengths = [sum(p.hold == h for p in plans) for h in holds]
    assert min(lengths) < max(lengths)  # holds of varying length
    for h in holds:  # one pose and one gain/exposure per hold
        ps = [p for p in plans if p.hold == h]
        assert len({(p.x, p.y, p.gain_db, p.exposure_time_s) for p in ps}) == 1
    moving = [p for p in plans if p.moving]
    assert moving and all(p.hold == -1 for p in moving)
    temps = np.array([p.sensor_temperature_c for p in plans])
    assert np.all(np.diff(temps) != 0)  # changes every frame
    assert len({p.gain_db for p in plans}) >= 3 and len({p.exposure_time_s for p in plans}) >= 5
    xs = np.array([p.x for p in plans]) * 1000
    assert np.any(np.abs(xs - np.rint(xs)) > 1e-3)  # sub-pixel poses


def test_render_is_bilinear_and_vignetted() -> None:
    world = np.tile(np.arange(64, dtype=np.float32) * 2.0, (48, 1))  # a ramp of 2 DN per column
    vig = campaign.vignetting(16, 20, 0.3)
    assert vig[8, 10] == pytest.approx(1.0, abs=0.01) and vig[0, 0] == pytest.approx(0.7, abs=0.04)  # corner pixel centre, just inside
    fp = campaign.FramePlan(0.25, 0.5, 0.0, 0.01, 30.0, 1.0, False, 0)
    img, (x, y) = campaign.render(world, fp, np.ones((16, 20), np.float32))
    assert x == pytest.approx(0.25 * (64 - 20 - 1))
    assert img[5, 0] == pytest.approx(2.0 * x, abs=1e-3)  # sub-pixel position, linear interpolation


def test_campaign_bag_truth(tmp_path) -> None:
    bag = simulate_bag(tmp_path / "c.mcap", "ev76c661", "campaign_heldout", frames=24, width=64, height=48,
                       fps=10.0, seed=2)
    truth = load_truth(bag)
    frames = truth["frames"]
    assert truth["scenario"] == "campaign_heldout" and len(frames) == 24
    assert any(f["hold"] == -1 for f in frames) and any(f["hold"] >= 1 for f in frames)
    temps = [f["true_metadata"]["sensor_temperature_c"] for f in frames]
    assert len(set(temps)) == 24


def test_world_of_own_images() -> None:
    """A campaign world from a user's own scenes: its photo panels are crops of them (a uniform scene: the panels
    are flat, against at most 15 % flat area with the bundled photographs); a bad image is a clear error."""
    own = campaign.make_world(np.random.default_rng(0), 128, 160, "heldout", photos=[np.full((90, 120), 100.0)])
    gy, gx = np.gradient(own)
    assert ((np.abs(gx) < 1e-3) & (np.abs(gy) < 1e-3)).mean() > 0.4
    with pytest.raises(ValueError, match="grayscale images of at least 8x8"):
        campaign.make_world(np.random.default_rng(0), 128, 160, "heldout", photos=[np.zeros((4, 90))])
    with pytest.raises(ValueError, match="grayscale images"):
        campaign.make_world(np.random.default_rng(0), 128, 160, "heldout", photos=[])


def test_photo_share_sets_how_much_of_the_world_is_the_scenes(tmp_path, capsys) -> None:
    """``photo_share``: the share of a world's panels that are the photographs (a uniform scene: its panels are flat,
    the procedural ones textured): 1 gives the scenes alone besides the chart patches, 0 none of them; the default
    is 0.75 (the worlds before the option); a share outside [0, 1] is a clear error, also from the CLI, and a
    non-campaign scenario refuses it."""
    flat_photo = [np.full((90, 120), 100.0)]

    def flat_share(share: float) -> float:
        world = campaign.make_world(np.random.default_rng(0), 128, 160, "heldout", photos=flat_photo, photo_share=share)
        gy, gx = np.gradient(world)
        return float(((np.abs(gx) < 1e-3) & (np.abs(gy) < 1e-3)).mean())

    assert flat_share(1.0) > 0.9 and flat_share(0.0) < 0.15 and flat_share(0.0) < flat_share(0.75) < flat_share(1.0)
    default = campaign.make_world(np.random.default_rng(0), 128, 160, "heldout", photos=flat_photo)
    assert np.array_equal(default, campaign.make_world(np.random.default_rng(0), 128, 160, "heldout", photos=flat_photo,
                                                       photo_share=0.75))
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="photo share must be in"):
            campaign.make_world(np.random.default_rng(0), 128, 160, "heldout", photo_share=bad)
    def simulate(share: str) -> int:
        return cli_main(["simulate-bag", str(tmp_path / f"{share}.mcap"), "--profile", "ev76c661", "--scenario",
                         "campaign_heldout", "--frames", "2", "--width", "64", "--height", "64", "--photo-share", share])

    assert simulate("1") == 0 and load_truth(tmp_path / "1.mcap")["photo_share"] == 1.0
    assert simulate("0.75") == 0 and "photo_share" not in load_truth(tmp_path / "0.75.mcap")  # the default: as before
    capsys.readouterr()
    assert simulate("2") == 2 and "photo share must be in [0, 1]" in capsys.readouterr().err
    other = ["simulate-bag", str(tmp_path / "x.mcap"), "--profile", "ev76c661", "--scenario", "image_noise", "--frames",
             "2", "--photo-share", "1"]
    assert cli_main(other) == 2 and "campaign scenario" in capsys.readouterr().err


def test_campaign_of_own_images_end_to_end(tmp_path, capsys) -> None:
    """`simulate-bag --images`: a field-like campaign over the user's own scene (named in the truth and the
    summary); replayed through the monitor, every frame is accounted for and the clean campaign's per-frame xi is
    within 0.3 DN of 0 (the truth: the simulator draws the noise from the stated model). A non-campaign scenario
    refuses the images."""
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    y, x = np.mgrid[0:480, 0:640]
    wall = 128 + 50 * np.sin(x / 60.0) * np.cos(y / 80.0) + 20 * (x // 160 % 2)
    cv2.imwrite(str(scenes / "wall.png"), wall.astype(np.uint8))
    js, bag = tmp_path / "s.json", tmp_path / "own.mcap"
    args = ["simulate-bag", str(bag), "--profile", "ev76c661", "--scenario", "campaign_heldout", "--images",
            str(scenes), "--frames", "16", "--width", "160", "--height", "128", "--fps", "10", "--seed", "3"]
    assert cli_main(args + ["--json", str(js)]) == 0
    assert json.loads(js.read_text())["images"] == ["wall.png"] and load_truth(bag)["images"] == ["wall.png"]
    s = replay(bag, "ev76c661", tmp_path / "out", progress=False, plot=False)
    assert s["frames_total"] == 16 and s["frames_processed"] + s["frames_skipped"] == 16 and s["frames_processed"] >= 12
    with open(tmp_path / "out" / "replay.csv") as fh:
        xi = [float(r["xi"]) for r in csv.DictReader(fh) if r["processed"] == "1"]
    assert len(xi) == s["frames_processed"] and np.sqrt(np.mean(np.square(xi))) < 0.3
    capsys.readouterr()
    bad = ["simulate-bag", str(tmp_path / "x.mcap"), "--profile", "ev76c661", "--scenario", "image_noise",
           "--images", str(scenes), "--frames", "4"]
    assert cli_main(bad) == 2 and "campaign scenario" in capsys.readouterr().err


def _frames(plans, world, effects=(), seed=0):
    h, w = 128, 160
    vig = campaign.vignetting(h, w, 0.3)
    model = NoiseModel(extra=list(effects))
    rng = np.random.default_rng(seed)
    out = []
    for i, p in enumerate(plans):
        clean, _ = campaign.render(world, p, vig)
        meta = PROFILE.metadata(gain_db=p.gain_db, exposure_time_s=p.exposure_time_s,
                                sensor_temperature_c=p.sensor_temperature_c)
        noisy, _ = model.simulate(clean, meta, rng, mode="joint")
        out.append(Frame(i * 100_000_000, np.rint(np.clip(noisy, 0, 255)).astype(np.float32), meta, index=i))
    return out


@pytest.fixture(scope="module")
def scene():
    rng = np.random.default_rng(3)
    return campaign.make_world(rng, 128, 160, "tuned"), campaign.plan(rng, 60, "tuned")


def test_scene_texture_is_not_read_as_fixed_pattern(scene) -> None:
    """Clean campaign: the components that must be zero (fixed, column, row, outlier) are zero within
    their stated errors, although the blocks hold photo texture; temporal matches the model."""
    world, plans = scene
    meas = measure_frames(_frames(plans, world))
    assert not meas.not_measured and meas.skipped.get(NOT_HELD, 0) > 0
    assert all(s.partners for s in meas.segments)  # every hold has views from other poses
    for comp in ("fixed", "column", "row", "outlier"):
        z = np.array([c.values[comp] / c.errors[comp] for c in meas.cells])
        assert abs(z.mean()) < 1.0 and z.std() < 2.0, comp


def test_column_offsets_measured_across_views(scene) -> None:
    world, plans = scene
    meas = measure_frames(_frames(plans, world, ["column_offsets=0.8"], seed=1))
    col = np.array([s.values["column"].mean() for s in meas.segments])
    assert col.mean() == pytest.approx(0.64, rel=0.25)  # 0.8 DN -> 0.64 DN^2 (a 160-column realisation)


def test_no_static_hold_is_stated_not_invented() -> None:
    rng = np.random.default_rng(4)
    world = campaign.make_world(rng, 128, 160, "tuned")
    pans = [campaign.FramePlan(0.1 * i, 0.05 * i, 6.0, 0.01, 30.0 + i, 1.0, True, -1) for i in range(6)]
    meas = measure_frames(_frames(pans, world))
    assert "temporal" in meas.not_measured and "no static hold" in meas.not_measured["temporal"]
    assert all("single" in c.values and "temporal" not in c.values for c in meas.cells)
    # metadata jumping inside a hold: the frames are not in a hold, and the rest is measured
    hold = [campaign.FramePlan(0.5, 0.5, 6.0, 0.01, 30.0, 1.0, False, 0)] * 6
    jumps = [campaign.FramePlan(0.5, 0.5, 9.0 + 3 * i, 0.01, 30.0, 1.0, False, 1) for i in range(4)]
    meas = measure_frames(_frames(hold + jumps, world))
    assert meas.skipped[NOT_HELD] == 4 and meas.frames_used == 6
    assert "fixed_pattern_separation" in meas.not_measured  # one pose only: said, not silently zero


@pytest.mark.parametrize(("name", "values"), [("prnu", {"sigma_pct": 2.0}),
                                               ("hot_pixels", {"fraction": 0.01, "dark_multiplier": 300.0}),
                                               ("gain_error", {"factor": 1.3})])
def test_batched_model_equals_each_segment_on_its_own(scene, name: str, values: dict[str, float]) -> None:
    """The comparison evaluates an effect once per metadata set over every segment's blocks and partner
    views (``Views``); each segment's components must equal those of that segment evaluated alone."""
    world, plans = scene
    meas = measure_frames(_frames(plans, world, seed=2))
    comp = Comparison(meas, NoiseModel(baseline_effects(PROFILE, meas.segments[0].meta, True)))
    assert any(sb.partners for sb in comp.segments)
    effects = comp.replaced([make_effect(name, **values)])
    together = comp.views.split(comp.views.components(effects, comp.span))
    for sb, comps in zip(comp.segments, together):
        alone = Views([(sb.seg.meta, sb.v, sb.sigma, sb.pos, sb.partners)]).components(effects, sb.span)
        for c, a in alone.items():
            np.testing.assert_allclose(comps[c], a, rtol=1e-12, atol=1e-12, err_msg=c)
    base = comp.views.components(comp.effects, comp.span)
    changed = comp.views.components(effects, comp.span)
    assert any(np.abs(changed[c] - base[c]).max() > 1e-3 for c in base)  # the effect matters here
