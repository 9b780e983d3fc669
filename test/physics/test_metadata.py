"""CameraMetadata: units, validation errors that name the field and range, normalisation, profiles, samplers."""
from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from noise_monitor.physics import (
    NORMALIZED_ORDER,
    PAPER_RANGES,
    CameraMetadata,
    MetadataError,
    db_to_factor,
    factor_to_db,
    load_profile,
    sample_metadata,
)
from noise_monitor.physics.metadata import celsius_to_kelvin, kelvin_to_celsius, profile_from_mapping


def _meta(**kw) -> CameraMetadata:
    return load_profile("ev76c661").metadata(**{"gain_db": 6.0, "exposure_time_s": 0.01, "sensor_temperature_c": 25.0, **kw})


def test_unit_conversions() -> None:
    assert db_to_factor(20.0) == pytest.approx(10.0)
    assert factor_to_db(16.0) == pytest.approx(24.0824, abs=1e-4)
    np.testing.assert_allclose(db_to_factor(np.array([0.0, 6.0206])), [1.0, 2.0], rtol=1e-5)
    assert celsius_to_kelvin(0.0) == 273.15 and kelvin_to_celsius(373.15) == pytest.approx(100.0)
    m = _meta(gain_db=factor_to_db(4.0), sensor_temperature_c=26.85)
    assert m.gain == pytest.approx(4.0) and m.temperature_k == pytest.approx(300.0)
    assert m.dn_per_electron == pytest.approx(255.0 / 8400.0)


@pytest.mark.parametrize(
    "field,value,pattern",
    [
        ("gain_db", -3.0, r"gain_db = -3 dB is outside the allowed range \[0, 48\] dB"),
        ("exposure_time_s", math.nan, r"exposure_time_s is not finite"),
        ("sensor_temperature_c", math.inf, r"sensor_temperature_c is not finite"),
        ("full_well_e", 5.0, r"full_well_e = 5 e- is outside the allowed range"),
        ("sense_node_reset_factor", 1.5, r"sense_node_reset_factor = 1.5 1 is outside the allowed range \[0, 1\]"),
        ("pixel_size_m", "big", r"pixel_size_m must be a number in m"),
        ("sensor_type", "ccd-ish", r"sensor_type must be one of \('ccd', 'cmos'\)"),
        ("bit_depth", 33, r"bit_depth must be an integer in \[1, 16\]"),
    ],
)
def test_invalid_values_name_field_and_range(field: str, value, pattern: str) -> None:
    with pytest.raises(MetadataError, match=pattern):
        _meta().replace(**{field: value})


def test_missing_and_unknown_fields_are_named() -> None:
    values = _meta().as_dict()
    del values["exposure_time_s"], values["full_well_e"]
    with pytest.raises(MetadataError, match="missing metadata field.*exposure_time_s, full_well_e"):
        CameraMetadata.from_mapping(values)
    with pytest.raises(MetadataError, match="unknown metadata field.*shutter"):
        CameraMetadata.from_mapping({**_meta().as_dict(), "shutter": 1})
    assert CameraMetadata.from_mapping({k: str(v) for k, v in _meta().as_dict().items()}) == _meta()


def test_normalized_uses_the_paper_ranges() -> None:
    lo = {k: v[0] for k, v in PAPER_RANGES.items()}
    hi = {k: v[1] for k, v in PAPER_RANGES.items()}
    n_lo = CameraMetadata(**lo, sensor_type="cmos").normalized()
    n_hi = CameraMetadata(**hi, sensor_type="ccd").normalized()
    np.testing.assert_allclose(n_lo, 0.0, atol=1e-6)
    np.testing.assert_allclose(n_hi, 1.0, atol=1e-6)
    mid = CameraMetadata(**{**lo, "gain_db": factor_to_db(8.5)}, sensor_type="cmos").normalized()
    assert mid[NORMALIZED_ORDER.index("gain_db")] == pytest.approx(0.5)  # gain as a factor 1..16
    assert len(NORMALIZED_ORDER) == 11
    assert _meta(gain_db=30.0).outside_paper_ranges() == ["gain_db"]


def test_bundled_profiles() -> None:
    icx = load_profile("icx285")
    assert icx.name == "ICX285" and icx.values["sensor_type"] == "ccd" and icx.values["full_well_e"] == 14000
    ev = load_profile("ev76c661")
    assert ev.values["pixel_clock_hz"] == 90e6 and ev.values["dark_signal_fom_na_cm2"] == 0.957
    gen = load_profile("generic").metadata(gain_db=0.0, exposure_time_s=0.01, sensor_temperature_c=30.0)
    assert gen.sensor_type == "cmos"
    with pytest.raises(FileNotFoundError, match="camera profile 'nosuch'"):
        load_profile("nosuch")


def test_profile_errors_name_the_keys() -> None:
    with pytest.raises(MetadataError, match="unknown key.*colour"):
        profile_from_mapping({"name": "x", "colour": "red"})
    with pytest.raises(MetadataError, match="full_well_e = -1"):
        profile_from_mapping({"name": "x", "full_well_e": -1})
    p = profile_from_mapping({"name": "x", "effects": ["prnu"]})
    assert p.effects == {"prnu": {}}
    with pytest.raises(MetadataError, match="missing metadata field.*full_well_e"):
        p.metadata(gain_db=0.0)


def test_profile_black_level_round_trips_and_is_checked() -> None:
    """A camera's black level (pedestal, 8-bit DN scale) is a profile key; it survives to_yaml and is a number in
    [0, 255)."""
    p = profile_from_mapping({"name": "x", "black_level_dn": 15.95})
    assert p.black_level_dn == 15.95
    assert profile_from_mapping(yaml.safe_load(p.to_yaml())).black_level_dn == 15.95
    assert profile_from_mapping({"name": "x"}).black_level_dn == 0.0 and "black" not in load_profile("icx285").to_yaml()
    for bad in (-1, 255, "16", True):
        with pytest.raises(MetadataError, match="black_level_dn must be a number"):
            profile_from_mapping({"name": "x", "black_level_dn": bad})


def test_samplers_are_seeded_and_cover_the_paper_ranges() -> None:
    a = [sample_metadata(np.random.default_rng(5)) for _ in range(2)]
    assert a[0] == a[1]
    metas = [sample_metadata(np.random.default_rng(i)) for i in range(300)]
    norm = np.stack([m.normalized() for m in metas])
    assert norm.min() >= 0.0 and norm.max() <= 1.0
    assert (norm.min(axis=0)[:-1] < 0.1).all() and (norm.max(axis=0)[:-1] > 0.9).all()
    assert {m.sensor_type for m in metas} == {"ccd", "cmos"}
