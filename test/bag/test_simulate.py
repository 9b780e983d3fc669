"""Synthetic field campaigns: scenes, scenarios, truth sidecar, effects and the simulate-bag command."""
from __future__ import annotations

import json

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from noise_monitor.bag import campaign
from noise_monitor.bag.lights import pwm_depth, pwm_gain, rolling_shutter_gain
from noise_monitor.bag.reader import open_bag
from noise_monitor.bag.scenarios import EPISODE, SCENARIOS, get_scenario
from noise_monitor.bag.scenes import camera_path, make_world, view
from noise_monitor.bag.simulate import load_truth, simulate_bag, truth_path
from noise_monitor.bag.writer import typestore
from noise_monitor.cli import main


def test_world_has_flat_textured_and_gradient_regions_at_many_levels(rng):
    world = make_world(rng, 64, 96)
    assert world.shape == (round(64 * 1.6), round(96 * 1.8)) and world.dtype == np.float32
    assert world.min() >= 0 and world.max() <= 255
    tile = 96 * 18 // 10 // 6
    blocks = [world[r:r + tile, c:c + tile] for r in range(0, world.shape[0] - tile + 1, tile)
              for c in range(0, world.shape[1] - tile + 1, tile)]
    flat = [b for b in blocks if np.ptp(b) == 0]
    ramps = [b for b in blocks
             if np.ptp(b) > 0 and (np.ptp(np.diff(b, axis=0)) < 1e-3 or np.ptp(np.diff(b, axis=1)) < 1e-3)]
    textured = [b for b in blocks if np.ptp(np.diff(b, axis=0)) > 1e-3 and np.ptp(np.diff(b, axis=1)) > 1e-3]
    assert flat and ramps and textured
    means = np.array([b.mean() for b in blocks])
    assert means.min() < 40 and means.max() > 215


def test_camera_path_static_and_moving():
    u = np.linspace(0, 1, 41)
    assert np.all(camera_path(u, moving=False) == 0.5)
    pos = camera_path(u, moving=True)
    steps = np.abs(np.diff(pos, axis=0)).sum(axis=1)
    assert (steps == 0).sum() >= 10 and (steps > 0).sum() >= 10  # static stretches and pans
    win, (x, y) = view(np.zeros((30, 40), np.float32), np.array([1.0, 1.0]), 20, 25)
    assert win.shape == (20, 25) and (x, y) == (15, 10)


def test_scenarios_cover_the_issue_list():
    for name in ("gain_sweep", "exposure_sweep", "temperature_ramp", "image_noise", "double_thermal_noise",
                 "double_temperature", "field", "lab", "static", "motion"):
        assert name in SCENARIOS
    assert get_scenario("gain_sweep").step(1.0).gain_db == 24.0
    assert get_scenario("exposure_sweep").step(0.0).exposure_time_s == pytest.approx(0.001)
    mid = sum(EPISODE) / 2
    assert get_scenario("image_noise").step(mid).image_noise_dn == 5.0
    assert get_scenario("image_noise").step(0.1).corrupted == []
    assert get_scenario("double_temperature").step(mid).stated_factors == {"sensor_temperature_c": 2.0}
    with pytest.raises(ValueError, match="unknown scenario 'nope'; known: static"):
        get_scenario("nope")


@pytest.mark.parametrize("scenario,profile,sign", [("image_noise", "icx285", "-"),
                                                    ("double_thermal_noise", "ev76c661", "+"),
                                                    ("double_temperature", "ev76c661", "+")])
def test_truth_records_corruption_and_xi_sign(tmp_path, scenario, profile, sign):
    bag = simulate_bag(tmp_path / "b.mcap", profile, scenario, frames=10, width=64, height=48, seed=2, hold_s=0)
    truth = load_truth(bag)
    (ep,) = truth["episodes"]
    assert ep["xi_sign"] == sign and ep["start_index"] == 4 and ep["end_index"] == 6
    clean = [r for r in truth["frames"] if not r["corrupted"]]
    # model == image apart from quantisation and sampling: the std of a 64x48 frame's sigma estimate is
    # sigma / sqrt(2 N), so allow 4 of those plus 0.05 DN for 8-bit rounding
    assert all(abs(r["xi"]) < 4 * r["sigma_model"] / np.sqrt(2 * 64 * 48) + 0.05 for r in clean)
    if scenario == "image_noise":
        for r in truth["frames"][4:7]:  # the paper's expectation: xi = sigma_model - sqrt(sigma_model^2 + 25),
            # a little less negative here: clipping at 0 and 255 DN trims part of the added noise
            assert r["xi"] == pytest.approx(r["sigma_model"] - np.hypot(r["sigma_model"], 5.0), abs=0.4)
            assert r["xi"] < -2.0


