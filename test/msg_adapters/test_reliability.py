"""Bad-input matrix of msg_adapters: every malformed image, metadata, CameraInfo or vendor message gives a
clear AdapterError / MetadataError naming the problem, never an uncaught exception or a wrong image.

Messages are real rclpy messages and their rosbags-deserialised twins (what a bag reader sees).
"""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from msg_adapters import (
    AdapterError,
    camera_geometry,
    image_to_gray_dn,
    metadata_from_diagnostics,
    metadata_from_temperature,
    metadata_from_vendor,
    resolve_metadata,
)
from msg_adapters.metadata import ALIASES
from noise_monitor.physics import MetadataError, load_profile

TS = get_typestore(Stores.ROS2_JAZZY)
PROFILE = load_profile("icx285")
DYNAMIC = {"gain_db": "6.0", "exposure_time_s": "0.01", "sensor_temperature_c": "40.0"}


def image(pixels: np.ndarray, encoding: str, bigendian: bool = False, override: dict | None = None, **fields):
    """An rclpy sensor_msgs/Image of ``pixels`` (uint8/uint16, (H, W) or (H, W, C)); then the fields in
    ``override`` and ``fields`` are set as given (bad headers)."""
    from sensor_msgs.msg import Image

    h, w = pixels.shape[:2]
    dtype = pixels.dtype.newbyteorder(">" if bigendian else "<")
    data = np.ascontiguousarray(pixels.astype(dtype)).reshape(h, -1).view(np.uint8)
    msg = Image(height=h, width=w, encoding=encoding, is_bigendian=int(bigendian), step=data.shape[1],
                data=data.tobytes())
    for key, value in {**(override or {}), **fields}.items():
        setattr(msg, key, value)
    return msg


def both(msg, msgtype: str) -> tuple:
    """The rclpy message and its rosbags twin (CDR round trip)."""
    from rclpy.serialization import serialize_message

    return msg, TS.deserialize_cdr(serialize_message(msg), msgtype)


def diagnostics(values: dict[str, str]):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    return DiagnosticArray(status=[DiagnosticStatus(name="camera", values=[
        KeyValue(key=k, value=v) for k, v in values.items()])])


# --- images --------------------------------------------------------------------------------------
PIXELS = np.arange(12 * 10, dtype=np.uint8).reshape(12, 10)


@pytest.mark.parametrize("case,override,match", [
    ("data shorter than height x step", {"data": PIXELS.tobytes()[:-11]}, "image data has 109 bytes, expected 120"),
    ("data longer than height x step", {"data": PIXELS.tobytes() + bytes(10)}, "image data has 130 bytes, expected 120"),
    ("header height larger than the data", {"height": 13}, "image data has 120 bytes, expected 130"),
    ("header width doubled, data unchanged", {"width": 5, "step": 5}, "image data has 120 bytes, expected 60"),
    ("step < width x bytes per pixel", {"step": 9}, "step 9 is smaller than width\\*channels\\*bytes = 10"),
    ("unknown encoding", {"encoding": "nv21"}, "unsupported image encoding 'nv21'; supported: mono8"),
    ("float encoding", {"encoding": "32FC1"}, "unsupported image encoding '32fc1'"),
    ("no encoding", {"encoding": ""}, "unsupported image encoding ''"),
    ("0x0 image", {"height": 0, "width": 0, "step": 0, "data": b""}, "empty image \\(0x0\\)"),
    ("zero width", {"width": 0}, "empty image \\(0x12\\)"),
])
def test_malformed_images_are_rejected_with_the_reason(case, override, match):
    for msg in both(image(PIXELS, "mono8", override=override), "sensor_msgs/msg/Image"):
        with pytest.raises(AdapterError, match=match):
            image_to_gray_dn(msg)


