"""Noise model: the paper's sensitivity table, analytic vs Monte-Carlo for every effect, clipping extremes."""
from __future__ import annotations

import numpy as np
import pytest

from noise_monitor.physics import CameraMetadata, EffectError, NoiseModel, load_profile, sample_metadata
from noise_monitor.physics.sensitivity import PAPER_NOISE_MODEL_TABLE, REFERENCE_VALUES, SWEEPS, sweep_cells

MAX_CMOS = REFERENCE_VALUES


@pytest.mark.parametrize("row", list(PAPER_NOISE_MODEL_TABLE))
def test_paper_sensitivity_table_within_5_percent(row: str) -> None:
    model = NoiseModel()
    # the pixel-clock row is readout noise alone (physics.md)
    key = "rn" if row == "pixel_clock_hz" else "total"
    got = [model.predict(v, meta)[key] for v, meta in sweep_cells(row)]
    np.testing.assert_allclose(got, PAPER_NOISE_MODEL_TABLE[row], rtol=0.05)


def test_thermal_white_noise_row_as_ccd_gives_the_values_physics_md_names() -> None:
    model = NoiseModel()
    meta = CameraMetadata(**{**MAX_CMOS, "sensor_type": "ccd"})
    got = [model.predict(128.0, meta.replace(thermal_white_noise_v_per_sqrt_hz=float(w)))["total"]
           for w in SWEEPS["thermal_white_noise_v_per_sqrt_hz"]]
    assert 9.50 < got[0] < 9.56 and 9.55 < got[-1] < 9.60


# --- analytic vs Monte-Carlo -------------------------------------------------------------------
EFFECT_CASES = {
    "paper": [],
    "prnu": ["prnu=3"],
    "dsnu": ["dsnu=0.5"],
    "row_offsets": ["row_offsets=1.5"],
    "column_offsets": ["column_offsets=1.5"],
    "quantization": ["quantization=6"],
    "hot_pixels": ["hot_pixels:fraction=0.05,dark_multiplier=30"],
    "extra_read_noise": ["extra_read_noise=40"],
    "dark_current_law": ["dark_current_law:scale=3,rate_per_k=0.03"],
    "gain_error": ["gain_error=1.6"],
    "exposure_error": ["exposure_error=2"],
    "temperature_error": ["temperature_error=12"],
}


def _metas() -> list[CameraMetadata]:
    icx = load_profile("icx285").metadata(gain_db=6.0, exposure_time_s=0.05, sensor_temperature_c=45.0)
    ev = load_profile("ev76c661").metadata(gain_db=18.0, exposure_time_s=0.1, sensor_temperature_c=60.0)
    small_fw = CameraMetadata(**{**MAX_CMOS, "full_well_e": 2_000.0, "gain_db": 12.0, "exposure_time_s": 0.01,
                                 "sensor_temperature_c": 30.0})
    return [icx, ev, small_fw, sample_metadata(np.random.default_rng(7))]


def _ramp(v: float, shape=(256, 256)) -> np.ndarray:
    """A clean map around v spanning 4 DN (so quantization phases are spread, as in real images)."""
    ramp = np.linspace(-2.0, 2.0, shape[1], dtype=np.float32)[None, :]
    return np.clip(v + np.broadcast_to(ramp, shape), 0.0, 255.0).astype(np.float32)


@pytest.mark.parametrize("mode", ["joint", "sequential"])
@pytest.mark.parametrize("case", list(EFFECT_CASES))
def test_analytic_matches_monte_carlo(case: str, mode: str) -> None:
    model = NoiseModel(extra=EFFECT_CASES[case])
    rng = np.random.default_rng(2024)
    failures = []
    for mi, meta in enumerate(_metas()):
        for v in (0.0, 2.0, 40.0, 128.0, 240.0, 255.0):
            clean = _ramp(v)
            _, mc = model.simulate(clean, meta, rng, mode=mode)
            pred = model.predict(clean, meta, mode=mode)
            for name, truth in mc.items():
                p = pred[name]
                if abs(p - truth) > max(0.03 * truth, 0.05):
                    failures.append(f"meta{mi} v={v} {name}: analytic {p:.4f} vs MC {truth:.4f}")
    assert not failures, "\n".join(failures)


@pytest.mark.parametrize("case", ["paper", "prnu", "hot_pixels", "quantization"])
def test_fast_simulation_path_matches_analytic_total(case: str) -> None:
    model = NoiseModel(extra=EFFECT_CASES[case])
    rng = np.random.default_rng(11)
    for meta in _metas():
        for v in (0.0, 5.0, 128.0, 250.0):
            clean = _ramp(v)
            _, mc = model.simulate(clean, meta, rng, per_source=False)
            assert set(mc) == {"total"}
            p = model.predict(clean, meta)["total"]
            assert abs(p - mc["total"]) <= max(0.03 * mc["total"], 0.05), (meta, v, p, mc)


