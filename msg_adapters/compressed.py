"""sensor_msgs/CompressedImage -> the fields of a raw sensor_msgs/Image, for lossless formats only.

Lossless formats are decoded; everything else is refused with the reason (lossy compression removes and
reshapes exactly the noise the monitor measures):

- compressed_image_transport PNG or TIFF: ``format`` like ``"mono8; png compressed "``,
  ``"bgr8; png compressed bgr8"`` or ``"mono16; tiff compressed "`` (the original encoding, then the
  codec and the target format); the payload is the PNG/TIFF file (decoded with OpenCV). Colour images
  arrive as BGR(A), gray ones with their original encoding (mono, Bayer).
- compressed_depth_image_transport: ``"16UC1; compressedDepth png"``: a 12-byte configuration header,
  then a 16-bit PNG (lossless); the 32FC1 variant quantises inverse depth (lossy) and RVL is not decoded.
- zstd_image_transport: ``format == "zstd"``: a 17-byte header (height, width: uint32 LE; is_bigendian:
  uint8; step: uint32 LE; encoding length: uint32 LE), the encoding, then the compressed raw ``data``.
  The upstream plugin compresses with zlib despite its name; a Zstandard frame (magic 28 b5 2f fd) is
  decoded with the ``zstandard`` package.
- anything else (``jpeg``, ``jpg``, ``webp``, ``avif``, ``h264``, ...): refused as lossy or unknown.
"""
from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from .errors import AdapterError

LOSSY_CODECS = ("jpeg", "jpg", "jp2", "webp", "avif", "h264", "h265", "hevc", "av1", "vp8", "vp9", "theora",
                "ffmpeg", "mjpeg", "compresseddepth rvl")
_ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"
_ZSTD_HEADER = struct.Struct("<IIBII")
_DEPTH_HEADER_BYTES = 12  # compressed_depth_image_transport ConfigHeader: int32 format + float32[2]
#: OpenCV-decoded arrays -> ROS encodings (by dtype and channels)
_DECODED = {("uint8", 1): "mono8", ("uint16", 1): "mono16", ("uint8", 3): "bgr8", ("uint16", 3): "bgr16",
            ("uint8", 4): "bgra8", ("uint16", 4): "bgra16"}


@dataclass
class RawImage:
    """The fields of a sensor_msgs/Image (what :func:`msg_adapters.image_to_gray_dn` reads)."""

    height: int
    width: int
    encoding: str
    is_bigendian: int
    step: int
    data: np.ndarray


def is_compressed(msg: Any) -> bool:
    """A CompressedImage (has ``format`` and ``data`` but no ``encoding``), rclpy or rosbags."""
    return hasattr(msg, "format") and hasattr(msg, "data") and not hasattr(msg, "encoding")


def _payload(msg: Any) -> bytes:
    data = msg.data
    if isinstance(data, np.ndarray):
        return np.ascontiguousarray(data).reshape(-1).view(np.uint8).tobytes()
    return bytes(data)


def decompress(msg: Any) -> RawImage:
    """Decode a lossless CompressedImage; :class:`AdapterError` names lossy, unknown or damaged input."""
    fmt = str(msg.format).strip()
    low = fmt.lower()
    data = _payload(msg)
    if not data:
        raise AdapterError(f"compressed image ({fmt!r}) has no data")
    if low == "zstd":
        return _zstd(data)
    original, _, codec = (part.strip() for part in low.partition(";"))
    codec_word = codec.split()[0] if codec else original
    if codec_word == "compresseddepth":
        return _depth(data, original, codec, fmt)
    if codec_word in ("png", "tiff"):
        return _opencv(data, original, fmt, codec_word)
    lossy = next((c for c in LOSSY_CODECS if c in low), None)
    if lossy:
        raise AdapterError(f"compressed image format {fmt!r} is lossy ({lossy}): lossy compression destroys the "
                           "noise the monitor measures; publish raw images or lossless PNG/zstd")
    raise AdapterError(f"unknown compressed image format {fmt!r}; lossless formats decoded: "
                       "'<enc>; png compressed ...', '<enc>; tiff compressed ...', '16UC1; compressedDepth png', 'zstd'")


def _opencv(data: bytes, original: str, fmt: str, codec: str) -> RawImage:
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise AdapterError(f"compressed image ({fmt!r}) does not decode as {codec.upper()}")
    channels = 1 if img.ndim == 2 else img.shape[2]
    encoding = _DECODED.get((img.dtype.name, channels))
    if encoding is None:
        raise AdapterError(f"compressed image ({fmt!r}) decodes to {img.dtype.name} x {channels} channels, "
                           "not an 8/16-bit mono or BGR(A) image")
    if channels == 1 and original.startswith("bayer_"):
        encoding = original  # gray payload of a Bayer image: keep the pattern (one green site per cell)
    img = np.ascontiguousarray(img)
    return RawImage(img.shape[0], img.shape[1], encoding, 0, img.strides[0], img.reshape(-1).view(np.uint8))


def _depth(data: bytes, original: str, codec: str, fmt: str) -> RawImage:
    if codec.split()[-1] != "png" or original not in ("16uc1", "mono16"):
        raise AdapterError(f"compressed depth format {fmt!r} is not decoded: only '16UC1; compressedDepth png' "
                           "is lossless (32FC1 quantises inverse depth; RVL is not supported)")
    if len(data) <= _DEPTH_HEADER_BYTES:
        raise AdapterError(f"compressed depth image ({fmt!r}) is shorter than its {_DEPTH_HEADER_BYTES}-byte header")
    raw = _opencv(data[_DEPTH_HEADER_BYTES:], "", fmt, "png")
    if raw.encoding != "mono16":
        raise AdapterError(f"compressed depth image ({fmt!r}) holds {raw.encoding}, expected 16-bit")
    raw.encoding = "16UC1"
    return raw


def _zstd(data: bytes) -> RawImage:
    if len(data) < _ZSTD_HEADER.size:
        raise AdapterError(f"zstd image has {len(data)} bytes, shorter than its {_ZSTD_HEADER.size}-byte header")
    height, width, bigendian, step, enc_len = _ZSTD_HEADER.unpack_from(data)
    start = _ZSTD_HEADER.size + enc_len
    if enc_len > 64 or start > len(data):
        raise AdapterError(f"zstd image header is damaged (encoding length {enc_len})")
    encoding = data[_ZSTD_HEADER.size:start].decode("ascii", errors="replace")
    body = data[start:]
    try:
        if body[:4] == _ZSTD_MAGIC:
            import zstandard

            raw = zstandard.ZstdDecompressor().decompress(body, max_output_size=max(step * height, 1))
        else:
            raw = zlib.decompress(body)
    except Exception as exc:  # zlib.error, zstandard.ZstdError
        raise AdapterError(f"zstd image payload does not decompress: {exc}") from None
    return RawImage(height, width, encoding, bigendian, step, np.frombuffer(raw, np.uint8))