@pytest.mark.parametrize("encoding,channels,itemsize", [("mono16", 1, 2), ("rgb8", 3, 1), ("bgra16", 4, 2)])
def test_step_smaller_than_a_row_of_multi_byte_pixels(encoding, channels, itemsize):
    px = np.zeros((4, 6, channels) if channels > 1 else (4, 6), np.uint16 if itemsize == 2 else np.uint8)
    row = 6 * channels * itemsize
    with pytest.raises(AdapterError, match=f"step {row - 1} is smaller than width\\*channels\\*bytes = {row}"):
        image_to_gray_dn(image(px, encoding, step=row - 1, data=bytes(4 * (row - 1))))


def test_missing_padding_of_the_last_row_only_is_accepted_exactly():
    padded = np.concatenate([PIXELS, np.full((12, 3), 99, np.uint8)], axis=1)
    msg = image(padded, "mono8", width=10)  # step 13 > width 10
    full = image_to_gray_dn(msg)
    msg.data = padded.tobytes()[:-3]  # a driver that omits the padding after the last row
    np.testing.assert_array_equal(image_to_gray_dn(msg), full)
    np.testing.assert_array_equal(full, PIXELS.astype(np.float32))


def test_one_by_one_images_convert_and_one_by_one_bayer_is_rejected():
    for msg in both(image(np.array([[200]], np.uint8), "mono8"), "sensor_msgs/msg/Image"):
        out = image_to_gray_dn(msg)
        assert out.shape == (1, 1) and out[0, 0] == 200.0
    with pytest.raises(AdapterError, match="Bayer image needs at least 2x2"):
        image_to_gray_dn(image(np.array([[200]], np.uint8), "bayer_rggb8"))


@pytest.mark.parametrize("bit_depth", [None, 12])
def test_big_endian_mono16_equals_little_endian(rng, bit_depth):
    top = 4095 if bit_depth else 65535
    px = rng.integers(0, top + 1, (6, 5)).astype(np.uint16)
    px[0, 0], px[0, 1] = top, 0x0102  # a value whose byte order matters
    little = image_to_gray_dn(image(px, "mono16"), bit_depth=bit_depth)
    np.testing.assert_allclose(little, px * (255.0 / top), rtol=1e-6)
    for msg in both(image(px, "mono16", bigendian=True), "sensor_msgs/msg/Image"):
        np.testing.assert_array_equal(image_to_gray_dn(msg, bit_depth=bit_depth), little)


def test_big_endian_flag_is_honoured_not_guessed():
    px = np.full((2, 2), 0x0010, np.uint16)  # 16 as big-endian bytes 00 10; read little-endian it is 4096
    msg = image(px, "mono16", bigendian=True)
    assert float(image_to_gray_dn(msg, bit_depth=12)[0, 0]) == pytest.approx(16 * 255 / 4095)
    msg.is_bigendian = 0  # the publisher lies about the byte order: values beyond 12 bits, named
    with pytest.raises(AdapterError, match="pixel value 4096 exceeds the 12-bit range"):
        image_to_gray_dn(msg, bit_depth=12)


@pytest.mark.parametrize("bit_depth,match", [(0, "bit_depth must be in \\[1, 16\\]"), (-4, "bit_depth must be in")])
def test_bad_bit_depth_parameter(bit_depth, match):
    with pytest.raises(AdapterError, match=match):
        image_to_gray_dn(image(np.zeros((2, 2), np.uint16), "mono16"), bit_depth=bit_depth)


def test_not_an_image_message():
    from sensor_msgs.msg import CameraInfo

    with pytest.raises(AdapterError, match="not an image message: no field 'encoding'"):
        image_to_gray_dn(CameraInfo())