def test_metadata_is_held_between_updates_while_image_noise_changes_per_frame(tmp_path):
    bag = simulate_bag(tmp_path / "h.mcap", "icx285", "field", frames=20, width=32, height=32, fps=5.0, hold_s=1.0)
    frames = load_truth(bag)["frames"]
    gains = [r["true_metadata"]["gain_db"] for r in frames]
    assert len(set(gains)) == 4 and gains[:5] == [gains[0]] * 5 and gains[5] > gains[4]
    noisy = [r["index"] for r in frames if r["image_noise_dn"]]
    assert noisy == list(range(8, 14))  # the episode follows campaign time, not the metadata updates


def test_effect_switched_on_adds_unmodelled_noise(tmp_path):
    bag = simulate_bag(tmp_path / "p.mcap", "icx285", "static", effects=["prnu=4"], frames=2, width=64, height=48)
    truth = load_truth(bag)
    assert truth["effects"] == ["prnu=4"]
    for r in truth["frames"]:
        assert r["sigma"]["prnu"] > 1.0 and r["xi"] < -0.5


def test_same_seed_same_bag(tmp_path):
    a = simulate_bag(tmp_path / "a.mcap", "generic", "motion", frames=3, width=32, height=32, seed=9)
    b = simulate_bag(tmp_path / "b.mcap", "generic", "motion", frames=3, width=32, height=32, seed=9)
    with open_bag(a) as ra, open_bag(b) as rb:
        for fa, fb in zip(ra.frames(), rb.frames()):
            assert np.array_equal(fa.image_dn, fb.image_dn)


def test_simulate_bag_help_lists_every_scenario(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["simulate-bag", "--help"])
    assert exc.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    assert all(name in text for name in SCENARIOS) and "40%-70% of the campaign" in text


def test_simulate_bag_command(tmp_path, capsys):
    out = tmp_path / "cmd.mcap"
    summary = tmp_path / "s.json"
    rc = main(["simulate-bag", str(out), "--profile", "ev76c661", "--scenario", "image_noise", "--frames", "5",
               "--width", "32", "--height", "32", "--effect", "row_offsets=1", "--json", str(summary)])
    assert rc == 0 and out.is_file() and truth_path(out).is_file()
    s = json.loads(summary.read_text())
    assert s["frames"] == 5 and s["effects"] == ["row_offsets=1"] and s["episodes"][0]["xi_sign"] == "-"
    assert main(["simulate-bag", str(out), "--profile", "ev76c661", "--scenario", "static"]) == 2
    assert "exists already" in capsys.readouterr().err
    assert main(["simulate-bag", str(tmp_path / "x.mcap"), "--profile", "ev76c661", "--scenario", "static",
                 "--effect", "nonsense=3"]) == 2
    assert "unknown effect 'nonsense'" in capsys.readouterr().err


def test_moving_objects_cross_a_campaign_view_and_only_a_campaign(tmp_path) -> None:
    """Each object is painted at its own place in each frame (the texture's rows and columns as they enter the
    view), moving by its velocity; a scenario without campaign views refuses them."""
    objects = campaign.moving_objects(np.random.default_rng(0), 1, 256, 320)
    o = objects[0]
    clean = np.full((256, 320), 100.0, np.float32)
    frames = [campaign.paint(clean, objects, i) for i in range(12)]
    for i, (painted, seen) in enumerate(frames):
        y, x = int(o.y0 + o.vy * i) % (256 + 60) - 30, int(o.x0 + o.vx * i) % (320 + 80) - 40
        changed = np.argwhere(painted != clean)
        assert seen == bool(changed.size)
        if changed.size:
            assert changed[:, 0].min() >= max(y, 0) and changed[:, 1].min() >= max(x, 0)
            yy, xx = changed[0]
            assert painted[yy, xx] == pytest.approx(np.clip(o.texture[yy - y, xx - x], 0, 255))
    assert sum(seen for _, seen in frames) >= 6
    with pytest.raises(ValueError, match="campaign scenario"):
        simulate_bag(tmp_path / "s.mcap", "ev76c661", "static", frames=4, moving_objects=2)


