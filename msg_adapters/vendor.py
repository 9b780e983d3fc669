"""Camera drivers' per-frame metadata messages -> CameraMetadata fields in SI units.

``VENDOR_TYPES`` holds the drivers' message definitions (copied read-only from the drivers' .msg files) so
that rosbags can deserialise bags recorded with these drivers without their packages installed
(:func:`register_vendor_types`); :func:`metadata_from_vendor` converts such a message (rclpy or rosbags).

- FLIR ``spinnaker_camera_driver`` (ros-drivers/flir_camera_driver): ``flir_camera_msgs/msg/ImageMetaData``,
  exposure_time in microseconds, gain in dB.
- Basler ``pylon_ros2_camera`` (basler/pylon-ros-camera): ``pylon_ros2_camera_interfaces/msg/CurrentParams``,
  no header (stamped by arrival / bag log time), exposure in microseconds, gain normalised 0..1 over the
  camera's gain range (mapped to dB through the profile's ``gain_range_db``), temperature in degC
  (0.0 = not available); -10000/-20000 mean "not available"/"error". ``black_level`` is the camera's
  BlackLevelRaw (ace GigE) or BlackLevel truncated to an integer (USB, ace 2), in units that depend on the model
  and pixel format: converted by the profile's ``driver_black_level_dn`` (8-bit DN per unit); without it, or at -10000 (the
  camera has none), the profile's black level applies.
- Intel RealSense (IntelRealSense/realsense-ros): ``realsense2_camera_msgs/msg/Metadata``, a JSON object
  with librealsense's frame metadata: ``actual_exposure`` in microseconds on the depth and infrared streams, in
  100 us on the colour stream (the RGB sensor's control granularity, librealsense#8243), ``gain_level`` in the sensor's
  relative gain units (mapped to dB through the profile's ``gain_range_db`` over ``driver_gain_range``). The colour
  stream (header ``frame_id`` ``<camera>_color_optical_frame``, or its colour controls among the keys) does not
  update ``actual_exposure`` while its auto-exposure runs (librealsense#2549): such metadata is refused.
- Orbbec (orbbec/OrbbecSDK_ROS2, Gemini 330 series): ``orbbec_camera_msgs/msg/Metadata`` on ``<stream>/metadata``, the
  SDK's frame metadata as JSON with the image's header. Its units differ by sensor (``exposure`` "usually 100 us for
  the color sensor and 1 us for depth/infrared", ``gain`` a level on some models), so it is read through the node's
  ``metadata_keymap`` (:func:`msg_adapters.keymap.metadata_from_json_keymap`), not converted here.
- GenICam cameras (GigE Vision, USB3 Vision) through ``camera_aravis2`` (FraunhoferIOSB/camera_aravis2 >= 1.0):
  ``camera_aravis2_msgs/msg/CameraDiagnostics`` on ``~/diagnostics``, the features its ``diagnostic_yaml_url`` lists
  as key/values named by the GenICam SFNC (``Feature`` or ``Feature-SelectorValue``), published at
  ``diagnostic_publishing_rate`` and stamped when published, not per frame (held until the next one): ``ExposureTime``
  (or ``ExposureTimeAbs``) in us; the gain in dB from ``Gain`` / ``Gain-All``, else ``Gain-AnalogAll`` plus
  ``Gain-DigitalAll``, else ``GainAbs``, else ``GainRaw`` in the camera's raw units (through ``gain_range_db`` over
  ``driver_gain_range``); ``DeviceTemperature-Sensor`` (or ``DeviceTemperature`` without a selector) in degC, another
  selector's temperature (the mainboard's) is not the sensor's and is left out; ``BlackLevel`` (``-All``) through
  ``driver_black_level_dn``, as Basler's.

A field a driver does not report comes from the camera profile; a reported field that is missing,
non-numeric or out of range raises :class:`AdapterError` naming the field and value.
"""
from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from typing import Any

from noise_monitor.text import clip

from .errors import AdapterError
from .metadata import BLACK_LEVEL, black_level_value

FLIR_IMAGE_METADATA = """\
std_msgs/Header header
uint64 camera_time
int16 brightness
uint32 exposure_time
uint32 max_exposure_time
float32 gain
"""

