"""Bounded decompression of MCAP chunks: a decompression bomb is refused, not expanded.

rosbags' MCAP storage plugin decompresses every chunk through ``storage_mcap.DECOMPRESSORS`` (compression
name -> ``f(data, declared_uncompressed_size)``), whether it reads the chunk index or scans the file.
:func:`install` puts bounded versions there: a chunk that declares more than :data:`MAX_CHUNK_BYTES` is
refused before anything is decompressed, and a chunk is never expanded beyond the size it declares (a
chunk that lies about its size stops at that size). Memory per chunk is thus at most the limit. rosbag2
bags compressed per message (``compression_mode: message``) are bounded the same way per message.
"""
from __future__ import annotations

import os
from collections.abc import Callable
from typing import Protocol

import lz4.frame
from rosbags.rosbag2 import reader as rosbag2_reader
from rosbags.rosbag2 import storage_mcap
from rosbags.rosbag2.errors import ReaderError

try:  # Python >= 3.14
    from compression import zstd
except ImportError:  # pragma: no cover - depends on the Python version
    from backports import zstd

#: Environment variable raising the limit (MiB) for bags whose single frames are larger.
LIMIT_VARIABLE = "NOISE_MONITOR_MAX_CHUNK_MIB"
#: Largest uncompressed MCAP chunk (or per-message compressed message) read, in bytes: a 16384 x 16384
#: 8-bit frame (256 MiB) with its record headers fits; rosbags and ``ros2 bag record`` write chunks of
#: about 1 MiB around smaller messages. Decompression holds up to twice this (output blocks, then the
#: joined chunk): a replay stays below 1 GB. ``NOISE_MONITOR_MAX_CHUNK_MIB`` raises it for larger frames.
MAX_CHUNK_BYTES = 257 * 2**20
#: Records an MCAP chunk may hold (Schema, Channel, Message): a chunk starting otherwise is not MCAP data.
CHUNK_OPCODES = frozenset((0x03, 0x04, 0x05))


class ChunkTooLarge(ReaderError):
    """A chunk declares or expands to more bytes than allowed."""


def chunk_limit() -> int:
    """The limit in bytes: :data:`MAX_CHUNK_BYTES`, or ``NOISE_MONITOR_MAX_CHUNK_MIB`` when set."""
    text = os.environ.get(LIMIT_VARIABLE)
    if text is None:
        return MAX_CHUNK_BYTES
    try:
        mib = float(text)
    except ValueError:
        mib = float("nan")
    if not 1 <= mib <= 64 * 1024:
        raise ReaderError(f"{LIMIT_VARIABLE} must be a number of MiB in [1, 65536], got {text[:80]!r}")
    return int(mib * 2**20)


def _check_declared(size: int, compression: str) -> int:
    limit = chunk_limit()
    if size > limit:
        raise ChunkTooLarge(f"a {compression} chunk declares {size} uncompressed bytes, more than the limit of "
                            f"{limit} (a decompression bomb?); refused without decompressing it (frames that "
                            f"large need a higher {LIMIT_VARIABLE})")
    return limit


class _Decompressor(Protocol):
    """zstd.ZstdDecompressor and lz4.frame.LZ4FrameDecompressor: one frame, bounded output."""

    eof: bool
    unused_data: bytes | None

    def decompress(self, data: memoryview, max_length: int = -1) -> bytes: ...


def _bounded(new: Callable[[], _Decompressor], compression: str) -> Callable[[bytes, int], bytes]:
    """A decompressor of concatenated frames that never returns (or holds) more than the declared size."""

    def decompress(data: bytes, size: int) -> bytes:
        _check_declared(size, compression)
        parts: list[bytes] = []
        total = 0
        rest = memoryview(data)
        while rest.nbytes:
            dec = new()
            part = dec.decompress(rest, max_length=size - total + 1)
            parts.append(part)
            total += len(part)
            if total > size:
                raise ChunkTooLarge(f"a {compression} chunk expands beyond the {size} bytes it declares (a "
                                    "decompression bomb?); refused")
            if not dec.eof:
                raise ReaderError(f"a {compression} chunk ends in the middle of its compressed data")
            rest = memoryview(dec.unused_data or b"")
        return b"".join(parts)

    return decompress


def _chunk(decompress: Callable[[bytes, int], bytes], compression: str) -> Callable[[bytes, int], bytes]:
    """``decompress`` for MCAP chunks: the content must start with a record a chunk may hold (a chunk of
    zeros would otherwise cost minutes of record-by-record parsing)."""

    def chunk(data: bytes, size: int) -> bytes:
        raw = decompress(data, size)
        if raw and raw[0] not in CHUNK_OPCODES:
            raise ReaderError(f"a {compression} chunk does not hold MCAP records (it starts with opcode "
                              f"0x{raw[0]:02x})")
        return raw

    return chunk


_zstd_bounded = _bounded(zstd.ZstdDecompressor, "zstd")


class _MessageZstd:
    """The ``zstd`` that rosbags' rosbag2 reader sees: per-message decompression (``compression_mode:
    message`` bags) bounded by :data:`MAX_CHUNK_BYTES` per message; everything else is the real module."""

    def __getattr__(self, name: str) -> object:
        return getattr(zstd, name)

    @staticmethod
    def decompress(data: bytes) -> bytes:
        try:
            limit = chunk_limit()
            return _zstd_bounded(data, limit)
        except ChunkTooLarge:
            raise ChunkTooLarge(f"a zstd-compressed message expands beyond the limit of {limit} bytes (a "
                                "decompression bomb?); refused") from None


def install() -> None:
    """Make rosbags decompress MCAP chunks and rosbag2 messages through the bounded decompressors
    (idempotent)."""
    storage_mcap.DECOMPRESSORS["zstd"] = _chunk(_zstd_bounded, "zstd")
    storage_mcap.DECOMPRESSORS["lz4"] = _chunk(_bounded(lz4.frame.LZ4FrameDecompressor, "lz4"), "lz4")
    rosbag2_reader.zstd = _MessageZstd()  # type: ignore[assignment]  # a bounded stand-in for the module