def test_a_vibrating_campaign_camera_shakes_about_its_nominal_pose(tmp_path) -> None:
    """``--vibration``: every frame's view displaced by an independent Gaussian (recorded as ``shake_px``, rms
    as asked), the nominal pose, holds and the noise's generator those of the bag without it; refused outside a
    campaign and beyond its range."""
    still = load_truth(simulate_bag(tmp_path / "a.mcap", "ev76c661", "campaign_heldout", frames=40, seed=3))
    shaken = load_truth(simulate_bag(tmp_path / "b.mcap", "ev76c661", "campaign_heldout", frames=40, seed=3,
                                     vibration_px=0.3))
    assert shaken["vibration_px"] == 0.3 and "vibration_px" not in still
    shake = np.array([f["shake_px"] for f in shaken["frames"]])
    assert shake.std() == pytest.approx(0.3, rel=0.3) and np.abs(np.diff(shake, axis=0)).max() > 0.3
    for a, b in zip(still["frames"], shaken["frames"]):
        assert (a["offset_px"], a["moving"], a["hold"]) == (b["offset_px"], b["moving"], b["hold"])
    with open_bag(tmp_path / "a.mcap") as ra, open_bag(tmp_path / "b.mcap") as rb:
        for fa, fb in zip(ra.frames(), rb.frames()):  # the view moved under the noise
            assert np.abs(np.asarray(fa.image_dn, float) - np.asarray(fb.image_dn, float)).mean() > 0.5
    with pytest.raises(ValueError, match="campaign scenario"):
        simulate_bag(tmp_path / "s.mcap", "ev76c661", "static", frames=4, vibration_px=0.2)
    with pytest.raises(ValueError, match="vibration_px"):
        simulate_bag(tmp_path / "s.mcap", "ev76c661", "campaign", frames=4, vibration_px=9.0)


def test_a_camera_vibrating_during_the_exposure_smears_its_view(tmp_path, capsys) -> None:
    """``--vibration-hz``: the camera oscillates at that frequency during each exposure, so a frame integrates
    the views along its path: a short exposure freezes one displacement, one of many periods smears it about
    the pose (truth ``blur_px``, the rms about the mean ``shake_px``). Without a frequency the bag is that of
    ``--vibration`` alone (one displacement per frame, as before)."""
    rng = np.random.default_rng(0)
    short, long_ = campaign.vibration_during_exposure(rng, [1e-4, 0.5], 0.4, 50.0)
    assert short.shape == (1, 2) and long_.shape == (campaign.MAX_EXPOSURE_SAMPLES, 2)
    assert np.sqrt(np.mean(long_**2, axis=0)) == pytest.approx([0.4, 0.4], rel=0.05)  # 25 periods: the rms asked
    paths = campaign.vibration_during_exposure(rng, [1e-4] * 4000, 0.4, 50.0)
    assert np.std(np.concatenate(paths), axis=0) == pytest.approx([0.4, 0.4], rel=0.05)
    world = np.random.default_rng(1).uniform(0, 255, (80, 90)).astype(np.float32)
    plan = campaign.FramePlan(0.3, 0.6, 0.0, 0.01, 30.0, 1.0, False, 0)
    vignette = np.ones((40, 50), np.float32)
    one = campaign.render(world, plan, vignette, (0.2, -0.1))[0]
    assert np.array_equal(one, campaign.render(world, plan, vignette, np.array([[0.2, -0.1]]))[0])
    mean = np.mean([campaign.render(world, plan, vignette, s)[0] for s in ((0.0, 0.0), (0.5, 0.0))], axis=0)
    assert campaign.render(world, plan, vignette, np.array([[0.0, 0.0], [0.5, 0.0]]))[0] == pytest.approx(mean, abs=1e-4)

    kw = {"frames": 30, "seed": 3, "vibration_px": 0.5}
    frozen = load_truth(simulate_bag(tmp_path / "a.mcap", "ev76c661", "campaign_heldout", **kw))
    smeared = load_truth(simulate_bag(tmp_path / "b.mcap", "ev76c661", "campaign_heldout", vibration_hz=60.0, **kw))
    assert smeared["vibration_hz"] == 60.0 and "vibration_hz" not in frozen
    assert "blur_px" not in frozen["frames"][0]
    exposure = np.array([f["true_metadata"]["exposure_time_s"] for f in smeared["frames"]])
    blur = np.array([f["blur_px"] for f in smeared["frames"]])
    periods = exposure * 60.0
    assert blur[periods > 3] == pytest.approx(0.5 * np.sqrt(2.0), abs=0.03)  # the same smear in every frame
    half = blur[(periods > 0.4) & (periods < 0.6)]  # half a period: a smear that changes from frame to frame
    assert half.size >= 10 and 0.3 < half.min() and half.max() < 0.75 and half.std() > 0.05
    for a, b in zip(frozen["frames"], smeared["frames"]):
        assert (a["offset_px"], a["hold"], a["true_metadata"]) == (b["offset_px"], b["hold"], b["true_metadata"])
    with pytest.raises(ValueError, match="vibration_px too"):
        simulate_bag(tmp_path / "s.mcap", "ev76c661", "campaign", frames=4, vibration_hz=50.0)
    assert main(["simulate-bag", str(tmp_path / "c.mcap"), "--profile", "ev76c661", "--scenario", "campaign",
                 "--frames", "4", "--vibration-hz", "50"]) == 2
    assert "give --vibration PX too" in capsys.readouterr().err


