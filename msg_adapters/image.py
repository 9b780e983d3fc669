"""sensor_msgs/Image -> float32 gray image on the 8-bit DN scale (0..255).

Reductions to one channel (the noise estimator works on gray images):

- ``mono8``/``8UC1``, ``mono16``/``16UC1``: as is, 16-bit words scaled by 255 / (2**bit_depth - 1);
  ``bit_depth`` (e.g. 10 or 12 for LSB-aligned data in 16-bit words) comes from the camera profile or a
  parameter and defaults to the container width. Values beyond the stated bit depth are an error.
- ``rgb8``/``bgr8``/``rgba8``/``bgra8`` (and the 16-bit variants): ``color="luma"`` (default) takes
  Rec.601 luma 0.299 R + 0.587 G + 0.114 B; for independent channel noise its sigma is ~0.67x the
  per-channel sigma, so estimates refer to the luma image. ``color="green"`` keeps the green channel.
- ``bayer_*8``/``bayer_*16``: one green site per 2x2 cell, giving a (H/2, W/2) image. No averaging of the
  two green sites (that would halve the noise variance and bias every estimate).
- ``yuv422_yuy2``/``yuyv`` (Y U Y V) and ``yuv422``/``uyvy`` (U Y V Y), 4:2:2 as USB and libcamera cameras send
  it: the Y (luma) of every pixel, at full resolution; ``color="green"`` is refused (no green channel without the
  subsampled chroma).

``step`` row padding and ``is_bigendian`` (16-bit data) are honoured. A sensor_msgs/CompressedImage in a
lossless format (PNG, TIFF, 16-bit compressedDepth PNG, zstd) is decoded first; lossy formats are refused
(:mod:`msg_adapters.compressed`).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from noise_monitor.text import clip

from .compressed import decompress, is_compressed
from .errors import AdapterError

#: encoding -> (bytes per channel value, channels, layout)
_ENCODINGS: dict[str, tuple[int, int, str]] = {
    "mono8": (1, 1, "mono"),
    "8uc1": (1, 1, "mono"),
    "mono16": (2, 1, "mono"),
    "16uc1": (2, 1, "mono"),
    "rgb8": (1, 3, "rgb"),
    "bgr8": (1, 3, "bgr"),
    "rgba8": (1, 4, "rgb"),
    "bgra8": (1, 4, "bgr"),
    "rgb16": (2, 3, "rgb"),
    "bgr16": (2, 3, "bgr"),
    "rgba16": (2, 4, "rgb"),
    "bgra16": (2, 4, "bgr"),
}
#: Bayer pattern -> (row, column) of the green site used in each 2x2 cell
_BAYER_GREEN = {"rggb": (0, 1), "bggr": (0, 1), "gbrg": (0, 0), "grbg": (0, 0)}
for _pat in _BAYER_GREEN:
    _ENCODINGS[f"bayer_{_pat}8"] = (1, 1, f"bayer_{_pat}")
    _ENCODINGS[f"bayer_{_pat}16"] = (2, 1, f"bayer_{_pat}")

#: 4:2:2 YUV: one luma and one (alternating) chroma byte per pixel; the luma byte's position in the pair
_YUV_LUMA = {"yuyv": 0, "uyvy": 1}
_ENCODINGS.update({"yuv422_yuy2": (1, 2, "yuyv"), "yuyv": (1, 2, "yuyv"), "yuv422": (1, 2, "uyvy"),
                   "uyvy": (1, 2, "uyvy")})

SUPPORTED_ENCODINGS: tuple[str, ...] = tuple(
    e if not e[0].isdigit() else e.upper() for e in _ENCODINGS
)
_LUMA = np.array([0.299, 0.587, 0.114], dtype=np.float32)
COLOR_MODES = ("luma", "green")


def _raw_bytes(data: Any) -> np.ndarray:
    """The message's data field as a flat uint8 array (rclpy: array.array/bytes; rosbags: ndarray)."""
    if isinstance(data, np.ndarray):
        return np.ascontiguousarray(data).reshape(-1).view(np.uint8)
    try:
        return np.frombuffer(data, dtype=np.uint8)
    except TypeError:
        return np.asarray(list(data), dtype=np.uint8)