BASLER_CURRENT_PARAMS = """\
uint32 offset_x
uint32 offset_y
bool reverse_x
bool reverse_y
int32 black_level
int32 pgi_mode
int32 demosaicing_mode
float32 noise_reduction
float32 sharpness_enhancement
int32 light_source_preset
int32 balance_white_auto
int32 sensor_readout_mode
int32 acquisition_frame_count
int32 trigger_selector
int32 trigger_mode
int32 trigger_source
int32 trigger_activation
float32 trigger_delay
int32 user_set_selector
int32 user_set_default_selector
bool is_sleeping
float32 brightness
float32 exposure
float32 gain
float32 gamma
uint32 binning_x
uint32 binning_y
float32 temperature
int32 max_num_buffer
sensor_msgs/RegionOfInterest roi
string[] available_image_encoding
string current_image_encoding
string current_image_ros_encoding
string ptp_status
string ptp_servo_status
int64 ptp_offset
float32 depth_min
float32 depth_max
int32 operating_mode
int32 hdr_mode
int32 fast_mode
int32 spatial_filter
int32 temporal_filter
int32 outlier_removal
int32 ambiguity_filter
float32 confidence_threshold
int32 projector_enable
int32 projector_level
int32 depth_preset
int32 illumination_mode
int32 depth_quality
int32 static_scene
bool success
string message
"""

REALSENSE_METADATA = """\
std_msgs/Header header
string json_data
"""

ARAVIS_CAMERA_DIAGNOSTICS = """\
std_msgs/Header header
diagnostic_msgs/KeyValue[] data
"""

FLIR = "flir_camera_msgs/msg/ImageMetaData"
BASLER = "pylon_ros2_camera_interfaces/msg/CurrentParams"
REALSENSE = "realsense2_camera_msgs/msg/Metadata"
ARAVIS = "camera_aravis2_msgs/msg/CameraDiagnostics"
ORBBEC = "orbbec_camera_msgs/msg/Metadata"
VENDOR_TYPES: dict[str, str] = {FLIR: FLIR_IMAGE_METADATA, BASLER: BASLER_CURRENT_PARAMS, REALSENSE: REALSENSE_METADATA,
                                ARAVIS: ARAVIS_CAMERA_DIAGNOSTICS, ORBBEC: REALSENSE_METADATA}
#: metadata_source name -> message type (the ROS package must be importable for a live subscription)
SOURCE_TYPES: dict[str, str] = {"flir": FLIR, "basler": BASLER, "realsense": REALSENSE, "aravis": ARAVIS, "orbbec": ORBBEC}
#: driver messages read through the node's ``metadata_keymap`` (JSON keys) rather than converted here
KEYMAP_TYPES = frozenset((ORBBEC,))
#: sources whose values are held until the next message instead of paired with images by stamp: Basler's
#: CurrentParams has no header, camera_aravis2 publishes at its own rate, stamped when it publishes
HELD_SOURCES = frozenset(("basler", "aravis"))
HELD_TYPES = frozenset(SOURCE_TYPES[s] for s in HELD_SOURCES)
_BASLER_UNAVAILABLE = (-10000.0, -20000.0)


def _num(field: str, value: Any, unit: str) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise AdapterError(f"driver metadata {field} = {clip(repr(value), 80)} is not a number ({unit})") from None
    if not math.isfinite(out):
        raise AdapterError(f"driver metadata {field} = {clip(repr(value), 80)} is not finite ({unit})")
    return out


def _exposure_us(field: str, value: Any) -> float:
    us = _num(field, value, "us")
    if us <= 0:
        raise AdapterError(f"driver metadata {field} = {us:g} us is not a valid exposure time (must be > 0)")
    return us * 1e-6


def map_gain(field: str, value: Any, gain_range_db: Sequence[float] | None,
             driver_range: Sequence[float] = (0.0, 1.0)) -> float:
    """A driver's relative gain (``driver_range``, default normalised 0..1) -> dB over the profile's gain range."""
    x = _num(field, value, f"relative gain {driver_range[0]:g}..{driver_range[1]:g}")
    if gain_range_db is None:
        raise AdapterError(f"driver metadata {field} = {x:g} is a relative gain: the camera profile needs "
                           "gain_range_db: [min_db, max_db] to convert it to dB")
    lo, hi = driver_range
    slack = 1e-6 * (hi - lo)  # a range end that float32 / JSON rounding put a hair outside is the end
    if not lo - slack <= x <= hi + slack:
        raise AdapterError(f"driver metadata {field} = {x:g} is outside the driver's gain range [{lo:g}, {hi:g}]")
    x = min(max(x, lo), hi)
    return gain_range_db[0] + (x - lo) / (hi - lo) * (gain_range_db[1] - gain_range_db[0])


def _flir(msg: Any, profile: Any) -> dict[str, float | str]:
    return {"exposure_time_s": _exposure_us("exposure_time", msg.exposure_time),
            "gain_db": _num("gain", msg.gain, "dB")}