def test_mains_lights_band_a_rolling_shutter_image(tmp_path) -> None:
    """``--banding``: lamps on 50 Hz mains modulated by 30 %, each row exposed 30 us after the previous: every
    frame's rows scaled by the light averaged over their exposure (``rolling_shutter_gain`` at the frame's random
    phase), bands as deep as the exposure allows (sinc of 100 Hz x exposure: none at whole periods); the scene and
    its noise seed those of the bag without them; refused beyond its range."""
    kw = {"frames": 24, "width": 320, "height": 256, "seed": 5}
    bag = simulate_bag(tmp_path / "b.mcap", "ev76c661", "campaign_heldout", banding_pct=30.0, **kw)
    simulate_bag(tmp_path / "p.mcap", "ev76c661", "campaign_heldout", **kw)
    truth = load_truth(bag)
    assert truth["banding_pct"] == 30.0 and truth["mains_hz"] == 50.0 and truth["line_time_s"] == 30e-6

    def bins(path):  # 16-row means: the noise averages out, the bands stay
        return [f.image_dn.reshape(16, -1).mean(axis=1) for f in open_bag(path).frames()]

    rows, rows_plain = bins(bag), bins(tmp_path / "p.mcap")
    depths = []
    for f, r, p in zip(truth["frames"], rows, rows_plain):
        t = f["true_metadata"]["exposure_time_s"]
        assert f["banding_depth"] == pytest.approx(0.3 * np.sinc(100.0 * t), abs=1e-6)
        expected = rolling_shutter_gain(256, t, f["banding_phase"], 0.3, 50.0, 30e-6).reshape(16, -1).mean(axis=1)
        noise = 6.0 * np.sqrt(2.0) * f["sigma_image"] / np.sqrt(16 * 320) / p  # two noisy bin means, 6 sigma
        assert np.all(np.abs(r / p - expected) <= 0.005 + noise)  # (0.5 %: the clipping of the brightest rows)
        depths.append(abs(f["banding_depth"]))
    assert max(depths) > 0.2  # short exposures show deep bands
    with pytest.raises(ValueError, match="banding_pct"):
        simulate_bag(tmp_path / "s.mcap", "ev76c661", "static", frames=4, banding_pct=120.0)


