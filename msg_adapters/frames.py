"""Image message + metadata -> the monitor's :class:`Frame`: the one frame preparation of node, replay and lab."""
from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from noise_monitor.monitor.frame import Frame
from noise_monitor.monitor.runtime import FrameOptions
from noise_monitor.physics import MetadataError
from noise_monitor.text import clip

from .camera_info import CameraGeometry
from .compressed import decompress, is_compressed
from .errors import AdapterError
from .image import image_to_gray_dn
from .libcamera import RAW_BLACK_LEVEL, RAW_GAIN
from .metadata import BLACK_LEVEL, black_level_value, resolve_metadata


def prepare_frame(image_msg: Any, stamp_ns: int, options: FrameOptions, *,
                  metadata: Mapping[str, Any] | Exception | str | None = None,
                  metadata_stamp_ns: int | None = None, temperature_c: float | str | None = None,
                  geometry: CameraGeometry | None = None, image_error: str | None = None,
                  index: int = 0, log_time_ns: int | None = None) -> Frame:
    """Convert an image message and the metadata chosen for it into a Frame.

    ``metadata``: the per-frame key/values (merged over the profile of ``options`` and the latest
    ``temperature_c``), or the error (an exception or its text) of a metadata message that could not be
    read; ``temperature_c`` may be why the Temperature reading cannot be used. ``geometry``: the latest CameraInfo, checked against the image size. ``image_error``: the image
    message is known to be unusable (e.g. damaged bytes in a bag). A raw Bayer image takes the gain and black level of
    the sensor's output where the metadata tells them apart (camera_ros's ``RAW_GAIN``, without the ISP's digital gain,
    and ``RAW_BLACK_LEVEL``, the pedestal the ISP takes off).
    Problems end up in the Frame's ``image_error`` / ``metadata_error`` / ``missing``, never as exceptions.
    """
    raw = metadata if isinstance(metadata, Mapping) else {}
    if _is_bayer(image_msg):  # the sensor's raw output: its own gain and pedestal where the metadata tells them apart
        raw = {**raw, **{key: raw[own] for key, own in (("gain_db", RAW_GAIN), (BLACK_LEVEL, RAW_BLACK_LEVEL))
                         if own in raw}}
    header = getattr(image_msg, "header", None)
    said = {"sensor_temperature_c": float(temperature_c)} if isinstance(temperature_c, (int, float)) else {}
    frame = Frame(stamp_ns, None, None, index=index, log_time_ns=log_time_ns, raw_metadata={**said, **raw},
                  frame_id=clip(str(getattr(header, "frame_id", "") or ""), 200),
                  metadata_age_s=None if metadata_stamp_ns is None else (stamp_ns - metadata_stamp_ns) / 1e9)
    try:  # a reported black level that is no number of DN makes the frame's metadata unusable (below)
        black, frame.black_level_source = black_level(options, raw)
    except AdapterError as exc:
        black, metadata = 0.0, exc
    try:
        if image_error:
            raise AdapterError(image_error)
        if is_compressed(image_msg):  # lossless formats decoded, lossy ones refused with the reason
            image_msg = decompress(image_msg)
        frame.image_dn = image_to_gray_dn(image_msg, bit_depth=options.depth(raw.get("bit_depth")),
                                          color=options.color)
        if black:  # the model reads signal: the camera's pedestal comes off first
            frame.image_dn = frame.image_dn - np.float32(black)
            frame.black_level_dn = black
        if geometry is not None:
            geometry.check_image(int(image_msg.height), int(image_msg.width))
    except AdapterError as exc:
        frame.image_dn = None
        frame.image_error = str(exc)
        return frame
    if isinstance(metadata, (Exception, str)):
        frame.metadata_error = str(metadata)
        return frame
    try:
        frame.metadata, frame.missing = resolve_metadata(options.profile, raw, temperature_c)
    except (MetadataError, AdapterError) as exc:
        frame.metadata_error = str(exc)
    return frame


def black_level(options: FrameOptions, raw: Mapping[str, Any]) -> tuple[float, str]:
    """The black level (8-bit DN) to take off a frame and where it comes from: the ``black_level_dn`` parameter
    when set, else the driver's per-frame value (``raw``), else the profile's ("parameter" / "metadata" / "profile")."""
    if options.black_level_dn is not None:
        return options.black_level_dn, "parameter"
    if raw.get(BLACK_LEVEL) is not None:
        try:
            return black_level_value(BLACK_LEVEL, float(raw[BLACK_LEVEL])), "metadata"
        except (TypeError, ValueError):
            raise AdapterError(f"metadata {BLACK_LEVEL} = {raw[BLACK_LEVEL]!r} is not a number") from None
    return options.black_level, "profile"


def _is_bayer(image_msg: Any) -> bool:
    """A raw Bayer image: an Image's encoding, or a CompressedImage's format (``"bayer_rggb8; png compressed ..."``)."""
    encoding = getattr(image_msg, "encoding", None) or str(getattr(image_msg, "format", "")).split(";")[0]
    return str(encoding).strip().lower().startswith("bayer_")
