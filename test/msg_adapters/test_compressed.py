"""Lossless CompressedImage (compressed_image_transport PNG/TIFF, compressedDepth PNG, zstd_image_transport)
decoded to the same numbers as the raw image; lossy formats refused with the reason, in bags skipped."""
from __future__ import annotations

import struct
import zlib
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
import zstandard

from msg_adapters import AdapterError, image_to_gray_dn
from noise_monitor.bag.reader import open_bag
from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.bag.writer import BagWriter, typestore

RNG = np.random.default_rng(7)
MONO8 = RNG.integers(0, 256, (24, 40), dtype=np.uint8)
MONO12 = RNG.integers(0, 4096, (24, 40), dtype=np.uint16)
BGR8 = RNG.integers(0, 256, (24, 40, 3), dtype=np.uint8)


def raw(img: np.ndarray, encoding: str, pad: int = 0) -> SimpleNamespace:
    rows = img.reshape(img.shape[0], -1).view(np.uint8) if img.dtype == np.uint16 else img.reshape(img.shape[0], -1)
    rows = np.pad(rows, ((0, 0), (0, pad)))
    return SimpleNamespace(height=img.shape[0], width=img.shape[1], encoding=encoding, is_bigendian=0,
                           step=rows.shape[1], data=rows.tobytes())


def png(img: np.ndarray, fmt: str, header: bytes = b"") -> SimpleNamespace:
    ok, buf = cv2.imencode(".png", img)
    assert ok
    return SimpleNamespace(format=fmt, data=header + buf.tobytes())


def zstd_msg(msg: SimpleNamespace, codec: str = "zlib") -> SimpleNamespace:
    """As zstd_image_transport publishes it: 17-byte header + encoding + compressed data."""
    body = zlib.compress(msg.data) if codec == "zlib" else zstandard.ZstdCompressor().compress(msg.data)
    enc = msg.encoding.encode()
    head = struct.pack("<IIBII", msg.height, msg.width, msg.is_bigendian, msg.step, len(enc)) + enc
    return SimpleNamespace(format="zstd", data=head + body)


@pytest.mark.parametrize("compressed,reference,bits", [
    (png(MONO8, "mono8; png compressed "), raw(MONO8, "mono8"), None),
    (png(MONO12, "mono16; png compressed "), raw(MONO12, "mono16"), 12),
    (png(BGR8, "bgr8; png compressed bgr8"), raw(BGR8, "bgr8"), None),
    (png(MONO8, "bayer_rggb8; png compressed "), raw(MONO8, "bayer_rggb8"), None),
    (png(MONO12, "16UC1; compressedDepth png", header=struct.pack("<iff", 0, 0.0, 0.0)), raw(MONO12, "16UC1"), 12),
    (zstd_msg(raw(MONO8, "mono8", pad=3)), raw(MONO8, "mono8"), None),
    (zstd_msg(raw(MONO12, "mono16")), raw(MONO12, "mono16"), 12),
    (zstd_msg(raw(MONO8, "mono8"), codec="zstd"), raw(MONO8, "mono8"), None),
])
def test_lossless_formats_decode_to_the_raw_values(compressed, reference, bits):
    out = image_to_gray_dn(compressed, bit_depth=bits)
    np.testing.assert_array_equal(out, image_to_gray_dn(reference, bit_depth=bits))


@pytest.mark.parametrize("fmt,match", [
    ("mono8; jpeg compressed mono8", "lossy \\(jpeg\\).*destroys the noise"),
    ("jpeg", "lossy"),
    ("bgr8; webp compressed bgr8", "lossy \\(webp\\)"),
    ("32FC1; compressedDepth png", "32FC1 quantises inverse depth"),
    ("16UC1; compressedDepth rvl", "RVL is not supported"),
    ("mono8; qoi compressed mono8", "unknown compressed image format"),
])
def test_lossy_and_unknown_formats_are_refused_with_the_reason(fmt, match):
    with pytest.raises(AdapterError, match=match):
        image_to_gray_dn(SimpleNamespace(format=fmt, data=b"\x00" * 32))


def test_damaged_payloads_are_refused():
    good = png(MONO8, "mono8; png compressed ")
    with pytest.raises(AdapterError, match="does not decode as PNG"):
        image_to_gray_dn(SimpleNamespace(format=good.format, data=good.data[:40]))
    z = zstd_msg(raw(MONO8, "mono8"))
    with pytest.raises(AdapterError, match="does not decompress"):
        image_to_gray_dn(SimpleNamespace(format="zstd", data=z.data[:30]))
    with pytest.raises(AdapterError, match="shorter than its 17-byte header"):
        image_to_gray_dn(SimpleNamespace(format="zstd", data=b"\x01\x02"))
    with pytest.raises(AdapterError, match="has no data"):
        image_to_gray_dn(SimpleNamespace(format="zstd", data=b""))


def _recompress(src, dst, fmt: str) -> None:
    """Copy a simulated bag with its image topic replaced by CompressedImage frames of format ``fmt``."""
    t = typestore().types
    with open_bag(src) as reader, BagWriter(dst) as w:
        for topic, log_time, msg in reader.messages(sorted(reader.topics)):
            if topic == reader.image_topic:
                img = np.frombuffer(msg.data, np.uint8).reshape(msg.height, msg.step)[:, :msg.width]
                if fmt == "png":
                    data, format_ = cv2.imencode(".png", img)[1].reshape(-1), "mono8; png compressed "
                elif fmt == "zstd":
                    data, format_ = np.frombuffer(zstd_msg(raw(img, "mono8")).data, np.uint8), "zstd"
                else:
                    data, format_ = cv2.imencode(".jpg", img)[1].reshape(-1), "mono8; jpeg compressed mono8"
                msg = t["sensor_msgs/msg/CompressedImage"](header=msg.header, format=format_, data=data)
                topic += "/compressed"
            w.write(topic, msg, log_time)


@pytest.mark.parametrize("fmt", ["png", "zstd", "jpeg"])
def test_compressed_bags_read_like_raw_ones(tmp_path, fmt):
    src = simulate_bag(tmp_path / "raw.mcap", "ev76c661", "gain_sweep", seed=2, frames=3, width=48, height=32)
    dst = tmp_path / f"{fmt}.mcap"
    _recompress(src, dst, fmt)
    with open_bag(src) as a, open_bag(dst) as b:
        assert b.image_topic == "/camera/image_raw/compressed"
        ref, got = list(a.frames("ev76c661")), list(b.frames("ev76c661"))
    assert len(got) == len(ref) == 3
    for r, g in zip(ref, got):
        if fmt == "jpeg":
            assert g.image_dn is None and "lossy (jpeg)" in g.skip_reason
        else:
            assert g.skip_reason is None
            np.testing.assert_array_equal(g.image_dn, r.image_dn)
            assert g.metadata == r.metadata