def test_flickering_lights_scale_each_frame(tmp_path) -> None:
    """``--flicker``: every frame's scene scaled by its own gain (recorded as ``flicker_gain``, rms as asked),
    the scene and its holds those of the bag without it; refused beyond its range."""
    truth = load_truth(simulate_bag(tmp_path / "f.mcap", "ev76c661", "campaign_heldout", frames=40, seed=3,
                                    flicker_pct=2.0))
    gains = np.array([f["flicker_gain"] for f in truth["frames"]])
    assert truth["flicker_pct"] == 2.0 and gains.std() == pytest.approx(0.02, rel=0.3)
    plain = load_truth(simulate_bag(tmp_path / "p.mcap", "ev76c661", "campaign_heldout", frames=40, seed=3))
    mean = np.array([f["mean_dn"] for f in truth["frames"]]) / np.array([f["mean_dn"] for f in plain["frames"]])
    assert np.allclose(mean, gains, atol=0.003)  # the clean scene scaled (up to clipping)
    with pytest.raises(ValueError, match="flicker_pct"):
        simulate_bag(tmp_path / "s.mcap", "ev76c661", "static", frames=4, flicker_pct=30.0)


def test_a_switched_lamp_steps_the_light_between_two_levels(tmp_path) -> None:
    """``--lamp``: a lamp adds its share to the scene's light, switched at random frames (recorded as ``lamp_gain``:
    1 or 1 + share, off at the start, about one switch per 25 frames), the scene and its holds those of the bag
    without it; refused beyond its range and by the photon-transfer recording."""
    kw = {"frames": 60, "seed": 2}
    truth = load_truth(simulate_bag(tmp_path / "l.mcap", "ev76c661", "campaign_heldout", lamp_pct=30.0, **kw))
    plain = load_truth(simulate_bag(tmp_path / "p.mcap", "ev76c661", "campaign_heldout", **kw))
    gains = np.array([f["lamp_gain"] for f in truth["frames"]])
    assert truth["lamp_pct"] == 30.0 and set(gains) == {1.0, 1.3} and gains[0] == 1.0
    assert 1 <= np.count_nonzero(np.diff(gains)) <= 8
    assert [f["offset_px"] for f in truth["frames"]] == [f["offset_px"] for f in plain["frames"]]
    mean = np.array([f["mean_dn"] for f in truth["frames"]]) / np.array([f["mean_dn"] for f in plain["frames"]])
    assert np.allclose(mean[gains == 1.0], 1.0) and np.all(np.abs(mean[gains > 1.0] - 1.3) < 0.03)  # up to clipping
    with pytest.raises(ValueError, match="lamp_pct"):
        simulate_bag(tmp_path / "s.mcap", "ev76c661", "static", frames=4, lamp_pct=150.0)
    with pytest.raises(ValueError, match="photon-transfer recording"):
        simulate_bag(tmp_path / "x.mcap", "generic", "ptc", frames=60, width=32, height=32, lamp_pct=30.0)


def test_auto_exposure_hunts_every_frame_and_the_metadata_report_it(tmp_path) -> None:
    """``--auto-exposure``: a live driver's exposure wanders about the plan's every frame (rms as asked, correlated
    from frame to frame), the scene's brightness following it under steady light, the metadata reporting the true
    exposure; the holds, poses and gains those of the bag without it; refused beyond its range."""
    kw = {"frames": 60, "seed": 3}
    bag = simulate_bag(tmp_path / "a.mcap", "ev76c661", "campaign_heldout", auto_exposure_pct=5.0, **kw)
    truth, plain = load_truth(bag), load_truth(simulate_bag(tmp_path / "p.mcap", "ev76c661", "campaign_heldout", **kw))
    factor = np.array([f["exposure_factor"] for f in truth["frames"]])
    assert truth["auto_exposure_pct"] == 5.0 and np.log(factor).std() == pytest.approx(0.05, rel=0.4)
    assert np.corrcoef(factor[1:], factor[:-1])[0, 1] > 0.5
    exposure = [f["true_metadata"]["exposure_time_s"] / p["true_metadata"]["exposure_time_s"]
                for f, p in zip(truth["frames"], plain["frames"])]
    assert np.allclose(exposure, factor, rtol=1e-5)
    stated = [f.metadata.exposure_time_s for f in open_bag(bag).frames("ev76c661")]
    assert np.allclose(stated, [f["true_metadata"]["exposure_time_s"] for f in truth["frames"]], rtol=1e-6)
    mean = np.array([f["mean_dn"] for f in truth["frames"]]) / np.array([f["mean_dn"] for f in plain["frames"]])
    assert np.allclose(mean, factor, atol=0.01)  # the clean scene scaled (up to clipping)
    assert [f["hold"] for f in truth["frames"]] == [f["hold"] for f in plain["frames"]]
    with pytest.raises(ValueError, match="auto_exposure_pct"):
        simulate_bag(tmp_path / "s.mcap", "ev76c661", "static", frames=4, auto_exposure_pct=50.0)


