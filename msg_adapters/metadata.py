"""Camera metadata from ROS messages and profiles -> CameraMetadata.

Sources, lowest priority first: the static camera profile (YAML), a sensor_msgs/Temperature reading,
and the per-frame metadata message (diagnostic_msgs/DiagnosticArray whose first status carries
key/values named like the CameraMetadata fields, or a vendor message, see :mod:`msg_adapters.vendor`).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from noise_monitor.physics import CameraMetadata, CameraProfile, MetadataError
from noise_monitor.physics.metadata import BLACK_LEVEL_MAX_DN, NUMERIC_FIELDS
from noise_monitor.text import clip

from .errors import AdapterError

REQUIRED_FIELDS: tuple[str, ...] = NUMERIC_FIELDS + ("sensor_type",)
#: the camera's black level (8-bit DN) as a driver reports it per frame: taken off the image, not a model input
BLACK_LEVEL = "black_level_dn"
KNOWN_FIELDS: frozenset[str] = frozenset(REQUIRED_FIELDS + ("bit_depth", BLACK_LEVEL))
#: Other common spellings with their conversion to the CameraMetadata field (SI units).
ALIASES: dict[str, tuple[str, float, float]] = {  # key -> (field, scale, offset)
    "exposure_time_us": ("exposure_time_s", 1e-6, 0.0),
    "exposure_time_ms": ("exposure_time_s", 1e-3, 0.0),
    "sensor_temperature_k": ("sensor_temperature_c", 1.0, -273.15),
    "pixel_size_um": ("pixel_size_m", 1e-6, 0.0),
    "sense_node_gain_uv_per_e": ("sense_node_gain_v_per_e", 1e-6, 0.0),
    "thermal_white_noise_nv_per_sqrt_hz": ("thermal_white_noise_v_per_sqrt_hz", 1e-9, 0.0),
    "pixel_clock_mhz": ("pixel_clock_hz", 1e6, 0.0),
}


def _number(key: str, value: Any) -> float:
    try:
        out = float(value.strip() if isinstance(value, str) else value)
    except (TypeError, ValueError):
        raise AdapterError(f"metadata value {clip(str(key), 80)}={clip(repr(value), 80)} is not a number") from None
    if not math.isfinite(out):
        raise AdapterError(f"metadata value {clip(str(key), 80)}={clip(repr(value), 80)} is not finite")
    return out


def metadata_from_mapping(values: Mapping[str, Any]) -> dict[str, float | str]:
    """Keep the entries named like CameraMetadata fields (or a known alias), as numbers.

    Other keys are ignored (drivers publish more than the noise model needs); empty values count as
    absent; a non-numeric value of a numeric field raises :class:`AdapterError` naming it.
    """
    out: dict[str, float | str] = {}
    for raw_key, value in values.items():
        key = str(raw_key).strip().lower()
        if value is None or (isinstance(value, str) and not value.strip()):
            continue
        if key == "sensor_type":
            out[key] = str(value).strip().lower()
        elif key == "bit_depth":
            bits = _number(key, value)
            if not bits.is_integer():
                raise AdapterError(f"metadata value {clip(str(key), 80)}={clip(repr(value), 80)} is not an integer")
            out[key] = int(bits)
        elif key == BLACK_LEVEL:
            out[key] = black_level_value(key, _number(key, value))
        elif key in KNOWN_FIELDS:
            out[key] = _number(key, value)
        elif key in ALIASES:
            name, scale, offset = ALIASES[key]
            out.setdefault(name, _number(key, value) * scale + offset)
    return out


def black_level_value(where: str, dn: float) -> float:
    """A reported black level on the 8-bit DN scale, checked to lie in [0, BLACK_LEVEL_MAX_DN)."""
    if not 0.0 <= dn < BLACK_LEVEL_MAX_DN:
        raise AdapterError(f"metadata value {clip(where, 80)} = {dn:g} DN is not a black level on the 8-bit scale "
                           f"(must be in [0, {BLACK_LEVEL_MAX_DN:g}))")
    return dn


def metadata_from_diagnostics(msg: Any) -> dict[str, float | str]:
    """Metadata from a DiagnosticArray (its first status) or a DiagnosticStatus (rclpy or rosbags)."""
    status = msg
    if hasattr(msg, "status"):
        if not len(msg.status):
            raise AdapterError("metadata DiagnosticArray has no status")
        status = msg.status[0]
    if not hasattr(status, "values"):
        raise AdapterError("not a DiagnosticArray/DiagnosticStatus message")
    return metadata_from_mapping({kv.key: kv.value for kv in status.values})


def metadata_from_temperature(msg: Any) -> dict[str, float]:
    """``{"sensor_temperature_c": ...}`` from a sensor_msgs/Temperature message (degrees Celsius)."""
    try:
        value = msg.temperature
    except AttributeError:
        raise AdapterError("not a sensor_msgs/Temperature message") from None
    return {"sensor_temperature_c": _number("temperature", value)}


def resolve_metadata(
    static: Mapping[str, Any] | CameraProfile | None,
    dynamic: Mapping[str, Any],
    temperature_c: float | str | None = None,
) -> tuple[CameraMetadata | None, list[str]]:
    """Merge static profile < Temperature reading < per-frame metadata into a CameraMetadata.

    Returns ``(metadata, [])`` when complete, ``(None, missing_field_names)`` when fields are missing.
    Values that are present but invalid (out of range, unknown sensor type) raise
    :class:`noise_monitor.physics.MetadataError` (a ValueError) naming them, as does a Temperature reading that
    cannot be used (``temperature_c`` the reason: not finite, stale) where nothing else gives the temperature.
    """
    base = dict(static.values) if isinstance(static, CameraProfile) else dict(static or {})
    merged = metadata_from_mapping(base)
    if isinstance(temperature_c, (int, float)):
        merged["sensor_temperature_c"] = _number("temperature", temperature_c)
    reported = metadata_from_mapping(dynamic)
    reported.pop(BLACK_LEVEL, None)  # the image's, taken off it before (msg_adapters.frames)
    merged.update(reported)
    if isinstance(temperature_c, str) and "sensor_temperature_c" not in merged:
        raise MetadataError(f"sensor_temperature_c from the {temperature_c}")
    missing = [name for name in REQUIRED_FIELDS if name not in merged]
    if missing:
        return None, missing
    return CameraMetadata.from_mapping(merged), []
