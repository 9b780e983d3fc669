"""camera_ros (christianrauch/camera_ros >= 0.7, the libcamera ROS 2 node: Raspberry Pi and other libcamera cameras)
-> CameraMetadata fields.

camera_ros publishes every frame's libcamera metadata on ``/diagnostics``: a DiagnosticArray with the image's header
(the same stamp) and one status whose ``hardware_id`` is the camera's libcamera id and whose key/values are libcamera's
control names and values as libcamera prints them. Read here: ``ExposureTime`` (us), ``AnalogueGain`` and
``DigitalGain`` (factors: the gain of a processed image is their product, the digital gain being applied in the ISP
that produces it; a raw Bayer stream is the sensor's output, whose gain is the analogue gain alone, kept as
:data:`RAW_GAIN` for :func:`msg_adapters.frames.prepare_frame`) and ``SensorTemperature`` (degC, where the sensor
reports one). ``SensorBlackLevels`` (R, Gr, Gb, B on a 16-bit scale, as libcamera prints an array: ``[ 4096, 4096,
4096, 4096 ]``) is the pedestal the raw Bayer output keeps, which the ISP takes off before its processed output: kept
as :data:`RAW_BLACK_LEVEL` (the green sites' mean on the 8-bit scale, the sites the monitor reads of a Bayer image) for
:func:`msg_adapters.frames.prepare_frame`. ``/diagnostics`` carries every node's
diagnostics, the monitor's own among them: an array without a libcamera status (or only other cameras', when a
``hardware_id`` is asked for) is not this camera's (None).
"""
from __future__ import annotations

import math
from typing import Any

from noise_monitor.text import clip

from .errors import AdapterError

EXPOSURE, ANALOGUE_GAIN, DIGITAL_GAIN, TEMPERATURE = "ExposureTime", "AnalogueGain", "DigitalGain", "SensorTemperature"
BLACK_LEVELS = "SensorBlackLevels"
#: keys only a libcamera metadata status has (camera_ros prints every control of the request's metadata)
LIBCAMERA_KEYS = frozenset((EXPOSURE, ANALOGUE_GAIN))
#: the gain (dB) of the sensor's raw output, without the ISP's digital gain: a raw Bayer image's
RAW_GAIN = "raw_gain_db"
#: the black level (8-bit DN) of the sensor's raw output, which the ISP's processed output no longer has
RAW_BLACK_LEVEL = "raw_black_level_dn"


def is_libcamera(status: Any) -> bool:
    """A DiagnosticStatus (rclpy or rosbags) that carries libcamera metadata."""
    return any(str(kv.key) in LIBCAMERA_KEYS for kv in getattr(status, "values", None) or ())


def libcamera_status(msg: Any, hardware_id: str = "") -> Any | None:
    """The first status of a DiagnosticArray that carries libcamera metadata, of the camera ``hardware_id`` when
    given; None when there is none."""
    for status in getattr(msg, "status", None) or ():
        if is_libcamera(status) and (not hardware_id or str(status.hardware_id).strip() == hardware_id):
            return status
    return None


def _number(key: str, value: Any, positive: bool = True) -> float:
    try:
        x = float(str(value).strip())
    except ValueError:
        raise AdapterError(f"camera_ros metadata {key} = {clip(repr(value), 80)} is not a number") from None
    if not math.isfinite(x) or (positive and x <= 0):
        raise AdapterError(f"camera_ros metadata {key} = {clip(repr(value), 80)} is not "
                           f"{'a positive number' if positive else 'finite'}")
    return x


def metadata_from_camera_ros(msg: Any, hardware_id: str = "") -> dict[str, float] | None:
    """CameraMetadata fields from camera_ros's DiagnosticArray, None when it is not this camera's (module docstring);
    a value that is not a number (a positive one for the exposure and the gains) is an AdapterError naming it."""
    status = libcamera_status(msg, hardware_id)
    if status is None:
        return None
    values = {str(kv.key): kv.value for kv in status.values}
    out: dict[str, float] = {}
    if EXPOSURE in values:
        out["exposure_time_s"] = _number(EXPOSURE, values[EXPOSURE]) * 1e-6
    if ANALOGUE_GAIN in values:
        analogue = _number(ANALOGUE_GAIN, values[ANALOGUE_GAIN])
        digital = _number(DIGITAL_GAIN, values[DIGITAL_GAIN]) if DIGITAL_GAIN in values else 1.0
        out["gain_db"] = 20.0 * math.log10(analogue * digital)
        out[RAW_GAIN] = 20.0 * math.log10(analogue)
    if TEMPERATURE in values:
        out["sensor_temperature_c"] = _number(TEMPERATURE, values[TEMPERATURE], positive=False)
    if BLACK_LEVELS in values:
        out[RAW_BLACK_LEVEL] = _green_black_level(values[BLACK_LEVELS])
    return out


def _green_black_level(value: Any) -> float:
    """libcamera's SensorBlackLevels text (R, Gr, Gb, B on a 16-bit scale) -> the green sites' mean, 8-bit DN."""
    items = str(value).strip().removeprefix("[").removesuffix("]").split(",")
    try:
        levels = [float(x) for x in items]
    except ValueError:
        levels = []
    if len(levels) != 4 or not all(math.isfinite(x) and 0 <= x < 65536 for x in levels):
        raise AdapterError(f"camera_ros metadata {BLACK_LEVELS} = {clip(repr(value), 80)} is not four levels "
                           "(R, Gr, Gb, B) on the 16-bit scale")
    return (levels[1] + levels[2]) / 2 * 255.0 / 65535.0