def _basler(msg: Any, profile: Any) -> dict[str, float | str]:
    if not bool(getattr(msg, "success", True)):
        raise AdapterError(f"driver metadata success = false ({str(getattr(msg, 'message', '')) or 'no message'})")
    out: dict[str, float | str] = {}
    for field in ("exposure", "gain", "temperature"):
        value = _num(field, getattr(msg, field, 0.0), "driver units")
        if value in _BASLER_UNAVAILABLE:
            raise AdapterError(f"driver metadata {field} = {value:g} ("
                               f"{'not available' if value == -10000.0 else 'error'} in the driver)")
    out["exposure_time_s"] = _exposure_us("exposure", msg.exposure)
    out["gain_db"] = map_gain("gain", msg.gain, _gain_range(profile))
    temperature = getattr(msg, "temperature", 0.0)  # absent from older definitions of the message
    if float(temperature) != 0.0:  # 0.0: the camera does not report it
        out["sensor_temperature_c"] = _num("temperature", temperature, "degC")
    if not hasattr(msg, "black_level"):  # pylon_ros2_camera before its black level was reported
        return out
    value = _num("black_level", msg.black_level, "driver units")
    black = None if value in _BASLER_UNAVAILABLE else _driver_black_level("black_level", value, profile)
    if black is not None:
        out[BLACK_LEVEL] = black
    return out


def _driver_black_level(field: str, value: float, profile: Any) -> float | None:
    """A driver's black level (camera units) on the 8-bit DN scale; None where the profile's applies."""
    per_unit = getattr(profile, "driver_black_level_dn", None)
    if per_unit is None:  # not convertible: the profile's black level applies (zero is zero in any unit)
        stated: float = getattr(profile, "black_level_dn", None) or 0.0
        if value == 0.0 or stated:
            return None
        raise AdapterError(f"driver metadata {field} = {value:g} is in the camera's units: the camera profile "
                           "needs driver_black_level_dn (8-bit DN per unit; ace GigE BlackLevelRaw at Mono8: 0.0625 "
                           "on most models) or black_level_dn")
    return black_level_value(field, value * per_unit)


def json_metadata(msg: Any) -> dict[str, Any]:
    """The JSON object of a driver's frame metadata message (``json_data``: RealSense's, Orbbec's)."""
    try:
        data = json.loads(str(msg.json_data))
    except json.JSONDecodeError as exc:
        raise AdapterError(f"driver metadata json_data is not JSON: {exc}") from None
    if not isinstance(data, dict):
        raise AdapterError("driver metadata json_data is not a JSON object")
    return data


#: Frame metadata only the RealSense RGB sensor reports (librealsense's names as realsense-ros writes them).
_REALSENSE_COLOUR_KEYS = frozenset({"white_balance", "manual_white_balance", "auto_white_balance_temperature", "hue",
                                    "saturation", "gamma", "power_line_frequency", "low_light_compensation"})


def _realsense(msg: Any, profile: Any) -> dict[str, float | str]:
    data = json_metadata(msg)
    header = getattr(msg, "header", None)
    colour = "_color_" in str(getattr(header, "frame_id", "")) or bool(_REALSENSE_COLOUR_KEYS & set(data))
    out: dict[str, float | str] = {}
    if colour and "actual_exposure" in data and _num("auto_exposure", data.get("auto_exposure", 0), "flag"):
        raise AdapterError("driver metadata actual_exposure of a RealSense colour stream under auto-exposure "
                           "(auto_exposure = 1) is the manual setting, not the frame's (librealsense#2549): turn the "
                           "colour stream's auto-exposure off (rgb_camera.enable_auto_exposure: false)")
    if "actual_exposure" in data:  # the RGB sensor counts in 100 us, depth and infrared in us
        out["exposure_time_s"] = _exposure_us("actual_exposure", data["actual_exposure"]) * (100.0 if colour else 1.0)
    if "gain_level" in data:
        out["gain_db"] = map_gain("gain_level", data["gain_level"], _gain_range(profile), _driver_range(profile))
    if not out:
        raise AdapterError("driver metadata json_data has neither actual_exposure nor gain_level "
                           f"(keys: {', '.join(sorted(data)) or 'none'})")
    return out


