"""Property-based tests (hypothesis) of CameraMetadata validation and normalisation."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from noise_monitor.physics import PAPER_RANGES, CameraMetadata, MetadataError, NoiseModel
from noise_monitor.physics.metadata import NUMERIC_FIELDS, VALID_RANGES

settings.register_profile("ci", max_examples=60, deadline=None, derandomize=True)
settings.load_profile("ci")


def _valid_values() -> st.SearchStrategy[dict]:
    fields = {n: st.floats(*VALID_RANGES[n], allow_nan=False) for n in NUMERIC_FIELDS}
    return st.fixed_dictionaries({**fields, "sensor_type": st.sampled_from(["ccd", "CMOS", " cmos "])})


def _paper_values() -> st.SearchStrategy[dict]:
    fields = {n: st.floats(*PAPER_RANGES[n], allow_nan=False) for n in NUMERIC_FIELDS}
    return st.fixed_dictionaries({**fields, "sensor_type": st.sampled_from(["ccd", "cmos"])})


@given(_valid_values())
def test_every_valid_value_is_accepted_and_round_trips(values: dict) -> None:
    meta = CameraMetadata.from_mapping(values)
    assert meta.sensor_type in ("ccd", "cmos")
    assert CameraMetadata.from_mapping(meta.as_dict()) == meta
    assert np.all(np.isfinite(meta.normalized()))


@given(_paper_values())
def test_paper_range_values_normalise_into_unit_interval(values: dict) -> None:
    norm = CameraMetadata.from_mapping(values).normalized()
    assert norm.dtype == np.float32 and norm.shape == (11,)
    assert np.all(norm >= -1e-6) and np.all(norm <= 1 + 1e-6)
    assert CameraMetadata.from_mapping(values).outside_paper_ranges() == []


@given(_valid_values(), st.sampled_from(NUMERIC_FIELDS),
       st.one_of(st.just(math.nan), st.just(math.inf), st.just(-math.inf), st.floats(-1e12, 1e12)))
def test_invalid_values_are_rejected_naming_the_field(values: dict, field: str, bad: float) -> None:
    lo, hi = VALID_RANGES[field]
    values = {**values, field: bad}
    if math.isfinite(bad) and lo <= bad <= hi:
        CameraMetadata.from_mapping(values)
        return
    with pytest.raises(MetadataError) as err:
        CameraMetadata.from_mapping(values)
    assert field in str(err.value)


@given(_paper_values(), st.floats(0.0, 255.0))
def test_predictions_are_finite_and_never_exceed_the_unclipped_noise(values: dict, level: float) -> None:
    meta = CameraMetadata.from_mapping(values)
    model = NoiseModel()
    out = model.predict(level, meta)
    assert all(math.isfinite(v) and v >= 0.0 for v in out.values())
    # clipping is a contraction, so it never adds variance: total <= the unclipped quadrature sum
    cond = model.conditions(meta)
    unclipped = math.sqrt(sum(float(e.variance_dn2(level, cond)) for e in model.effects))
    assert out["total"] <= unclipped * 1.001 + 1e-6
