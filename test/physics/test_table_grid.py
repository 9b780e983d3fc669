"""Interpolated physics tables (metadata that changes every frame) against the exact tables."""
from __future__ import annotations

import math

import numpy as np
import pytest

from noise_monitor.monitor.model_patches import predict_patches
from noise_monitor.physics import CameraMetadata, NoiseModel, load_profile, sample_static
from noise_monitor.physics.model import _V_GRID
from noise_monitor.physics.table_grid import GridSpec

SPEC = GridSpec()


def _sigma(t: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    m1, m2 = t
    return np.sqrt(np.maximum(m2 - m1**2, 0.0))


def _worst(exact: NoiseModel, interp: NoiseModel, meta: CameraMetadata, modes=("joint", "sequential")) -> float:
    """Largest |sigma_interp - sigma_exact| / max(0.5 % sigma_exact, 0.01 DN) over levels, tables, modes."""
    worst = 0.0
    for mode in modes:
        te, ti = exact.tables(meta, mode), interp.tables(meta, mode)
        assert set(te) == set(ti)
        for name in te:
            se, si = _sigma(te[name]), _sigma(ti[name])
            worst = max(worst, float(np.max(np.abs(si - se) / np.maximum(0.005 * se, 0.01))))
    return worst


def _cell_centre(rng: np.random.Generator, static: dict) -> CameraMetadata:
    """Random conditions over the paper's ranges moved to the centre of their lattice cell (the worst place)."""
    g = (math.floor(rng.uniform(0, 24.08) / SPEC.gain_step_db - 0.5) + 0.5) * SPEC.gain_step_db
    lt = (math.floor(rng.uniform(math.log(1e-3), math.log(0.2)) / SPEC.log_exposure_step) + 0.5) * SPEC.log_exposure_step
    t = (math.floor(rng.uniform(0, 80) / SPEC.temperature_step_c - 0.5) + 0.5) * SPEC.temperature_step_c
    return CameraMetadata.from_mapping({**static, "gain_db": max(g, 0.75), "exposure_time_s": math.exp(lt),
                                        "sensor_temperature_c": max(t, 2.5)})


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_interpolated_tables_within_bound_at_random_cameras(seed):
    rng = np.random.default_rng(seed)
    meta = _cell_centre(rng, sample_static(rng))
    assert _worst(NoiseModel(), NoiseModel(interpolate=True), meta) <= 1.0


@pytest.mark.parametrize("profile", ["icx285", "ev76c661"])
def test_interpolated_tables_within_bound_for_profiles_with_effects(profile):
    """Joint mode (the node's model_mode) of a camera with more effects; the sequential protocol of such a
    model is looser (effects after the chain: up to 1.4x the bound, bench/bench_table_grid.py)."""
    effects = {"prnu": {}, "dsnu": {}, "hot_pixels": {}, "quantization": {"bits": 8}, "dark_current_law": {}}
    meta = load_profile(profile).metadata(gain_db=12.75, exposure_time_s=math.exp(-4.5 * 0.35 - 2.0),
                                          sensor_temperature_c=37.5)
    exact, interp = NoiseModel(extra=effects), NoiseModel(extra=effects, interpolate=True)
    assert _worst(exact, interp, meta, modes=("joint",)) <= 1.0
    assert _worst(exact, interp, meta, modes=("sequential",)) <= 2.0


def test_interpolated_maps_match_exact_predict():
    meta = load_profile("ev76c661").metadata(gain_db=9.7, exposure_time_s=0.013, sensor_temperature_c=51.3)
    rng = np.random.default_rng(4)
    maps = np.clip(rng.uniform(0, 255, (6, 1, 1)) + rng.normal(0, 25, (6, 32, 32)), 0, 255)
    exact, interp = NoiseModel(), NoiseModel(interpolate=True)
    for mode in ("joint", "sequential"):
        a, b = exact.predict(maps, meta, mode), predict_patches(interp, maps, meta, mode)
        for name in a:
            assert np.all(np.abs(b[name] - a[name]) <= np.maximum(0.005 * a[name], 0.01)), (mode, name)


def test_drifting_metadata_reuses_nodes():
    """A temperature drifting every frame plus auto-exposure: tables per frame without recomputation."""
    profile = load_profile("icx285")
    model = NoiseModel(interpolate=True)
    for i in range(300):
        meta = profile.metadata(gain_db=18.0, exposure_time_s=0.01 * (1.0 + 0.2 * math.sin(i / 15.0)),
                                sensor_temperature_c=40.0 + 0.013 * i)
        model.tables(meta, "joint")
        model.tables(meta, "sequential")
    # 300 distinct metadata sets, both modes: only the lattice nodes around the path were computed
    assert model.grid.nodes_computed <= 2 * 16


def test_at_a_node_equals_exact_and_outside_lattice_falls_back():
    profile = load_profile("icx285")
    node = profile.metadata(gain_db=6.0, exposure_time_s=math.exp(-14 * SPEC.log_exposure_step),
                            sensor_temperature_c=25.0)
    exact, interp = NoiseModel(), NoiseModel(interpolate=True)
    for name, (m1, m2) in exact.tables(node, "joint").items():
        i1, i2 = interp.tables(node, "joint")[name]
        np.testing.assert_allclose(i1, m1, atol=1e-12)
        np.testing.assert_allclose(i2, m2, rtol=1e-9, atol=1e-12)
    high = profile.metadata(gain_db=6.0, exposure_time_s=580.0, sensor_temperature_c=25.0)  # upper node e^6.65 s > 600 s
    before = interp.grid.nodes_computed
    for name, (m1, m2) in exact.tables(high, "joint").items():
        np.testing.assert_allclose(interp.tables(high, "joint")[name][1], m2, rtol=1e-12)
    assert interp.grid.nodes_computed == before
    assert _V_GRID.size == next(iter(exact.tables(high, "joint").values()))[0].size


def test_grid_spec_rejects_bad_steps():
    with pytest.raises(ValueError, match="gain_step_db"):
        GridSpec(gain_step_db=0.0)
    with pytest.raises(ValueError, match="max_nodes"):
        GridSpec(max_nodes=2)


def test_held_metadata_gets_exact_tables_and_drifting_metadata_the_lattice():
    """GridSpec.held_exact_requests (the runtime's policy): a first or held metadata set is computed
    exactly (cheaper than a lattice cell), conditions changing at every request are interpolated."""
    profile = load_profile("icx285")
    exact = NoiseModel()
    model = NoiseModel(interpolate=GridSpec(held_exact_requests=3))
    held = [profile.metadata(gain_db=g, exposure_time_s=0.01, sensor_temperature_c=40.0) for g in (6.1, 9.3, 12.7)]
    for meta in held:  # each set serves 3 requests (frames) before the next arrives
        for _ in range(3):
            tables = model.tables(meta, "joint")
        for name, (m1, m2) in exact.tables(meta, "joint").items():
            np.testing.assert_array_equal(tables[name][1], m2)
    assert model.grid.nodes_computed == 0
    for i in range(20):  # a temperature drifting every frame
        model.tables(profile.metadata(gain_db=12.7, exposure_time_s=0.01, sensor_temperature_c=40.0 + 0.05 * i), "joint")
    assert 0 < model.grid.nodes_computed <= 16
