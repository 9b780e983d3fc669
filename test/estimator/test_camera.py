"""Estimator on a camera with effects beyond the paper's sources: prior, data, fine-tuning CLI, replay."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch
import yaml

from noise_monitor.bag.replay import replay
from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.cli import main as cli_main
from noise_monitor.estimator import load
from noise_monitor.estimator.data import camera_model, generate
from noise_monitor.estimator.physics_prior import PhysicsPrior, box_smooth
from noise_monitor.physics import NoiseModel, load_profile
from noise_monitor.physics.metadata import NUMERIC_FIELDS

torch.set_num_threads(1)
EFFECTS = {"column_offsets": {"sigma_dn": 2.0}, "prnu": {"sigma_pct": 1.5}, "gain_error": {"factor": 1.3}}


@pytest.fixture(scope="module")
def meta():
    return load_profile("ev76c661").metadata(gain_db=12.0, exposure_time_s=0.02, sensor_temperature_c=40.0)


@pytest.fixture(scope="module")
def camera_yaml(tmp_path_factory):
    """The bundled EV76C661 profile extended with column offsets of 2 DN (as the lab writes it)."""
    prof = load_profile("ev76c661")
    path = tmp_path_factory.mktemp("camera") / "camera.yaml"
    doc = {"name": "ev76c661_columns", **dict(prof.values), "effects": {"column_offsets": {"sigma_dn": 2.0}}}
    path.write_text(yaml.safe_dump(doc))
    return path


def test_prior_extra_row_matches_noise_model(meta):
    model = NoiseModel(extra=EFFECTS)
    prior = PhysicsPrior(model)
    assert prior.extra_effects == ["column_offsets", "prnu"]  # the modifier changes the paper's sources
    smooth = box_smooth(np.random.default_rng(1).uniform(20, 230, (2, 32, 32)).astype(np.float32))
    fast = prior.predict(smooth, [meta] * 2, debias=False)
    for i in range(2):
        ref = model.predict(smooth[i], meta, mode="sequential")
        for k in ("pn", "dcsn", "rn", "total"):
            assert fast[k][i] == pytest.approx(ref[k], rel=1e-9)
        assert fast["extra"][i] == pytest.approx(np.hypot(ref["column_offsets"], ref["prnu"]), rel=1e-3)
    assert PhysicsPrior().tables(meta).shape[1] == 3  # the paper's camera keeps three rows


def test_data_with_camera_effects():
    sensor = {"full_well_e": 12000.0, "pixel_size_m": 5.3e-6, "sensor_type": "cmos"}
    d = generate(16, 32, seed=5, group=8, progress=False, effects={"column_offsets": {"sigma_dn": 2.0}}, sensor=sensor)
    assert d["tables"].shape[:3] == (2, 2, 4)
    assert np.all(np.abs(d["truth_extra"] - 2.0) < 0.5)  # per-patch std of 32 column offsets of 2 DN
    total = np.sqrt(sum(d[f"truth_{s}"] ** 2 for s in ("pn", "dcsn", "rn", "extra")))
    np.testing.assert_allclose(d["truth_sigma_model"], total, rtol=1e-9)
    clean = ~d["overridden"].any(axis=1) & (d["unexpected"] == 0)
    np.testing.assert_allclose(d["truth_xi"][clean], 0.0, atol=1e-9)
    full_well = d["meta_rows"][:, NUMERIC_FIELDS.index("full_well_e")]  # the sensor is the profile's
    assert np.all(full_well == 12000.0) and np.all(d["meta_rows"][:, -1] == 1)
    # fixed patterns get a fresh seed per group: nothing to memorise
    rng = np.random.default_rng(0)
    seeds = {camera_model({"column_offsets": {"sigma_dn": 2.0}}, rng).effects[-1].pattern_seed() for _ in range(3)}
    assert len(seeds) == 3


def test_train_cli_profile_fine_tune(tmp_path, camera_yaml, meta):
    out = tmp_path / "ft"
    rc = cli_main(["train", "--variant", "full_meta", "--out", str(out), "--steps", "2", "--batch", "4",
                   "--patches", "16", "--patch-size", "32", "--threads", "1", "--profile", str(camera_yaml),
                   "--json", str(tmp_path / "s.json")])
    summary = json.loads((tmp_path / "s.json").read_text())
    assert rc == 0 and summary["effects"] == {"column_offsets": {"sigma_dn": 2.0}}
    assert "--profile" in summary["command"]
    ckpt = torch.load(out / "full_meta.pt", weights_only=True)
    assert ckpt["effects"] == {"column_offsets": {"sigma_dn": 2.0}}
    est = load("full_meta", device="cpu", weights=out / "full_meta.pt", backend="torch")
    flat = np.full((1, 32, 32), 120.0, np.float32)
    res = est.predict(flat, meta)
    assert res["extra"][0] == pytest.approx(2.0, abs=0.02)
    assert res["sigma_model"][0] == pytest.approx(np.sqrt(res["pn"][0] ** 2 + res["dcsn"][0] ** 2 + res["rn"][0] ** 2 + 4.0), rel=1e-6)
    with pytest.warns(UserWarning, match="trained for a camera with column_offsets"):
        load("full_meta", device="cpu", weights=out / "full_meta.pt", backend="torch", model=NoiseModel())
    # the same dataset cannot silently serve another camera
    rc = cli_main(["train", "--variant", "full_meta", "--out", str(out), "--steps", "2", "--patches", "16",
                   "--patch-size", "32", "--threads", "1"])
    assert rc == 2


def test_train_and_evaluate_refuse_what_does_not_fit(tmp_path, camera_yaml, capsys):
    """Until 2026-12-04: a dataset of other size or seed was reused and the asked values recorded; a wrong --init
    failed with a traceback after the data were generated; evaluate read fine-tuned weights on the benchmark's
    effect-free data without a word, and --cards wrote any run's figures over the card."""
    out = tmp_path / "ft"
    base = ["train", "--variant", "full_meta", "--steps", "2", "--batch", "4", "--patch-size", "32", "--threads", "1"]
    assert cli_main(base + ["--out", str(out), "--patches", "16", "--profile", str(camera_yaml)]) == 0
    capsys.readouterr()
    assert cli_main(base + ["--out", str(out), "--patches", "32", "--profile", str(camera_yaml)]) == 2
    assert "holds 16 patches of 32 px from data seed 1, not --patches 32" in capsys.readouterr().err
    for variant, init, needle in (("drne", out / "full_meta.pt", "holds full_meta weights, not drne"),
                                  ("full_meta", out / "train_data.npz", "is not noise_monitor weights")):
        other = tmp_path / f"init_{variant}"
        assert cli_main(["train", "--variant", variant, "--out", str(other), "--patches", "16",
                         "--init", str(init)]) == 2
        assert needle in capsys.readouterr().err and not (other / "train_data.npz").exists()  # before the data
    assert cli_main(["train", "--variant", "full_meta", "--out", str(tmp_path / "r"), "--resume"]) == 2
    assert "--resume: no checkpoint at" in capsys.readouterr().err
    ev = ["evaluate", "--weights-dir", str(out), "--variants", "full_meta", "--cache", str(tmp_path / "cache")]
    assert cli_main(ev + ["--cards"]) == 2
    assert "--cards: full_meta was fine-tuned for a camera with column_offsets" in capsys.readouterr().err
    assert not (out / "full_meta.md").exists()
    shipped = ["evaluate", "--variants", "full_meta", "--cards", "--patches", "20", "--parts", "a"]  # the bundled cards
    assert cli_main(shipped) == 2
    assert "--patches below 600, --parts a would put a smaller run's figures in them" in capsys.readouterr().err
    assert cli_main(ev + ["--patches", "10", "--parts", "a", "--no-peers", "--no-sweep"]) == 0
    assert "note: full_meta was fine-tuned for a camera with column_offsets" in capsys.readouterr().err
    # replay records the checkpoint it ran (until 2026-12-04 only the variant's name)
    from noise_monitor.bag.simulate import simulate_bag

    bag = simulate_bag(tmp_path / "b.mcap", "ev76c661", "static", frames=3, width=96, height=64, seed=1)
    assert cli_main(["replay", str(bag), "--profile", str(camera_yaml), "--weights", str(out / "full_meta.pt"),
                     "--out", str(tmp_path / "rep"), "--json", str(tmp_path / "rep.json"), "--no-plot"]) == 0
    assert json.loads((tmp_path / "rep.json").read_text())["weights"] == str((out / "full_meta.pt").resolve())
    assert f"estimator full_meta ({(out / 'full_meta.pt').resolve()})" in capsys.readouterr().out


