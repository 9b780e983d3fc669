"""msg_adapters on real rclpy messages and real rosbags-deserialised messages."""
from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from msg_adapters import (
    AdapterError,
    StatusReport,
    camera_geometry,
    image_to_gray_dn,
    metadata_from_diagnostics,
    metadata_from_temperature,
    metadata_from_vendor,
    register_vendor_types,
    reports_from_msg,
    resolve_metadata,
    to_rclpy,
    to_rosbags,
)
from noise_monitor.physics import MetadataError, load_profile

TS = get_typestore(Stores.ROS2_JAZZY)


def rclpy_image(pixels: np.ndarray, encoding: str, pad: int = 0, bigendian: bool = False):
    from sensor_msgs.msg import Image

    h, w = pixels.shape[:2]
    dtype = pixels.dtype.newbyteorder(">" if bigendian else "<") if pixels.dtype.itemsize > 1 else pixels.dtype
    rows = pixels.astype(dtype).reshape(h, -1).view(np.uint8)
    data = np.concatenate([rows, np.full((h, pad), 7, np.uint8)], axis=1)
    return Image(height=h, width=w, encoding=encoding, is_bigendian=int(bigendian), step=data.shape[1],
                 data=data.tobytes())


def rosbags_roundtrip(msg, msgtype: str, typestore=TS):
    """Serialise an rclpy message to CDR and deserialise it with rosbags (what a bag reader sees)."""
    from rclpy.serialization import serialize_message

    return typestore.deserialize_cdr(serialize_message(msg), msgtype)


@pytest.mark.parametrize("pad", [0, 3])
def test_mono8_with_step_padding_same_on_both_middlewares(rng, pad):
    pixels = rng.integers(0, 256, (5, 7), dtype=np.uint8)
    msg = rclpy_image(pixels, "mono8", pad=pad)
    for m in (msg, rosbags_roundtrip(msg, "sensor_msgs/msg/Image")):
        out = image_to_gray_dn(m)
        assert out.dtype == np.float32 and out.shape == (5, 7)
        np.testing.assert_array_equal(out, pixels.astype(np.float32))


@pytest.mark.parametrize("bigendian", [False, True])
def test_mono16_twelve_bit_scaled_to_8bit_range(rng, bigendian):
    pixels = rng.integers(0, 4096, (4, 6)).astype(np.uint16)
    pixels[0, 0] = 4095
    msg = rclpy_image(pixels, "mono16", pad=2, bigendian=bigendian)
    out = image_to_gray_dn(rosbags_roundtrip(msg, "sensor_msgs/msg/Image"), bit_depth=12)
    np.testing.assert_allclose(out, pixels * (255.0 / 4095.0), rtol=1e-6)
    assert out.max() == pytest.approx(255.0)
    full = image_to_gray_dn(msg)  # default: the container's 16 bits
    np.testing.assert_allclose(full, pixels * (255.0 / 65535.0), rtol=1e-6)


def test_mono16_values_beyond_bit_depth_are_an_error():
    msg = rclpy_image(np.array([[5000, 3]], np.uint16), "mono16")
    with pytest.raises(AdapterError, match="exceeds the 12-bit range"):
        image_to_gray_dn(msg, bit_depth=12)


@pytest.mark.parametrize("encoding,code", [
    ("rgb8", cv2.COLOR_RGB2GRAY), ("bgr8", cv2.COLOR_BGR2GRAY),
    ("rgba8", cv2.COLOR_RGBA2GRAY), ("bgra8", cv2.COLOR_BGRA2GRAY),
])
def test_color_luma_matches_opencv(rng, encoding, code):
    channels = 4 if "a" in encoding[3:] else 3
    pixels = rng.integers(0, 256, (6, 5, channels), dtype=np.uint8)
    out = image_to_gray_dn(rclpy_image(pixels, encoding, pad=1))
    np.testing.assert_allclose(out, cv2.cvtColor(pixels, code).astype(np.float32), atol=0.51)
    green = image_to_gray_dn(rclpy_image(pixels, encoding), color="green")
    np.testing.assert_array_equal(green, pixels[:, :, 1].astype(np.float32))


@pytest.mark.parametrize("pattern,site", [("rggb", (0, 1)), ("bggr", (1, 0)), ("gbrg", (0, 0)), ("grbg", (1, 1))])
def test_bayer_keeps_one_green_site_per_cell(rng, pattern, site):
    pixels = rng.integers(0, 256, (8, 6), dtype=np.uint8)
    green_mask = np.zeros((2, 2), bool)
    green_mask[site] = True
    green_mask[1 - site[0], 1 - site[1]] = True
    out = image_to_gray_dn(rosbags_roundtrip(rclpy_image(pixels, f"bayer_{pattern}8"), "sensor_msgs/msg/Image"))
    assert out.shape == (4, 3)
    r, c = [(i, j) for i in range(2) for j in range(2) if green_mask[i, j]][0]
    np.testing.assert_array_equal(out, pixels[r::2, c::2].astype(np.float32))