# --- metadata ------------------------------------------------------------------------------------
@pytest.mark.parametrize("key,value,error,match", [
    ("gain_db", "nan", AdapterError, "gain_db='nan' is not finite"),
    ("exposure_time_s", "inf", AdapterError, "exposure_time_s='inf' is not finite"),
    ("sensor_temperature_c", "-inf", AdapterError, "sensor_temperature_c='-inf' is not finite"),
    ("exposure_time_us", "NaN", AdapterError, "exposure_time_us='NaN' is not finite"),
    ("gain_db", "high", AdapterError, "gain_db='high' is not a number"),
    ("bit_depth", "12.5", AdapterError, "bit_depth='12.5' is not an integer"),
    ("exposure_time_s", "-0.01", MetadataError, "exposure_time_s = -0.01 s is outside the allowed range"),
    ("gain_db", "99", MetadataError, "gain_db = 99 dB is outside the allowed range \\[0, 48\\]"),
    ("sensor_temperature_c", "-300", MetadataError, "sensor_temperature_c = -300 degC is outside"),
    ("sensor_temperature_k", "-5", MetadataError, "sensor_temperature_c = -278.15 degC is outside"),
    ("full_well_e", "0", MetadataError, "full_well_e = 0 e- is outside"),
    ("sensor_type", "cmos-ish", MetadataError, "sensor_type must be one of"),
    ("bit_depth", "20", MetadataError, "bit_depth must be an integer in \\[1, 16\\]"),
])
def test_bad_metadata_values_are_named(key, value, error, match):
    """NaN/inf/negative/out-of-range values: from the message (AdapterError) or at validation
    (MetadataError), both ValueErrors naming the field and the value."""
    values = {k: v for k, v in DYNAMIC.items() if k != ALIASES.get(key, ("",))[0]}  # the alias is the only source
    for msg in both(diagnostics({**values, key: value}), "diagnostic_msgs/msg/DiagnosticArray"):
        with pytest.raises(error, match=match):
            resolve_metadata(PROFILE, metadata_from_diagnostics(msg))


def test_missing_metadata_names_every_absent_field():
    meta, missing = resolve_metadata(PROFILE, metadata_from_diagnostics(diagnostics({"gain_db": "3", "exposure_time_s": ""})))
    assert meta is None and missing == ["exposure_time_s", "sensor_temperature_c"]
    meta, missing = resolve_metadata(None, {})
    assert meta is None and missing[:3] == ["gain_db", "exposure_time_s", "sensor_temperature_c"]
    assert "sensor_type" in missing and len(missing) == 11


def test_metadata_message_without_status_or_of_the_wrong_type():
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import Temperature

    with pytest.raises(AdapterError, match="metadata DiagnosticArray has no status"):
        metadata_from_diagnostics(DiagnosticArray())
    with pytest.raises(AdapterError, match="not a DiagnosticArray/DiagnosticStatus"):
        metadata_from_diagnostics(Temperature())


@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_temperature_message_not_finite(value):
    from sensor_msgs.msg import Temperature

    for msg in both(Temperature(temperature=value), "sensor_msgs/msg/Temperature"):
        with pytest.raises(AdapterError, match="temperature=.* is not finite"):
            metadata_from_temperature(msg)
    with pytest.raises(AdapterError, match="not a sensor_msgs/Temperature"):
        metadata_from_temperature(diagnostics({}))


def test_temperature_below_absolute_zero_is_rejected_at_validation():
    with pytest.raises(MetadataError, match="sensor_temperature_c = -300"):
        resolve_metadata(PROFILE, {"gain_db": 0.0, "exposure_time_s": 0.01}, temperature_c=-300.0)


def test_unknown_vendor_message_type_names_the_supported_ones():
    from sensor_msgs.msg import CameraInfo

    rosbags_info = TS.types["sensor_msgs/msg/CameraInfo"]
    for msg in (CameraInfo(), both(CameraInfo(), "sensor_msgs/msg/CameraInfo")[1]):
        with pytest.raises(AdapterError, match="no metadata adapter for sensor_msgs/msg/CameraInfo; supported "
                                               "vendor types: camera_aravis2_msgs/msg/CameraDiagnostics, "
                                               "flir_camera_msgs/msg/ImageMetaData"):
            metadata_from_vendor(msg)
    assert rosbags_info.__msgtype__ == "sensor_msgs/msg/CameraInfo"


