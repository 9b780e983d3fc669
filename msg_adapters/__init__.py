"""ROS messages <-> numpy images, CameraMetadata and diagnostics.

Works on rclpy messages and on rosbags-deserialised messages alike (duck typing on field names).
"""
from .camera_info import CameraGeometry, camera_geometry
from .diagnostics import ERROR, LEVEL_NAMES, OK, STALE, WARN, StatusReport, reports_from_msg, to_rclpy, to_rosbags
from .errors import AdapterError
from .frames import prepare_frame
from .image import SUPPORTED_ENCODINGS, image_to_gray_dn
from .metadata import (
    metadata_from_diagnostics,
    metadata_from_mapping,
    metadata_from_temperature,
    resolve_metadata,
)
from .vendor import VENDOR_TYPES, metadata_from_vendor, register_vendor_types

__all__ = [
    "AdapterError", "CameraGeometry", "ERROR", "LEVEL_NAMES", "OK", "STALE", "SUPPORTED_ENCODINGS", "StatusReport",
    "VENDOR_TYPES", "WARN", "camera_geometry", "image_to_gray_dn", "metadata_from_diagnostics",
    "metadata_from_mapping", "metadata_from_temperature", "metadata_from_vendor", "prepare_frame", "register_vendor_types",
    "reports_from_msg", "resolve_metadata", "to_rclpy", "to_rosbags",
]