@pytest.mark.parametrize("encoding,code", [
    ("yuv422_yuy2", cv2.COLOR_YUV2GRAY_YUY2), ("yuyv", cv2.COLOR_YUV2GRAY_YUY2),
    ("yuv422", cv2.COLOR_YUV2GRAY_UYVY), ("uyvy", cv2.COLOR_YUV2GRAY_UYVY),
])
def test_yuv422_gives_its_luma_at_full_resolution(rng, encoding, code):
    """4:2:2 YUV (USB cameras, camera_ros's YUYV / UYVY): every pixel's Y, as OpenCV reads it; no green channel."""
    pairs = rng.integers(0, 256, (6, 8, 2), dtype=np.uint8)  # (luma, chroma) or (chroma, luma) byte per pixel
    for msg in (rclpy_image(pairs, encoding, pad=2),
                rosbags_roundtrip(rclpy_image(pairs, encoding), "sensor_msgs/msg/Image")):
        out = image_to_gray_dn(msg)
        assert out.shape == (6, 8)
        np.testing.assert_array_equal(out, cv2.cvtColor(pairs, code).astype(np.float32))
    with pytest.raises(AdapterError, match="a YUV image has no green channel"):
        image_to_gray_dn(rclpy_image(pairs, encoding), color="green")


@pytest.mark.parametrize("change,match", [
    ({"encoding": "nv21"}, "unsupported image encoding"),
    ({"step": 3}, "step 3 is smaller"),
    ({"height": 9}, "image data has"),
    ({"width": 0}, "empty image"),
])
def test_bad_images_give_clear_errors(change, match):
    msg = rclpy_image(np.zeros((4, 4), np.uint8), "mono8")
    for k, v in change.items():
        setattr(msg, k, v)
    with pytest.raises(AdapterError, match=match):
        image_to_gray_dn(msg)


def rclpy_metadata(values: dict[str, str]):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    status = DiagnosticStatus(name="camera", values=[KeyValue(key=k, value=v) for k, v in values.items()])
    return DiagnosticArray(status=[status])


def test_metadata_from_diagnostics_both_middlewares():
    msg = rclpy_metadata({"gain_db": "6.0", "exposure_time_us": "20000", "sensor_type": "CMOS",
                          "driver_version": "3.1", "sensor_temperature_c": " 41.5 "})
    for m in (msg, rosbags_roundtrip(msg, "diagnostic_msgs/msg/DiagnosticArray")):
        d = metadata_from_diagnostics(m)
        assert d == {"gain_db": 6.0, "exposure_time_s": pytest.approx(0.02), "sensor_type": "cmos",
                     "sensor_temperature_c": 41.5}


def test_metadata_non_numeric_value_is_named():
    with pytest.raises(AdapterError, match="gain_db='high'"):
        metadata_from_diagnostics(rclpy_metadata({"gain_db": "high"}))
    with pytest.raises(AdapterError, match="no status"):
        metadata_from_diagnostics(rclpy_metadata({}).__class__())


def test_resolve_metadata_priorities_and_missing_fields():
    profile = load_profile("icx285")
    meta, missing = resolve_metadata(profile, {"gain_db": 12.0}, temperature_c=None)
    assert meta is None and missing == ["exposure_time_s", "sensor_temperature_c"]
    dynamic = {"gain_db": "12", "exposure_time_s": "0.01", "full_well_e": "20000"}
    meta, missing = resolve_metadata(profile, dynamic, temperature_c=35.0)
    assert missing == [] and meta.gain_db == 12.0 and meta.full_well_e == 20000.0  # dynamic wins
    assert meta.sensor_temperature_c == 35.0 and meta.sensor_type == "ccd"
    meta2, _ = resolve_metadata(profile, {**dynamic, "sensor_temperature_c": 50.0}, temperature_c=35.0)
    assert meta2.sensor_temperature_c == 50.0  # the per-frame metadata beats the Temperature topic
    with pytest.raises(MetadataError, match="gain_db"):
        resolve_metadata(profile, {**dynamic, "gain_db": 99.0}, temperature_c=35.0)
    meta3, missing3 = resolve_metadata(None, {"gain_db": 1.0})
    assert meta3 is None and "full_well_e" in missing3 and "sensor_type" in missing3


def test_temperature_message():
    from sensor_msgs.msg import Temperature

    msg = Temperature(temperature=42.25)
    assert metadata_from_temperature(rosbags_roundtrip(msg, "sensor_msgs/msg/Temperature")) == {
        "sensor_temperature_c": 42.25}
    with pytest.raises(AdapterError, match="not finite"):
        metadata_from_temperature(Temperature(temperature=float("nan")))


