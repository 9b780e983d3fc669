"""sensor_msgs/CameraInfo -> image geometry (full size, binning, region of interest)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .errors import AdapterError


@dataclass(frozen=True)
class CameraGeometry:
    """Sensor size and the binning/ROI that produced the published image (ROS REP 104 semantics)."""

    width: int
    height: int
    binning_x: int = 1
    binning_y: int = 1
    roi: tuple[int, int, int, int] | None = None  # x_offset, y_offset, width, height (full-res pixels)

    @property
    def image_size(self) -> tuple[int, int]:
        """(height, width) of the image the camera publishes with this binning and ROI."""
        w, h = (self.roi[2], self.roi[3]) if self.roi else (self.width, self.height)
        return h // self.binning_y, w // self.binning_x

    @property
    def binned_pixels(self) -> int:
        """Sensor pixels combined into one image pixel."""
        return self.binning_x * self.binning_y

    def check_image(self, height: int, width: int) -> None:
        """Raise AdapterError when an image does not match this geometry (e.g. a stale CameraInfo)."""
        expected = self.image_size
        if (height, width) != expected:
            raise AdapterError(
                f"image is {width}x{height} but CameraInfo implies {expected[1]}x{expected[0]} "
                f"(sensor {self.width}x{self.height}, binning {self.binning_x}x{self.binning_y}, roi {self.roi})"
            )


def camera_geometry(msg: Any) -> CameraGeometry:
    """Geometry of a CameraInfo message (rclpy or rosbags). Binning 0 means 1 (REP 104)."""
    try:
        width, height = int(msg.width), int(msg.height)
        bx, by = int(msg.binning_x) or 1, int(msg.binning_y) or 1
        roi = msg.roi
        rw, rh = int(roi.width), int(roi.height)
        box = (int(roi.x_offset), int(roi.y_offset), rw, rh) if rw and rh else None
    except AttributeError as exc:
        raise AdapterError(f"not a CameraInfo message: {exc}") from None
    if width <= 0 or height <= 0:
        raise AdapterError(f"CameraInfo has no size ({width}x{height})")
    if box and (box[0] + box[2] > width or box[1] + box[3] > height):
        raise AdapterError(f"CameraInfo ROI {box} exceeds the sensor size {width}x{height}")
    return CameraGeometry(width, height, bx, by, box)
