"""The one frame type of the monitor (live node, bag replay, lab) and the rules that make it unusable."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from noise_monitor.physics import CameraMetadata


@dataclass
class Frame:
    """One image with the metadata resolved for it, or the reasons it cannot be evaluated.

    ``image_dn`` is the gray image in DN (None with ``image_error`` when the message could not be
    converted), the camera's black level ``black_level_dn`` taken off (its ADC clips at ``-black_level_dn`` and
    ``255 - black_level_dn``); ``metadata`` is None with ``missing`` (fields nobody provided) or ``metadata_error``
    (present but invalid). ``index`` and ``log_time_ns`` place a bag frame in its recording.
    """

    stamp_ns: int
    image_dn: np.ndarray | None
    metadata: CameraMetadata | None
    missing: list[str] = field(default_factory=list)
    metadata_age_s: float | None = None  # image stamp minus the stamp of the metadata used
    metadata_error: str | None = None  # metadata present but invalid (e.g. out of range)
    image_error: str | None = None  # the image message could not be converted
    index: int = 0
    log_time_ns: int | None = None  # when the recorder received the image (bags)
    raw_metadata: dict[str, Any] = field(default_factory=dict)
    frame_id: str = ""  # the image header's frame_id (the per-frame outputs carry it)
    black_level_dn: float = 0.0  # the camera's black level, subtracted from the image (8-bit DN scale)
    black_level_source: str = "profile"  # where it comes from: "parameter", "metadata" (per frame) or "profile"

    @property
    def skip_reason(self) -> str | None:
        """Why this frame's inputs cannot be evaluated (image or metadata unusable), else None."""
        return input_problem(self)


def input_problem(frame: Frame) -> str | None:
    """The reason a frame's image or metadata is unusable, worded for users; None when both are usable."""
    if frame.image_error:
        return f"image unusable: {frame.image_error}"
    if frame.image_dn is None:
        return "image unusable: no image"
    if frame.metadata_error:
        return f"metadata invalid: {frame.metadata_error}"
    if frame.metadata is None:
        if frame.missing:
            return f"metadata missing: {', '.join(frame.missing)}"
        return "no metadata for this image"
    img = frame.image_dn
    if img.ndim != 2:
        return f"image must be 2-D gray, got shape {img.shape}"
    if not np.all(np.isfinite(img)):
        return "image contains NaN or inf"
    return None


def skip_reason(frame: Frame, metadata_timeout_s: float, min_size: int = 1) -> str | None:
    """Why a frame cannot be evaluated: unusable inputs, metadata older than ``metadata_timeout_s``
    (relative to the image) or an image smaller than ``min_size`` pixels; None when it can."""
    problem = input_problem(frame)
    if problem:
        return problem
    if frame.metadata_age_s is not None and abs(frame.metadata_age_s) > metadata_timeout_s:
        return (f"metadata stale: {abs(frame.metadata_age_s):.2f} s between image and metadata "
                f"(timeout {metadata_timeout_s:g} s)")
    h, w = frame.image_dn.shape  # type: ignore[union-attr]  # input_problem checked it
    if h < min_size or w < min_size:
        return f"image {w}x{h} is smaller than the patch size {min_size}"
    return None
