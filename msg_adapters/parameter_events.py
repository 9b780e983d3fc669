"""Drivers that expose exposure and gain as ROS parameters (v4l2_camera, usb_cam): follow their
``rcl_interfaces/msg/ParameterEvent`` on ``/parameter_events`` and keep the latest values.

The parameter names and units come from a key map (:mod:`msg_adapters.keymap`, STATUS ``*``); presets
name the drivers' own parameters. V4L2 exposure controls count in 100 us; a V4L2 gain is in the device's
relative units (the camera profile maps it to dB with ``gain_range_db`` over ``driver_gain_range``).
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from .keymap import KeyMapEntry, apply_keymap, parse_keymap

#: driver -> key map of its parameters
PRESETS: dict[str, tuple[str, ...]] = {
    "v4l2_camera": ("*|exposure_time_absolute|exposure_time_s|100us", "*|gain|gain_db|relative"),
    "usb_cam": ("*|exposure|exposure_time_s|100us", "*|gain|gain_db|relative"),
}
#: rcl_interfaces/msg/ParameterType -> ParameterValue field
_VALUE_FIELDS = {1: "bool_value", 2: "integer_value", 3: "double_value", 4: "string_value"}


def preset_keymap(driver: str) -> list[KeyMapEntry]:
    if driver not in PRESETS:
        raise ValueError(f"no parameter preset for driver {driver!r}; presets: {', '.join(PRESETS)} "
                         "(or give metadata_keymap)")
    return parse_keymap(PRESETS[driver])


def parameter_values(event: Any, node_name: str) -> dict[str, Any] | None:
    """{name: value} of the new and changed parameters in a ParameterEvent of ``node_name`` (fully
    qualified, e.g. ``/camera/v4l2_camera``), None for other nodes' events."""
    if str(event.node) != node_name:
        return None
    out: dict[str, Any] = {}
    for p in list(event.new_parameters) + list(event.changed_parameters):
        field = _VALUE_FIELDS.get(int(p.value.type))
        if field is not None:
            out[str(p.name)] = getattr(p.value, field)
    return out


def read_values(names: Sequence[str], values: Sequence[Any]) -> dict[str, Any]:
    """{name: value} of a GetParameters response's ``values`` (rcl_interfaces/ParameterValue, in the order of the
    names asked for); parameters the driver does not have (type NOT_SET) or of other types are absent."""
    out: dict[str, Any] = {}
    for name, value in zip(names, values):
        field = _VALUE_FIELDS.get(int(value.type))
        if field is not None:
            out[str(name)] = getattr(value, field)
    return out


def metadata_from_parameters(values: dict[str, Any], keymap: Sequence[KeyMapEntry], profile: Any = None) -> dict[str, float]:
    """Fields from a driver's parameter values through the key map (parameters it lacks are absent)."""
    return apply_keymap({("*", k): v for k, v in values.items()}, keymap, profile)
