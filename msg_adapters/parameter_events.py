"""Drivers that expose exposure and gain as ROS parameters (v4l2_camera, usb_cam): follow their
``rcl_interfaces/msg/ParameterEvent`` on ``/parameter_events`` and keep the latest values.

The parameter names and units come from a key map (:mod:`msg_adapters.keymap`, STATUS ``*``); presets
name the drivers' own parameters. V4L2 exposure controls count in 100 us; a V4L2 gain is in the device's
relative units (the camera profile maps it to dB with ``gain_range_db`` over ``driver_gain_range``).

Under the camera's auto-exposure the exposure parameter is the manual setting, not the frame's exposure (usb_cam
``autoexposure: true``, its default, sets V4L2 aperture priority; v4l2_camera's ``auto_exposure`` control 0 or 3):
such values are refused with the reason. usb_cam's ``gain: -1`` (its default) leaves the device's gain alone and
reports none: the gain is then the camera profile's, as for any field a driver does not report.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from .errors import AdapterError
from .keymap import KeyMapEntry, apply_keymap, parse_keymap

#: driver -> key map of its parameters
PRESETS: dict[str, tuple[str, ...]] = {
    "v4l2_camera": ("*|exposure_time_absolute|exposure_time_s|100us", "*|gain|gain_db|relative"),
    "usb_cam": ("*|exposure|exposure_time_s|100us", "*|gain|gain_db|relative"),
}
def _v4l2_auto(value: Any) -> bool:
    """V4L2's exposure menu: 0 auto, 1 manual, 2 shutter priority, 3 aperture priority (the exposure automatic)."""
    return int(value) in (0, 3)


#: driver -> its auto-exposure parameters (v4l2_camera's name of the control on newer and older kernels) and the
#: values under which the exposure parameter is not the frame's
AUTO_EXPOSURE: dict[str, dict[str, Callable[[Any], bool]]] = {
    "v4l2_camera": {"auto_exposure": _v4l2_auto, "exposure_auto": _v4l2_auto},
    "usb_cam": {"autoexposure": bool},
}
#: driver -> its gain parameter and the value that leaves the device's gain alone (not reported)
GAIN_UNSET: dict[str, tuple[str, Callable[[Any], bool]]] = {"usb_cam": ("gain", lambda v: int(v) < 0)}
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


def driver_parameter_names(driver: str, keymap: Sequence[KeyMapEntry]) -> tuple[str, ...]:
    """The parameters to read from the driver: the key map's and its auto-exposure switches."""
    return tuple(dict.fromkeys([e.key for e in keymap] + list(AUTO_EXPOSURE.get(driver, {}))))


def metadata_from_parameters(values: dict[str, Any], keymap: Sequence[KeyMapEntry], profile: Any = None,
                             driver: str = "") -> dict[str, float]:
    """Fields from a driver's parameter values through the key map (parameters it lacks are absent); AdapterError
    while the ``driver``'s auto-exposure runs (module docstring)."""
    for name, automatic in AUTO_EXPOSURE.get(driver, {}).items():
        if name in values and automatic(values[name]):
            raise AdapterError(f"{driver} {name} = {values[name]!r}: the camera's auto-exposure sets each frame's "
                               "exposure and the exposure parameter is only the manual setting; turn auto-exposure "
                               "off for the noise model to know the exposure")
    unset = GAIN_UNSET.get(driver)
    if unset and unset[0] in values and unset[1](values[unset[0]]):
        values = {k: v for k, v in values.items() if k != unset[0]}  # the device's own gain: none reported
    return apply_keymap({("*", k): v for k, v in values.items()}, keymap, profile)