def _aravis(msg: Any, profile: Any) -> dict[str, float | str]:
    values = {str(kv.key).strip(): kv.value for kv in getattr(msg, "data", None) or ()}

    def first(*keys: str) -> str | None:
        return next((k for k in keys if k in values), None)

    out: dict[str, float | str] = {}
    exposure = first("ExposureTime", "ExposureTimeAbs")
    if exposure:
        out["exposure_time_s"] = _exposure_us(exposure, values[exposure])
    overall, absolute, raw = first("Gain", "Gain-All"), first("GainAbs", "GainAbs-All"), first("GainRaw", "GainRaw-All")
    parts = [k for k in ("Gain-AnalogAll", "Gain-DigitalAll") if k in values]
    if overall:
        out["gain_db"] = _num(overall, values[overall], "dB")
    elif parts:  # analog and digital gains in dB: the image's gain is their sum
        out["gain_db"] = sum(_num(k, values[k], "dB") for k in parts)
    elif absolute:
        out["gain_db"] = _num(absolute, values[absolute], "dB")
    elif raw:
        out["gain_db"] = map_gain(raw, values[raw], _gain_range(profile), _driver_range(profile))
    elif any(k.startswith("Gain") for k in values):
        raise AdapterError("driver metadata has no overall gain, only "
                           f"{clip(', '.join(sorted(k for k in values if k.startswith('Gain'))))}: list Gain with the "
                           "selector All (or AnalogAll and DigitalAll) in camera_aravis2's diagnostic_yaml_url")
    temperature = first("DeviceTemperature-Sensor", "DeviceTemperature")
    if temperature:
        out["sensor_temperature_c"] = _num(temperature, values[temperature], "degC")
    black = first("BlackLevel", "BlackLevel-All")
    if black:
        level = _driver_black_level(black, _num(black, values[black], "camera units"), profile)
        if level is not None:
            out[BLACK_LEVEL] = level
    if "exposure_time_s" not in out and "gain_db" not in out:
        raise AdapterError("driver metadata has neither ExposureTime nor Gain (keys: "
                           f"{clip(', '.join(sorted(values))) or 'none'}): list them in camera_aravis2's diagnostic_yaml_url")
    return out


def _gain_range(profile: Any) -> Sequence[float] | None:
    return getattr(profile, "gain_range_db", None)


def _driver_range(profile: Any) -> Sequence[float]:
    return getattr(profile, "driver_gain_range", None) or (0.0, 1.0)


_CONVERTERS: dict[str, Callable[[Any, Any], dict[str, float | str]]] = {FLIR: _flir, BASLER: _basler, REALSENSE: _realsense,
                                                                        ARAVIS: _aravis}


def message_type_name(msg: Any) -> str:
    """'pkg/msg/Name' of a rosbags (``__msgtype__``) or rclpy (module path) message."""
    name = getattr(msg, "__msgtype__", None)
    if name:
        return str(name)
    cls = type(msg)
    return f"{cls.__module__.split('.')[0]}/msg/{cls.__name__}"


def metadata_from_vendor(msg: Any, profile: Any = None) -> dict[str, float | str]:
    """CameraMetadata fields from a supported driver metadata message (``profile``: a CameraProfile, for
    drivers that report a relative gain)."""
    name = message_type_name(msg)
    try:
        convert = _CONVERTERS[name]
    except KeyError:
        raise AdapterError(
            f"no metadata adapter for {name}; supported vendor types: {', '.join(sorted(_CONVERTERS))}"
        ) from None
    try:
        return convert(msg, profile)
    except AttributeError as exc:  # a bag keeps the definition it was recorded with: an older driver's
        fields = ", ".join(name for name in (getattr(msg, "__dataclass_fields__", None)  # rosbags; rclpy below
                                             or getattr(msg, "get_fields_and_field_types", dict)())
                           if not name.startswith("_"))
        raise AdapterError(f"driver metadata {name} has no field '{exc.name}' (recorded with another version of "
                           f"the message; its fields: {fields or 'unknown'})") from None


def message_class(source: str) -> Any:
    """The rclpy message class of a driver ``metadata_source``; AdapterError naming the ROS package to
    install when it is not importable."""
    import importlib

    pkg, _, cls = SOURCE_TYPES[source].split("/")
    try:
        return getattr(importlib.import_module(f"{pkg}.msg"), cls)
    except (ImportError, AttributeError) as exc:
        raise AdapterError(f"metadata_source {source} subscribes to {SOURCE_TYPES[source]}: install the ROS "
                           f"package {pkg} (not importable: {exc})") from None


def register_vendor_types(typestore: Any) -> None:
    """Add the vendor message definitions to a rosbags typestore (skips types it already knows)."""
    from rosbags.typesys import get_types_from_msg

    types: dict = {}
    for name, text in VENDOR_TYPES.items():
        if name not in typestore.types:
            types.update(get_types_from_msg(text, name))
    if types:
        typestore.register(types)