def test_the_ptc_recording_takes_the_camera_id_and_start_and_refuses_field_conditions(tmp_path) -> None:
    """Before: ``--hardware-id``, ``--start`` and the field options were silently ignored by the ptc scenario."""
    bag = simulate_bag(tmp_path / "p.mcap", "generic", "ptc", frames=60, width=32, height=32, hardware_id="robot9/front",
                       start_ns=1_777_000_000_000_000_000)
    assert next(iter(open_bag(bag).frames("generic"))).stamp_ns == 1_777_000_000_000_000_000
    with AnyReader([bag], default_typestore=typestore()) as r:
        conn = [c for c in r.connections if c.topic == "/camera/metadata"]
        _, _, raw = next(r.messages(connections=conn))
        assert r.deserialize(raw, conn[0].msgtype).status[0].hardware_id == "robot9/front"
    for kw in ({"flicker_pct": 2.0}, {"banding_pct": 30.0}, {"auto_exposure_pct": 5.0}):
        with pytest.raises(ValueError, match="photon-transfer recording"):
            simulate_bag(tmp_path / "x.mcap", "generic", "ptc", frames=60, width=32, height=32, **kw)


def test_leds_dimmed_by_pwm_band_a_rolling_shutter_image(tmp_path, capsys) -> None:
    """``--banding PCT --pwm-hz HZ --pwm-duty D``: LEDs dimmed by pulse-width modulation instead of lamps on the
    mains. Each row averages a square wave over its exposure: at an exposure far short of the period the rows see
    the light on or off (sharp-edged bands, 0 to 1 / D of the mean at 100 % depth), over whole periods no band;
    the mean over whole periods is the light's mean. The truth names the LED, not the mains."""
    short = pwm_gain(4000, 1e-6, 0.7, 1.0, 500.0, 0.3, 30e-6)
    assert short.min() == pytest.approx(0.0, abs=1e-9) and short.max() == pytest.approx(1 / 0.3)
    assert np.mean(short[:3000]) == pytest.approx(1.0, abs=0.01)  # 3,000 rows of 30 us: 45 periods
    assert np.ptp(pwm_gain(500, 0.004, 0.7, 1.0, 500.0, 0.3, 30e-6)) < 1e-9  # two whole periods
    half = pwm_gain(500, 0.001, 0.7, 0.5, 500.0, 0.3, 30e-6)
    assert (np.ptp(half) / 2 == pytest.approx(pwm_depth(0.5, 0.001, 500.0, 0.3), rel=0.02)
            and pwm_depth(0.5, 0.001, 500.0, 0.3) < pwm_depth(1.0, 0.001, 500.0, 0.3))
    truth = load_truth(simulate_bag(tmp_path / "a.mcap", "ev76c661", "campaign_heldout", frames=12, seed=3,
                                    banding_pct=100.0, pwm_hz=500.0, pwm_duty=0.3))
    assert (truth["pwm_hz"], truth["pwm_duty"]) == (500.0, 0.3) and "mains_hz" not in truth
    for f in truth["frames"]:
        assert f["banding_depth"] == pytest.approx(pwm_depth(1.0, f["true_metadata"]["exposure_time_s"], 500.0, 0.3),
                                                   abs=1e-6)
    from noise_monitor.cli import main as cli_main

    base = ["simulate-bag", str(tmp_path / "x.mcap"), "--profile", "ev76c661", "--scenario", "static", "--frames", "2"]
    for extra, message in ((["--pwm-hz", "500"], "give --banding PCT too"),
                           (["--banding", "50", "--pwm-hz", "500", "--mains-hz", "60"], "give one of --pwm-hz"),
                           (["--banding", "50", "--pwm-duty", "0.3"], "give --pwm-hz HZ too")):
        assert cli_main(base + extra) == 2 and message in capsys.readouterr().err
    with pytest.raises(ValueError, match="pwm_duty"):
        simulate_bag(tmp_path / "y.mcap", "ev76c661", "static", frames=2, banding_pct=50.0, pwm_hz=500.0, pwm_duty=1.0)


