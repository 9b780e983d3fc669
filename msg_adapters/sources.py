"""The node's ``metadata_source`` parameter -> what to subscribe to and how to convert it.

| metadata_source | message | topic |
|---|---|---|
| ``diagnostics`` (default) | diagnostic_msgs/DiagnosticArray with CameraMetadata key names | metadata_topic |
| ``keymap`` | diagnostic_msgs/DiagnosticArray read through ``metadata_keymap`` | metadata_topic |
| ``flir`` / ``basler`` / ``realsense`` / ``aravis`` | the driver's metadata message (:mod:`msg_adapters.vendor`) | metadata_topic |
| ``orbbec`` | Orbbec's JSON frame metadata read through ``metadata_keymap`` (its units differ by sensor) | metadata_topic |
| ``camera_ros`` | diagnostic_msgs/DiagnosticArray with libcamera's metadata (:mod:`msg_adapters.libcamera`) | metadata_topic (``/diagnostics``) |
| ``parameters`` | rcl_interfaces/ParameterEvent of ``metadata_driver_node`` (v4l2_camera, usb_cam) | /parameter_events |

Driver message packages are imported only for their source; a missing one is a ValueError naming the ROS
package to install. A sensor_msgs/Temperature (``temperature_topic``) completes any source.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .keymap import ORBBEC_UNITS, keymap_entries, metadata_from_json_keymap, metadata_from_keymap, parse_keymap
from .libcamera import libcamera_status, metadata_from_camera_ros
from .metadata import metadata_from_diagnostics
from .parameter_events import driver_parameter_names, metadata_from_parameters, parameter_values, preset_keymap
from .vendor import HELD_SOURCES, SOURCE_TYPES, message_class, metadata_from_vendor

METADATA_SOURCES = ("diagnostics", "keymap", *SOURCE_TYPES, "camera_ros", "parameters")
PARAMETER_EVENTS_TOPIC = "/parameter_events"


@dataclass
class MetadataSource:
    """A resolved metadata source. ``convert(msg)`` returns CameraMetadata fields (AdapterError on bad
    fields) or None for a message that does not concern this camera (another node's parameter event).
    ``held``: values persist until changed (parameter events, Basler's header-less CurrentParams, camera_aravis2's
    periodic diagnostics) instead of being paired with images by stamp.
    """

    name: str
    msg_type: Any
    topic: str
    convert: Callable[[Any], dict[str, Any] | None]
    held: bool = False
    #: a driver whose values are its ROS parameters (``parameters``): its node, the parameters to read at start
    #: (events only tell changes) and ``from_values`` for what that read returns ({name: value}: fills what no
    #: event has told yet)
    driver_node: str = ""
    parameter_names: tuple[str, ...] = ()
    from_values: Callable[[dict[str, Any]], dict[str, Any]] | None = None
    #: the camera's own status of a DiagnosticArray shared with other nodes (camera_ros on /diagnostics)
    own_status: Callable[[Any], Any] | None = None

    def hardware_id(self, msg: Any) -> str | None:
        """The driver's device id (its serial) when the message carries one: a DiagnosticArray status's
        ``hardware_id`` (the first non-empty one; the camera's own status's on a shared topic)."""
        statuses = [self.own_status(msg)] if self.own_status is not None else getattr(msg, "status", None) or ()
        for status in statuses:
            if str(getattr(status, "hardware_id", "")).strip():
                return str(status.hardware_id).strip()
        return None


def resolve_source(source: str, topic: str, keymap: str = "", driver_node: str = "", driver: str = "v4l2_camera",
                   profile: Any = None, hardware_id: str = "") -> MetadataSource | None:
    """The source for the node's parameters (None without a metadata topic); ValueError naming what is wrong.
    ``hardware_id``: with ``camera_ros``, read only this camera's statuses (several cameras on /diagnostics)."""
    if source not in METADATA_SOURCES:
        raise ValueError(f"parameter metadata_source must be one of {', '.join(METADATA_SOURCES)}, got {source!r}")
    entries = parse_keymap(keymap_entries(keymap)) if keymap else None
    if source == "keymap" and not entries:
        raise ValueError("metadata_source keymap needs metadata_keymap entries 'STATUS|KEY|FIELD|UNIT[|SCALE]'")
    if source == "orbbec" and not entries:
        raise ValueError(f"metadata_source orbbec needs metadata_keymap entries for the stream's JSON metadata: "
                         f"{ORBBEC_UNITS}")
    if source == "parameters":
        if not driver_node.startswith("/"):
            raise ValueError("metadata_source parameters needs metadata_driver_node, the driver node's fully "
                             f"qualified name (e.g. /camera/v4l2_camera), got {driver_node!r}")
        from rcl_interfaces.msg import ParameterEvent

        km = entries or preset_keymap(driver)
        state: dict[str, Any] = {}

        def from_event(msg: Any) -> dict[str, Any] | None:
            values = parameter_values(msg, driver_node)
            if values is None:
                return None
            state.update(values)
            return metadata_from_parameters(state, km, profile, driver)

        def from_values(values: dict[str, Any]) -> dict[str, Any]:
            for name, value in values.items():
                state.setdefault(name, value)
            return metadata_from_parameters(state, km, profile, driver)

        return MetadataSource(source, ParameterEvent, PARAMETER_EVENTS_TOPIC, from_event, held=True,
                              driver_node=driver_node, parameter_names=driver_parameter_names(driver, km),
                              from_values=from_values)
    if not topic:
        return None
    if source == "orbbec":
        mapped_json = entries or []
        return MetadataSource(source, message_class(source), topic,
                              lambda m: metadata_from_json_keymap(m, mapped_json, profile))
    if source in SOURCE_TYPES:
        return MetadataSource(source, message_class(source), topic, lambda m: metadata_from_vendor(m, profile),
                              held=source in HELD_SOURCES)
    from diagnostic_msgs.msg import DiagnosticArray

    if source == "camera_ros":
        return MetadataSource(source, DiagnosticArray, topic, lambda m: metadata_from_camera_ros(m, hardware_id),
                              own_status=lambda m: libcamera_status(m, hardware_id))
    if source == "keymap":
        mapped = entries or []
        return MetadataSource(source, DiagnosticArray, topic, lambda m: metadata_from_keymap(m, mapped, profile))
    return MetadataSource(source, DiagnosticArray, topic, metadata_from_diagnostics)
