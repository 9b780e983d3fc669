"""Build rosbags messages (ROS 2 Jazzy types) for the contract topics: image, camera info, metadata."""
from __future__ import annotations

from typing import Any

import numpy as np

from msg_adapters.diagnostics import OK, StatusReport, to_rosbags
from msg_adapters.outputs import rosbags_image
from noise_monitor.physics import CameraMetadata

from .writer import typestore


def header(stamp_ns: int, frame_id: str = "camera") -> Any:
    t = typestore().types
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    return t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id=frame_id)


def image_msg(img: np.ndarray, stamp_ns: int, frame_id: str = "camera") -> Any:
    """sensor_msgs/Image mono8 (uint8 image) or mono16 (uint16 image)."""
    if img.ndim != 2 or img.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"image must be a 2-D uint8 or uint16 array, got {img.dtype} {img.shape}")
    return rosbags_image(img, stamp_ns, frame_id, typestore())


def camera_info_msg(height: int, width: int, stamp_ns: int, frame_id: str = "camera",
                    focal_px: float | None = None) -> Any:
    """sensor_msgs/CameraInfo of an undistorted pinhole camera (no binning, no ROI)."""
    t = typestore().types
    f = float(focal_px or width)
    cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    return t["sensor_msgs/msg/CameraInfo"](
        header=header(stamp_ns, frame_id), height=height, width=width, distortion_model="plumb_bob",
        d=np.zeros(5), k=np.array([f, 0, cx, 0, f, cy, 0, 0, 1.0]), r=np.eye(3).reshape(-1),
        p=np.array([f, 0, cx, 0, 0, f, cy, 0, 0, 0, 1.0, 0]), binning_x=0, binning_y=0,
        roi=t["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
    )


def metadata_msg(meta: CameraMetadata, stamp_ns: int, hardware_id: str) -> Any:
    """diagnostic_msgs/DiagnosticArray whose first status carries every CameraMetadata field."""
    values = {k: (v if isinstance(v, str) else repr(v)) for k, v in meta.as_dict().items()}
    report = StatusReport(level=OK, name="camera metadata", message="", hardware_id=hardware_id, values=values)
    return to_rosbags([report], stamp_ns, typestore())
