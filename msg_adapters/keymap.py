"""A configurable key map from a driver's key/values to CameraMetadata fields, with units.

Used for a generic ``diagnostic_msgs/DiagnosticArray`` (status name + key), for drivers that expose
exposure and gain as ROS parameters (parameter name as key, see :mod:`msg_adapters.parameter_events`) and for a
driver's JSON frame metadata (Orbbec's: the JSON object's keys, STATUS ``*``).
An entry is the string ``"STATUS|KEY|FIELD|UNIT|SCALE"`` (STATUS ``*`` = any status; SCALE optional,
default 1): the value is multiplied by SCALE, then converted from UNIT to the field's SI unit.
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from noise_monitor.text import clip

from .errors import AdapterError
from .metadata import BLACK_LEVEL, black_level_value
from .vendor import json_metadata, map_gain

#: why Orbbec's JSON metadata needs a key map, with an example (its SDK's units differ by sensor)
ORBBEC_UNITS = ("its units differ by sensor (exposure usually in 100 us on the color stream, 1 us on the IR streams; "
                "gain a level), e.g. '*|exposure|exposure_time_s|100us; *|gain|gain_db|relative'")
#: field -> unit -> (factor, offset) to the field's unit; ``factor`` / ``relative`` gains are special
UNITS: dict[str, dict[str, tuple[float, float]]] = {
    "exposure_time_s": {"s": (1.0, 0.0), "ms": (1e-3, 0.0), "us": (1e-6, 0.0), "100us": (1e-4, 0.0), "ns": (1e-9, 0.0)},
    "gain_db": {"db": (1.0, 0.0), "factor": (1.0, 0.0), "relative": (1.0, 0.0)},
    "sensor_temperature_c": {"degc": (1.0, 0.0), "k": (1.0, -273.15)},
    # a black level in codes of the image's ADC depth -> the 8-bit DN scale
    "black_level_dn": {"dn": (1.0, 0.0), "dn10": (255.0 / 1023.0, 0.0), "dn12": (255.0 / 4095.0, 0.0),
                       "dn16": (255.0 / 65535.0, 0.0)},
}


@dataclass(frozen=True)
class KeyMapEntry:
    status: str
    key: str
    field: str
    unit: str
    scale: float

    def convert(self, value: Any, profile: Any = None) -> float:
        where = f"{self.key}" if self.status == "*" else f"{self.status}/{self.key}"
        try:
            x = float(value.strip() if isinstance(value, str) else value) * self.scale
        except (TypeError, ValueError):
            raise AdapterError(f"metadata {where} = {value!r} is not a number ({self.unit})") from None
        if not math.isfinite(x):
            raise AdapterError(f"metadata {where} = {value!r} is not finite ({self.unit})")
        if self.unit == "factor":
            if x <= 0:
                raise AdapterError(f"metadata {where} = {x:g} is not a valid gain factor (must be > 0)")
            return 20.0 * math.log10(x)
        if self.unit == "relative":
            return map_gain(where, x, getattr(profile, "gain_range_db", None),
                            getattr(profile, "driver_gain_range", None) or (0.0, 1.0))
        factor, offset = UNITS[self.field][self.unit]
        if self.field == BLACK_LEVEL:
            return black_level_value(where, x * factor)
        return x * factor + offset


def parse_keymap(entries: Iterable[str]) -> list[KeyMapEntry]:
    """Parse ``STATUS|KEY|FIELD|UNIT|SCALE`` strings; ValueError naming the entry and what is wrong."""
    out = []
    for raw in entries:
        parts = [p.strip() for p in str(raw).split("|")]
        if len(parts) not in (4, 5) or not all(parts[:4]):
            raise ValueError(f"metadata_keymap entry {raw!r} must be 'STATUS|KEY|FIELD|UNIT[|SCALE]'")
        status, key, field, unit = parts[:4]
        if field not in UNITS:
            raise ValueError(f"metadata_keymap entry {raw!r}: unknown field {field!r} "
                             f"(fields: {', '.join(UNITS)})")
        if unit.lower() not in UNITS[field]:
            raise ValueError(f"metadata_keymap entry {raw!r}: unit {unit!r} is not one of "
                             f"{', '.join(UNITS[field])} for {field}")
        try:
            scale = float(parts[4]) if len(parts) == 5 and parts[4] else 1.0
        except ValueError:
            raise ValueError(f"metadata_keymap entry {raw!r}: scale {parts[4]!r} is not a number") from None
        if not (math.isfinite(scale) and scale > 0):
            raise ValueError(f"metadata_keymap entry {raw!r}: scale must be a positive number, got {scale:g}")
        out.append(KeyMapEntry(status, key, field, unit.lower(), scale))
    return out


def apply_keymap(values: Mapping[tuple[str, str], Any], keymap: Sequence[KeyMapEntry],
                 profile: Any = None) -> dict[str, float]:
    """Fields from ``{(status name, key): value}``; keys the map names but the driver did not send are absent."""
    out: dict[str, float] = {}
    for entry in keymap:
        for (status, key), value in values.items():
            if key == entry.key and entry.status in ("*", status):
                out[entry.field] = entry.convert(value, profile)
                break
    return out


def metadata_from_keymap(msg: Any, keymap: Sequence[KeyMapEntry], profile: Any = None) -> dict[str, float]:
    """Fields from a DiagnosticArray (rclpy or rosbags) through a key map (every status is searched)."""
    statuses = getattr(msg, "status", None)
    if statuses is None:
        raise AdapterError("not a DiagnosticArray message")
    values = {(str(st.name), str(kv.key)): kv.value for st in statuses for kv in st.values}
    out = apply_keymap(values, keymap, profile)
    if not out:
        wanted = ", ".join(f"{e.status}|{e.key}" for e in keymap)
        raise AdapterError(f"metadata DiagnosticArray has none of the mapped keys ({wanted})")
    return out


def metadata_from_json_keymap(msg: Any, keymap: Sequence[KeyMapEntry], profile: Any = None) -> dict[str, float]:
    """Fields from a driver message carrying its frame metadata as a JSON object (``json_data``: Orbbec's) through a
    key map (the object's keys, STATUS ``*``); AdapterError without a key map, for JSON that is no object or holds
    none of the mapped keys."""
    if not keymap:
        raise AdapterError(f"Orbbec frame metadata is read through metadata_keymap: {ORBBEC_UNITS}")
    data = json_metadata(msg)
    out = apply_keymap({("", str(k)): v for k, v in data.items()}, keymap, profile)
    if not out:
        raise AdapterError(f"driver metadata json_data has none of the mapped keys ({', '.join(e.key for e in keymap)}; "
                           f"keys: {clip(', '.join(sorted(map(str, data))))})")
    return out


def keymap_entries(text: str) -> list[str]:
    """A ``metadata_keymap`` parameter's text: entries separated by ';' (or newlines)."""
    return [e.strip() for e in text.replace("\n", ";").split(";") if e.strip()]