def test_replay_uses_the_profile_model_in_the_estimator(tmp_path, camera_yaml):
    bag = simulate_bag(tmp_path / "cols.mcap", camera_yaml, "static", frames=3, width=160, height=128, seed=2)
    s = replay(bag, profile=str(camera_yaml), progress=False, plot=False)
    # estimator total (its physics prior) and the monitor's model agree: both include the column offsets
    assert s["sigma_total"]["mean"] == pytest.approx(s["sigma_model"]["mean"], rel=0.02)
    plain = replay(bag, profile="ev76c661", progress=False, plot=False)
    assert s["sigma_model"]["mean"] ** 2 - plain["sigma_model"]["mean"] ** 2 == pytest.approx(4.0, rel=0.1)


def test_a_model_card_says_whether_its_data_were_generated_or_reused(tmp_path):
    """A dataset generated in seconds was described as "pre-generated" (the card guessed from the time); train now
    records whether it reused a dataset file (2026-12-04)."""
    out = tmp_path / "w"
    base = ["train", "--variant", "full_meta", "--out", str(out), "--steps", "2", "--batch", "4", "--patches", "16",
            "--patch-size", "32", "--threads", "1", "--json", str(out / "full_meta.train.json")]
    assert cli_main(base) == 0
    assert json.loads((out / "full_meta.train.json").read_text())["data_reused"] is False
    ev = ["evaluate", "--weights-dir", str(out), "--variants", "full_meta", "--patches", "10", "--parts", "a",
          "--no-peers", "--no-sweep", "--cards", "--cache", str(tmp_path / "cache")]
    assert cli_main(ev) == 0
    card = (out / "full_meta.md").read_text()
    assert "generated in 0.0 min" in card and "pre-generated" not in card
    assert cli_main(base) == 0 and cli_main(ev) == 0  # the same dataset file again
    assert "(pre-generated dataset file;" in (out / "full_meta.md").read_text()
