"""Vendor per-frame metadata messages (camera drivers that publish exposure/gain on their own topic).

``VENDOR_TYPES`` holds the message definitions so that rosbags can deserialise bags recorded with these
drivers without their packages installed (:func:`register_vendor_types`); :func:`metadata_from_vendor`
converts such a message (rclpy or rosbags) to CameraMetadata fields in SI units.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

from .errors import AdapterError
from .metadata import metadata_from_mapping

#: FLIR Spinnaker driver (ros-drivers/flir_camera_driver): exposure_time in microseconds, gain in dB.
FLIR_IMAGE_METADATA = """\
std_msgs/Header header
uint64 camera_time
int16 brightness
uint32 exposure_time
uint32 max_exposure_time
float32 gain
"""

VENDOR_TYPES: dict[str, str] = {"flir_camera_msgs/msg/ImageMetaData": FLIR_IMAGE_METADATA}


def _flir(msg: Any) -> dict[str, float | str]:
    return metadata_from_mapping({"exposure_time_us": msg.exposure_time, "gain_db": msg.gain})


_CONVERTERS: dict[str, Callable[[Any], dict[str, float | str]]] = {
    "flir_camera_msgs/msg/ImageMetaData": _flir,
}


def message_type_name(msg: Any) -> str:
    """'pkg/msg/Name' of a rosbags (``__msgtype__``) or rclpy (module path) message."""
    name = getattr(msg, "__msgtype__", None)
    if name:
        return str(name)
    cls = type(msg)
    return f"{cls.__module__.split('.')[0]}/msg/{cls.__name__}"


def metadata_from_vendor(msg: Any) -> dict[str, float | str]:
    """CameraMetadata fields from a registered vendor metadata message."""
    name = message_type_name(msg)
    try:
        convert = _CONVERTERS[name]
    except KeyError:
        raise AdapterError(
            f"no metadata adapter for {name}; supported vendor types: {', '.join(sorted(_CONVERTERS))}"
        ) from None
    return convert(msg)


def register_vendor_types(typestore: Any) -> None:
    """Add the vendor message definitions to a rosbags typestore (skips types it already knows)."""
    from rosbags.typesys import get_types_from_msg

    types: dict = {}
    for name, text in VENDOR_TYPES.items():
        if name not in typestore.types:
            types.update(get_types_from_msg(text, name))
    if types:
        typestore.register(types)