def test_flir_vendor_metadata_through_registered_definition():
    ts = get_typestore(Stores.ROS2_JAZZY)
    register_vendor_types(ts)
    t = ts.types
    header = t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=1, nanosec=2), frame_id="cam")
    msg = t["flir_camera_msgs/msg/ImageMetaData"](header=header, camera_time=5, brightness=100,
                                                 exposure_time=12500, max_exposure_time=30000, gain=9.5)
    back = ts.deserialize_cdr(ts.serialize_cdr(msg, "flir_camera_msgs/msg/ImageMetaData"),
                              "flir_camera_msgs/msg/ImageMetaData")
    assert metadata_from_vendor(back) == {"exposure_time_s": pytest.approx(0.0125), "gain_db": pytest.approx(9.5)}
    with pytest.raises(AdapterError, match="no metadata adapter for sensor_msgs/msg/Temperature"):
        from sensor_msgs.msg import Temperature

        metadata_from_vendor(Temperature())


def test_driver_metadata_recorded_with_an_older_definition():
    """A bag keeps the message definition it was recorded with: an older FLIR ImageMetaData (``gain_db``, not
    ``gain``) is a clear AdapterError naming the field, an older Basler CurrentParams without temperature and
    black level converts without them (until 2026-12-04 both stopped replay and analyze with an AttributeError
    traceback)."""
    from rosbags.typesys import get_types_from_msg

    from msg_adapters.vendor import BASLER_CURRENT_PARAMS

    ts = get_typestore(Stores.ROS2_JAZZY)
    old_basler = "".join(line + "\n" for line in BASLER_CURRENT_PARAMS.splitlines()
                         if line.split()[-1] not in ("temperature", "black_level"))
    ts.register({**get_types_from_msg("std_msgs/Header header\nuint32 exposure_time\nfloat32 gain_db\n",
                                      "flir_camera_msgs/msg/ImageMetaData"),
                 **get_types_from_msg(old_basler, "pylon_ros2_camera_interfaces/msg/CurrentParams")})
    t = ts.types
    header = t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=1, nanosec=2), frame_id="cam")
    flir = t["flir_camera_msgs/msg/ImageMetaData"](header=header, exposure_time=12500, gain_db=9.5)
    with pytest.raises(AdapterError, match="has no field 'gain' .*another version.*fields: header, exposure_time, "
                                           "gain_db\\)"):
        metadata_from_vendor(flir)
    cls = t["pylon_ros2_camera_interfaces/msg/CurrentParams"]
    values = {f.name: ([] if f.name == "available_image_encoding" else "" if "str" in str(f.type) else 0)
              for f in dataclasses.fields(cls) if f.name != "__msgtype__"}
    values["roi"] = t["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    basler = cls(**{**values, "exposure": 5000.0, "gain": 0.5, "success": True})
    profile = type("Profile", (), {"gain_range_db": (0.0, 24.0), "black_level_dn": None})()
    assert metadata_from_vendor(basler, profile) == {"exposure_time_s": pytest.approx(0.005), "gain_db": 12.0}


def test_diagnostic_levels_converted_per_middleware():
    from rclpy.serialization import serialize_message

    reports = [StatusReport(3, "noise_monitor: cam", "stale", "cam-1", {"xi": "-1.25"}),
               StatusReport(1, "noise_monitor: cam", "warn", "cam-1", {})]
    msg = to_rclpy(reports, 1_500_000_000_123)
    assert msg.status[0].level == b"\x03" and msg.header.stamp.sec == 1500 and msg.header.stamp.nanosec == 123
    back = TS.deserialize_cdr(serialize_message(msg), "diagnostic_msgs/msg/DiagnosticArray")
    assert back.status[0].level == 3 and reports_from_msg(back) == reports
    rb = to_rosbags(reports, 1_500_000_000_123)
    assert rb.status[1].level == 1
    rb_back = TS.deserialize_cdr(TS.serialize_cdr(rb, "diagnostic_msgs/msg/DiagnosticArray"),
                                 "diagnostic_msgs/msg/DiagnosticArray")
    assert reports_from_msg(rb_back) == reports == reports_from_msg(msg)
    with pytest.raises(ValueError, match="strings"):
        StatusReport(0, "n", "m", "h", {"xi": 1.0})
    with pytest.raises(ValueError, match="level"):
        StatusReport(7, "n", "m", "h", {})


def test_camera_info_geometry():
    from sensor_msgs.msg import CameraInfo, RegionOfInterest

    info = CameraInfo(width=1280, height=1024, binning_x=2, binning_y=2,
                      roi=RegionOfInterest(x_offset=100, y_offset=50, width=640, height=480))
    geo = camera_geometry(rosbags_roundtrip(info, "sensor_msgs/msg/CameraInfo"))
    assert geo.image_size == (240, 320) and geo.binned_pixels == 4
    geo.check_image(240, 320)
    with pytest.raises(AdapterError, match="CameraInfo implies 320x240"):
        geo.check_image(480, 640)
    assert camera_geometry(CameraInfo(width=64, height=32)).image_size == (32, 64)
    with pytest.raises(AdapterError, match="exceeds"):
        camera_geometry(CameraInfo(width=64, height=32, roi=RegionOfInterest(x_offset=60, width=10, height=5)))