# --- CameraInfo ----------------------------------------------------------------------------------
def test_camera_info_disagreeing_with_the_image_size():
    from sensor_msgs.msg import CameraInfo, RegionOfInterest

    for info in both(CameraInfo(width=640, height=480), "sensor_msgs/msg/CameraInfo"):
        geo = camera_geometry(info)
        geo.check_image(480, 640)
        with pytest.raises(AdapterError, match="image is 320x240 but CameraInfo implies 640x480"):
            geo.check_image(240, 320)
    binned = camera_geometry(CameraInfo(width=640, height=480, binning_x=2, binning_y=2))
    with pytest.raises(AdapterError, match="image is 640x480 but CameraInfo implies 320x240.*binning 2x2"):
        binned.check_image(480, 640)
    with pytest.raises(AdapterError, match="CameraInfo has no size \\(0x0\\)"):
        camera_geometry(CameraInfo())
    with pytest.raises(AdapterError, match="ROI \\(600, 0, 100, 10\\) exceeds the sensor size 640x480"):
        camera_geometry(CameraInfo(width=640, height=480, roi=RegionOfInterest(x_offset=600, width=100, height=10)))
    with pytest.raises(AdapterError, match="not a CameraInfo message"):
        camera_geometry(diagnostics({}))


# --- huge images ---------------------------------------------------------------------------------
HUGE = r'''
import json, re, sys
from types import SimpleNamespace
import numpy as np, torch
torch.set_num_threads(1)
from msg_adapters import image_to_gray_dn
from noise_monitor.estimator import load
from noise_monitor.monitor import Frame, Monitor, MonitorConfig
from noise_monitor.physics import NoiseModel, load_profile

def mem_mb(key):
    return int(re.search(rf"{key}:\s+(\d+) kB", open("/proc/self/status").read()).group(1)) / 1024

def image(h, w, rng):
    data = np.empty((h, w), np.uint8)
    ramp = (60 + 120 * np.arange(w) / w).astype(np.uint8)
    for r in range(0, h, 256):
        data[r:r + 256] = ramp + rng.integers(0, 3, size=(min(256, h - r), w), dtype=np.uint8)
    return SimpleNamespace(height=h, width=w, step=w, encoding="mono8", is_bigendian=0, data=data.reshape(-1))

meta = load_profile("icx285").metadata(gain_db=18.0, exposure_time_s=0.01, sensor_temperature_c=40.0)
monitor = Monitor(MonitorConfig(), load("full_meta", device="cpu"), NoiseModel(), "cam", "hw")
rng = np.random.default_rng(0)
monitor.process(Frame(0, image_to_gray_dn(image(256, 256, rng)), meta))  # warm-up: tables, network
msg = image(int(sys.argv[1]), int(sys.argv[1]), rng)
before = mem_mb("VmRSS")
res = monitor.process(Frame(1, image_to_gray_dn(msg), meta))
print(json.dumps({"extra_mb": mem_mb("VmHWM") - before, "processed": res.processed, "level": res.level,
                  "numbers": res.numeric()}))
'''


def test_huge_8k_image_is_evaluated_within_bounded_memory():
    """An 8192 x 8192 mono8 frame (64 MB) through conversion and the monitor pipeline, in a fresh process:
    evaluated with finite numbers; peak memory beyond the input stays below 24 bytes per pixel."""
    size = 8192
    run = subprocess.run([sys.executable, "-c", HUGE, str(size)], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    out = json.loads(run.stdout.strip().splitlines()[-1])
    assert out["processed"] and out["numbers"]["patches"] == 8.0
    assert all(np.isfinite(v) for v in out["numbers"].values())
    assert out["extra_mb"] < 24 * size * size / 2**20, out["extra_mb"]