def test_clipping_extremes() -> None:
    model = NoiseModel()
    meta = CameraMetadata(**{**MAX_CMOS, "full_well_e": 2_000.0})
    # full well 2,000 e-: one pass clipped once, the paper's 118.4 DN
    assert model.predict(128.0, meta)["total"] == pytest.approx(118.4, rel=0.02)
    # the sequential protocol gives more (each source clipped on its own)
    assert model.predict(128.0, meta, mode="sequential")["total"] > 130.0
    # a black or white patch without noise reaching into the range has (almost) no noise
    quiet = load_profile("icx285").metadata(gain_db=0.0, exposure_time_s=0.001, sensor_temperature_c=0.0)
    out0 = model.predict(0.0, quiet)
    assert out0["pn"] == pytest.approx(0.0, abs=1e-6) and out0["total"] < 0.6 * model.predict(128.0, quiet)["rn"]
    # at 0 and 255 only about half of the noise survives the clip
    for v in (0.0, 255.0):
        out = model.predict(v, CameraMetadata(**MAX_CMOS))
        unclipped = model.predict(128.0, CameraMetadata(**MAX_CMOS))["total"]
        assert 0.45 * unclipped < out["total"] < 0.7 * unclipped


def test_predict_shapes_and_map_aggregation() -> None:
    model = NoiseModel()
    meta = load_profile("ev76c661").metadata(gain_db=12.0, exposure_time_s=0.02, sensor_temperature_c=40.0)
    levels = model.predict(np.array([10.0, 100.0, 200.0]), meta)
    assert levels["total"].shape == (3,)
    batch = np.stack([np.full((16, 16), 10.0), np.full((16, 16), 100.0)]).astype(np.float32)
    out = model.predict(batch, meta)
    np.testing.assert_allclose(out["total"], levels["total"][:2], rtol=1e-9)
    # a half-dark, half-bright map: the per-pixel mixture of the two levels
    mixed = np.concatenate([batch[0], batch[1]], axis=1)
    expected = np.sqrt((levels["pn"][0] ** 2 + levels["pn"][1] ** 2) / 2.0)
    assert model.predict(mixed, meta)["pn"] == pytest.approx(expected, rel=1e-6)
    with pytest.raises(ValueError, match="NaN"):
        model.predict(np.array([np.nan]), meta)
    with pytest.raises(ValueError, match="mode"):
        model.predict(1.0, meta, mode="parallel")


def test_a_black_level_effect_reads_the_signal_below_the_output() -> None:
    """The ``black_level`` response: an output level is the signal plus the pedestal, so the photon shot noise is the
    signal's (that at the level less the offset) and the rest of the noise is unchanged."""
    meta = load_profile("ev76c661").metadata(gain_db=12.0, exposure_time_s=0.02, sensor_temperature_c=40.0)
    plain, raised = NoiseModel(), NoiseModel(extra={"black_level": {"offset_dn": 16.0}})
    levels = np.array([40.0, 100.0, 200.0])
    got, want = raised.predict(levels, meta), plain.predict(levels - 16.0, meta)
    np.testing.assert_allclose(got["pn"], want["pn"], rtol=1e-3)
    np.testing.assert_allclose(got["rn"], plain.predict(levels, meta)["rn"], rtol=1e-3)
    assert np.all(got["total"] < plain.predict(levels, meta)["total"])


def test_a_pedestal_keeps_the_noise_below_black() -> None:
    """A camera with a black level b records its dark noise unclipped down to -b (the image returned is without the
    pedestal): at black the noise is the model's unclipped one, and the same draws clip at 0 without it."""
    meta = load_profile("ev76c661").metadata(gain_db=12.0, exposure_time_s=0.02, sensor_temperature_c=40.0)
    black = np.zeros((128, 128), np.float32)
    plain, _ = NoiseModel().simulate(black, meta, np.random.default_rng(5))
    kept, sigmas = NoiseModel().simulate(black, meta, np.random.default_rng(5), black_level_dn=16.0)
    assert plain.min() == 0.0 and kept.min() < -5.0 and kept.min() >= -16.0
    np.testing.assert_array_equal(np.maximum(kept, 0.0), plain)
    dark = float(np.hypot(NoiseModel().predict(100.0, meta)["rn"], NoiseModel().predict(100.0, meta)["dcsn"]))
    assert float(np.std(kept)) == pytest.approx(dark, rel=0.05) and sigmas["total"] == pytest.approx(dark, rel=0.05)
    assert float(np.std(plain)) < 0.7 * dark


def test_simulation_is_seeded_and_overrides_change_only_that_source() -> None:
    model = NoiseModel()
    meta = load_profile("icx285").metadata(gain_db=6.0, exposure_time_s=0.05, sensor_temperature_c=30.0)
    clean = _ramp(100.0, (64, 64))
    a, sa = model.simulate(clean, meta, np.random.default_rng(3), mode="sequential")
    b, sb = model.simulate(clean, meta, np.random.default_rng(3), mode="sequential")
    np.testing.assert_array_equal(a, b)
    assert sa == sb
    louder = meta.replace(gain_db=18.0)
    _, so = model.simulate(clean, meta, np.random.default_rng(3), mode="sequential", overrides={"rn": louder})
    assert so["rn"] > 3.0 * sa["rn"]
    assert so["pn"] == pytest.approx(sa["pn"], rel=1e-6)


def test_effect_failures_are_reported_by_name() -> None:
    with pytest.raises(EffectError, match="unknown effect 'blur'"):
        NoiseModel(extra=["blur"])
    with pytest.raises(EffectError, match="prnu.sigma_pct"):
        NoiseModel(extra=["prnu=-1"])
    with pytest.raises(EffectError, match="listed twice"):
        NoiseModel(extra=["pn"])
