"""Property-based tests (hypothesis) of msg_adapters: images, metadata mappings, diagnostics, CameraInfo.

The central property: whatever a message holds, an adapter either returns a correct, finite result or
raises AdapterError / MetadataError (ValueErrors with a reason), never anything else.
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from rosbags.typesys import Stores, get_typestore

from msg_adapters import (
    LEVEL_NAMES,
    SUPPORTED_ENCODINGS,
    AdapterError,
    StatusReport,
    camera_geometry,
    image_to_gray_dn,
    metadata_from_mapping,
    reports_from_msg,
    resolve_metadata,
    to_rclpy,
    to_rosbags,
)
from msg_adapters.metadata import ALIASES, KNOWN_FIELDS
from noise_monitor.physics import CameraMetadata, MetadataError, load_profile
from noise_monitor.physics.metadata import DYNAMIC_FIELDS, VALID_RANGES

TS = get_typestore(Stores.ROS2_JAZZY)
PROFILE = load_profile("ev76c661")
FAST = settings(max_examples=80, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def msg(pixels: np.ndarray, encoding: str, pad: bytes = b"", bigendian: bool = False) -> SimpleNamespace:
    """A duck-typed Image (the adapters read fields only) with ``pad`` after every row."""
    h, w = pixels.shape[:2]
    dtype = pixels.dtype.newbyteorder(">" if bigendian else "<")
    rows = np.ascontiguousarray(pixels.astype(dtype)).reshape(h, -1).view(np.uint8)
    padded = np.concatenate([rows, np.tile(np.frombuffer(pad, np.uint8), (h, 1))], axis=1)
    return SimpleNamespace(height=h, width=w, encoding=encoding, is_bigendian=int(bigendian),
                           step=padded.shape[1], data=padded.tobytes())


shapes = st.tuples(st.integers(1, 9), st.integers(1, 9))


@FAST
@given(hnp.arrays(np.uint8, shapes), st.binary(max_size=5), st.sampled_from(["mono8", "8UC1", "MONO8"]))
def test_mono8_is_exact_whatever_the_row_padding(pixels, pad, encoding):
    out = image_to_gray_dn(msg(pixels, encoding, pad))
    assert out.dtype == np.float32 and out.shape == pixels.shape
    np.testing.assert_array_equal(out, pixels)


@FAST
@given(hnp.arrays(np.uint16, shapes), st.integers(1, 16), st.booleans(), st.binary(max_size=4))
def test_mono16_scales_to_0_255_or_names_the_overflowing_value(pixels, bits, bigendian, pad):
    m = msg(pixels, "mono16", pad, bigendian)
    top = (1 << bits) - 1
    if int(pixels.max()) > top:
        with pytest.raises(AdapterError, match=f"pixel value {int(pixels.max())} exceeds the {bits}-bit range"):
            image_to_gray_dn(m, bit_depth=bits)
        return
    out = image_to_gray_dn(m, bit_depth=bits)
    np.testing.assert_allclose(out, pixels * (255.0 / top), rtol=1e-6, atol=1e-4)
    assert 0.0 <= out.min() and out.max() <= 255.0 + 1e-3


@FAST
@given(hnp.arrays(np.uint8, st.tuples(st.integers(1, 6), st.integers(1, 6), st.just(3))),
       st.sampled_from(["rgb8", "bgr8"]))
def test_colour_luma_is_a_weighted_mean_within_the_channel_range(pixels, encoding):
    out = image_to_gray_dn(msg(pixels, encoding))
    rgb = pixels.astype(np.float64) if encoding == "rgb8" else pixels[..., ::-1].astype(np.float64)
    np.testing.assert_allclose(out, rgb @ [0.299, 0.587, 0.114], atol=1e-3)
    assert np.all(out >= pixels.min(axis=2) - 1e-3) and np.all(out <= pixels.max(axis=2) + 1e-3)


sizes = st.one_of(st.integers(1, 12), st.integers(-2, 0))
header_encodings = st.sampled_from([e.lower() for e in SUPPORTED_ENCODINGS] + ["nv21", "32FC1", "", "mono12"])
YUV = ("yuv422", "yuv422_yuy2", "yuyv", "uyvy")


def row_bytes(encoding: str, width: int) -> int:
    """Bytes of one unpadded row of a supported encoding (1 for unsupported ones)."""
    channels = 4 if "a" in encoding[2:4] else 3 if encoding[:3] in ("rgb", "bgr") else 2 if encoding in YUV else 1
    return width * channels * (2 if "16" in encoding else 1)


@FAST
@given(st.sampled_from(SUPPORTED_ENCODINGS), st.integers(2, 8), st.integers(2, 8), st.integers(0, 3), st.data(),
       st.booleans(), st.sampled_from(["luma", "green"]))
def test_every_supported_encoding_with_a_consistent_header_converts(enc, h, w, pad, draw, big, color):
    step = row_bytes(enc.lower(), w) + pad
    data = draw.draw(st.binary(min_size=step * h, max_size=step * h))
    m = SimpleNamespace(height=h, width=w, step=step, encoding=enc, is_bigendian=int(big), data=data)
    if enc in YUV and color == "green":
        with pytest.raises(AdapterError, match="no green channel"):
            image_to_gray_dn(m, color=color)
        return
    out = image_to_gray_dn(m, color=color)
    if enc.startswith("bayer"):  # one green site per 2x2 cell (odd sizes: a partial cell may count)
        assert out.shape[0] in (h // 2, (h + 1) // 2) and out.shape[1] in (w // 2, (w + 1) // 2)
    else:
        assert out.shape == (h, w)
    assert out.dtype == np.float32 and np.all(np.isfinite(out)) and 0.0 <= out.min() and out.max() <= 255.0 + 1e-3


@FAST
@given(sizes, sizes, header_encodings, st.data(), st.booleans(),
       st.one_of(st.none(), st.integers(-2, 18)), st.sampled_from(["luma", "green"]))
def test_any_header_and_data_give_a_valid_image_or_an_adapter_error(h, w, enc, draw, big, bits, color):
    # fuzzed headers; some steps and data sizes fit the header (within the last row's padding)
    step = draw.draw(st.one_of(st.integers(-2, 40), st.integers(0, 3).map(lambda p: row_bytes(enc, w) + p)))
    fits = st.integers(max(min(step * h - step, step * h), 0), max(step * h, 0))
    size = draw.draw(st.one_of(fits, st.integers(0, 300)))
    data = draw.draw(st.binary(min_size=size, max_size=size))
    m = SimpleNamespace(height=h, width=w, step=step, encoding=enc, is_bigendian=int(big), data=data)
    try:
        out = image_to_gray_dn(m, bit_depth=bits, color=color)
    except AdapterError as exc:
        assert str(exc)
        return
    assert out.dtype == np.float32 and out.ndim == 2 and out.size > 0
    if enc.startswith("bayer"):  # one green site per 2x2 cell (odd sizes: the last, partial cell counts)
        assert out.shape[0] in (h // 2, (h + 1) // 2) and out.shape[1] in (w // 2, (w + 1) // 2)
    else:
        assert out.shape == (h, w)
    assert np.all(np.isfinite(out)) and out.min() >= 0.0 and out.max() <= 255.0 + 1e-3
    assert step * (h - 1) < len(data) <= step * h  # accepted only when the data fits the header


# --- metadata ------------------------------------------------------------------------------------
keys = st.one_of(st.sampled_from(sorted(KNOWN_FIELDS | set(ALIASES))), st.text(max_size=12))
values = st.one_of(st.none(), st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**6, 10**6),
                   st.text(max_size=12), st.floats(-1e3, 1e3).map(lambda v: f" {v!r} "))


@FAST
@given(st.dictionaries(keys, values, max_size=8))
def test_metadata_mapping_keeps_only_known_fields_as_finite_numbers_or_says_why(mapping):
    try:
        out = metadata_from_mapping(mapping)
    except AdapterError as exc:
        assert "metadata value" in str(exc)
        return
    assert set(out) <= KNOWN_FIELDS
    for k, v in out.items():
        if k == "sensor_type":
            assert isinstance(v, str) and v == v.strip().lower()
        else:
            assert isinstance(v, (int, float)) and math.isfinite(v)


@FAST
@given(st.sampled_from(sorted(ALIASES)), st.floats(-1e6, 1e6, allow_nan=False))
def test_aliases_convert_to_si_and_never_override_the_si_field(alias, value):
    field, scale, offset = ALIASES[alias]
    assert metadata_from_mapping({alias: str(value)})[field] == pytest.approx(value * scale + offset)
    assert metadata_from_mapping({field: 1.0, alias: value})[field] == 1.0


dynamic = st.fixed_dictionaries({n: st.floats(-1e3, 1e3, allow_nan=False) for n in DYNAMIC_FIELDS})


@FAST
@given(dynamic, st.one_of(st.none(), st.floats(-400, 400, allow_nan=False)))
def test_resolve_metadata_is_valid_metadata_with_the_dynamic_values_or_a_named_error(dyn, temperature):
    try:
        meta, missing = resolve_metadata(PROFILE, {k: repr(v) for k, v in dyn.items()}, temperature)
    except MetadataError as exc:
        bad = [n for n, v in dyn.items() if not VALID_RANGES[n][0] <= v <= VALID_RANGES[n][1]]
        assert bad and any(n in str(exc) for n in bad)
        return
    assert missing == [] and isinstance(meta, CameraMetadata)
    for name, value in dyn.items():  # the per-frame message wins over profile and Temperature topic
        assert getattr(meta, name) == value
    assert meta.full_well_e == PROFILE.values["full_well_e"] and np.all(np.isfinite(meta.normalized()))


@FAST
@given(st.sets(st.sampled_from(DYNAMIC_FIELDS)))
def test_missing_fields_are_listed_exactly(present):
    meta, missing = resolve_metadata(PROFILE, {n: "1.0" for n in present})
    expected = [n for n in DYNAMIC_FIELDS if n not in present]
    assert missing == expected and (meta is None) == bool(expected)


# --- diagnostics and CameraInfo ------------------------------------------------------------------
text = st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"), max_size=20)
reports = st.builds(StatusReport, st.sampled_from(sorted(LEVEL_NAMES)), text, text, text,
                    st.dictionaries(text, text, max_size=4))


@settings(FAST, max_examples=40)
@given(st.lists(reports, max_size=3), st.integers(0, 2**31 * 10**9 - 1))  # builtin_interfaces/Time: int32 sec
def test_status_reports_survive_both_middlewares_and_cdr(items, stamp_ns):
    from rclpy.serialization import serialize_message

    rc = to_rclpy(items, stamp_ns)
    rb = to_rosbags(items, stamp_ns, TS)
    via_cdr = TS.deserialize_cdr(serialize_message(rc), "diagnostic_msgs/msg/DiagnosticArray")
    rb_back = TS.deserialize_cdr(TS.serialize_cdr(rb, "diagnostic_msgs/msg/DiagnosticArray"),
                                 "diagnostic_msgs/msg/DiagnosticArray")
    assert reports_from_msg(rc) == reports_from_msg(via_cdr) == reports_from_msg(rb_back) == items
    stamp = via_cdr.header.stamp
    assert stamp.sec * 10**9 + stamp.nanosec == stamp_ns


@FAST
@given(st.integers(1, 4000), st.integers(1, 4000), st.integers(0, 4), st.integers(0, 4),
       st.tuples(st.integers(0, 4000), st.integers(0, 4000), st.integers(0, 4000), st.integers(0, 4000)))
def test_camera_info_geometry_accepts_exactly_the_image_size_it_implies(w, h, bx, by, roi):
    info = SimpleNamespace(width=w, height=h, binning_x=bx, binning_y=by, roi=SimpleNamespace(
        x_offset=roi[0], y_offset=roi[1], width=roi[2], height=roi[3]))
    try:
        geo = camera_geometry(info)
    except AdapterError as exc:
        assert "exceeds the sensor size" in str(exc)
        assert roi[2] and roi[3] and (roi[0] + roi[2] > w or roi[1] + roi[3] > h)
        return
    ih, iw = geo.image_size
    geo.check_image(ih, iw)
    with pytest.raises(AdapterError, match="but CameraInfo implies"):
        geo.check_image(ih + 1, iw)