def test_the_banding_options_without_banding_are_an_error(capsys) -> None:
    """Before, ``--mains-hz`` or ``--line-us`` without ``--banding`` were accepted and had no effect (``--line-us``
    also sets the line time of ``--wobble``, which needs a vibration's frequency)."""
    from noise_monitor.cli import main as cli_main

    for extra, message in ((["--mains-hz", "60"], "give --banding PCT too"),
                           (["--line-us", "20"], "--banding or --wobble: give one of them too"),
                           (["--wobble"], "give --vibration PX --vibration-hz HZ"),
                           (["--vibration", "0.3", "--wobble"], "give --vibration PX --vibration-hz HZ")):
        args = ["simulate-bag", "x.mcap", "--profile", "ev76c661", "--scenario", "static", "--frames", "2", *extra]
        assert cli_main(args) == 2 and message in capsys.readouterr().err


def test_a_rolling_shutter_reads_a_vibrating_view_row_by_row() -> None:
    """``--wobble``: each row of a rolling shutter starts its exposure one line time after the previous one, so
    under a vibration each row is displaced along its own stretch of the path: on a horizontal ramp a row's level
    moves by the ramp's slope times its own displacement (to the bilinear interpolation's rounding); the first row
    sees the frame's path, and the truth's wobble is the rms of the rows' displacements about their mean."""
    h, w = 64, 48
    world = np.tile(np.arange(w + 40, dtype=np.float32) * 2.0, (h + 40, 1))  # 2 DN per px along x
    plan = campaign.FramePlan(x=0.5, y=0.5, gain_db=0.0, exposure_time_s=1e-4, sensor_temperature_c=30.0,
                              brightness=1.0, hold=0, moving=False)
    rows = campaign.vibration_during_exposure(np.random.default_rng(3), [1e-4], 1.0, 200.0, h, 100e-6)[0]
    whole = campaign.vibration_during_exposure(np.random.default_rng(3), [1e-4], 1.0, 200.0)[0]
    assert rows.shape == (h, 1, 2) and np.array_equal(rows[0], whole)
    flat, _ = campaign.render(world, plan, np.ones((h, w), np.float32))
    wobbled, _ = campaign.render(world, plan, np.ones((h, w), np.float32), rows)
    shift = (wobbled - flat).mean(axis=1) / 2.0  # each row's x displacement read off the ramp
    np.testing.assert_allclose(shift, rows[:, 0, 0], atol=0.01)
    assert campaign.wobble_px(rows) == pytest.approx(float(np.sqrt(np.mean(np.sum(
        (rows.mean(axis=1) - rows.mean(axis=(0, 1))) ** 2, axis=1)))))
    assert campaign.wobble_px(whole) == 0.0
    assert np.array_equal(campaign.first_row(rows), whole) and campaign.first_row(whole) is whole



def test_a_plan_of_whole_sets_says_how_many_frames_it_wrote(tmp_path, capsys) -> None:
    """The ptc plan records whole sets (30 fixed frames, then levels of 4): 63 frames asked for make 62, and the
    command says so (until 2026-11-29 it wrote fewer without a word)."""
    bag = tmp_path / "ptc.mcap"
    assert main(["simulate-bag", str(bag), "--profile", "icx285", "--scenario", "ptc", "--frames", "63",
                 "--width", "32", "--height", "32"]) == 0
    printed = capsys.readouterr().out
    assert len(load_truth(bag)["frames"]) == 62
    assert "62 of the 63 frames asked for: the ptc scenario records whole sets of frames" in printed
    with open_bag(bag) as reader:
        assert len(reader) == 62