def _field(msg: Any, name: str) -> Any:
    try:
        return getattr(msg, name)
    except AttributeError:
        raise AdapterError(f"not an image message: no field {name!r}") from None


def image_to_gray_dn(msg: Any, bit_depth: int | None = None, color: str = "luma") -> np.ndarray:
    """Convert a sensor_msgs/Image (rclpy or rosbags) to float32 (H, W) gray DN in [0, 255].

    Raises :class:`AdapterError` with the reason for unsupported encodings, inconsistent sizes or
    values beyond ``bit_depth``; a CompressedImage is decoded when lossless, else refused with the reason.
    """
    if is_compressed(msg):
        msg = decompress(msg)
    encoding = str(_field(msg, "encoding")).strip().lower()
    height, width, step = int(_field(msg, "height")), int(_field(msg, "width")), int(_field(msg, "step"))
    if encoding not in _ENCODINGS:
        raise AdapterError(
            f"unsupported image encoding {clip(repr(encoding), 80)}; supported: {', '.join(SUPPORTED_ENCODINGS)}"
        )
    if color not in COLOR_MODES:
        raise AdapterError(f"color must be one of {COLOR_MODES}, got {color!r}")
    nbytes, channels, layout = _ENCODINGS[encoding]
    if height <= 0 or width <= 0:
        raise AdapterError(f"empty image ({width}x{height})")
    row_bytes = width * channels * nbytes
    if step < row_bytes:
        raise AdapterError(f"step {step} is smaller than width*channels*bytes = {row_bytes} ({encoding})")
    raw = _raw_bytes(_field(msg, "data"))
    if raw.size < step * (height - 1) + row_bytes or raw.size > step * height:  # longer: header/data mismatch
        raise AdapterError(
            f"image data has {raw.size} bytes, expected {step * height} for {width}x{height} {encoding} step {step}"
        )
    if raw.size < step * height:  # last row without padding: pad so the reshape works
        raw = np.concatenate([raw, np.zeros(step * height - raw.size, np.uint8)])
    rows = raw[: step * height].reshape(height, step)[:, :row_bytes]
    if nbytes == 1:
        values = rows.reshape(height, width, channels)
    else:
        dtype = np.dtype(">u2" if bool(_field(msg, "is_bigendian")) else "<u2")
        values = np.ascontiguousarray(rows).view(dtype).reshape(height, width, channels)
    container = 8 * nbytes
    bits = container if bit_depth is None else min(int(bit_depth), container)
    if not 1 <= bits <= 16:
        raise AdapterError(f"bit_depth must be in [1, 16], got {bit_depth!r}")
    max_code = (1 << bits) - 1
    if bits < container:
        top = int(values.max())
        if top > max_code:
            raise AdapterError(
                f"pixel value {top} exceeds the {bits}-bit range (max {max_code}) of {encoding}; "
                "check the bit_depth parameter / profile (data must be LSB-aligned)"
            )
    gray = _to_gray(values, layout, color)
    return (gray * np.float32(255.0 / max_code)).astype(np.float32, copy=False)


def _to_gray(values: np.ndarray, layout: str, color: str) -> np.ndarray:
    if layout == "mono":
        return values[:, :, 0].astype(np.float32)
    if layout.startswith("bayer_"):
        r, c = _BAYER_GREEN[layout[len("bayer_"):]]
        if values.shape[0] < 2 or values.shape[1] < 2:
            raise AdapterError("a Bayer image needs at least 2x2 pixels")
        return values[r::2, c::2, 0].astype(np.float32)
    if layout in _YUV_LUMA:
        if color == "green":
            raise AdapterError("a YUV image has no green channel (its chroma is subsampled): read its luma with "
                               "color luma")
        return values[:, :, _YUV_LUMA[layout]].astype(np.float32)
    rgb = values[:, :, :3].astype(np.float32)
    if layout == "bgr":
        rgb = rgb[:, :, ::-1]
    if color == "green":
        return np.ascontiguousarray(rgb[:, :, 1])
    return rgb @ _LUMA
