"""Security cases of issue 16 (run in CI by `make test`): decompression bombs in MCAP chunks, YAML alias
bombs ("billion laughs") in every YAML the package reads, and symlinks in a replay's output folder.

Hostile inputs are generated here, small on disk; memory is checked with tracemalloc (it sees the
buffers zstd and lz4 allocate).
"""
from __future__ import annotations

import sqlite3
import tracemalloc
from pathlib import Path

import lz4.frame
import numpy as np
import pytest
import torch
from mcap.data_stream import RecordBuilder
from mcap.records import Channel, Chunk, DataEnd, Footer, Header, Schema
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

from noise_monitor import safe_yaml
from noise_monitor.bag import BagError, bounded
from noise_monitor.bag.bounded import MAX_CHUNK_BYTES
from noise_monitor.bag.messages import image_msg
from noise_monitor.bag.reader import open_bag
from noise_monitor.bag.replay import replay
from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.bag.writer import typestore
from noise_monitor.cli import main
from noise_monitor.monitor import MonitorConfig
from noise_monitor.monitor.config import read_ros_params
from noise_monitor.physics import MetadataError, load_profile

try:
    from compression import zstd
except ImportError:
    from backports import zstd

torch.set_num_threads(1)
MAGIC = b"\x89MCAP0\r\n"
MIB = 2**20
BLOCK = bytes(16 * MIB)


def zeros_compressed(kind: str, n_bytes: int) -> bytes:
    """``n_bytes`` zero bytes compressed as one zstd or lz4 frame, streamed (never held uncompressed)."""
    if kind == "zstd":
        c = zstd.ZstdCompressor(level=1)
        parts = [c.compress(BLOCK[: min(len(BLOCK), n_bytes - i)]) for i in range(0, n_bytes, len(BLOCK))]
        return b"".join(parts) + c.flush()
    c = lz4.frame.LZ4FrameCompressor()
    parts = [c.begin()] + [c.compress(BLOCK[: min(len(BLOCK), n_bytes - i)]) for i in range(0, n_bytes, len(BLOCK))]
    return b"".join(parts) + c.flush()


def bomb_mcap(path: Path, kind: str, real_bytes: int, declared_bytes: int) -> Path:
    """An MCAP with an Image channel and one chunk of ``real_bytes`` zeros that declares ``declared_bytes``."""
    b = RecordBuilder()
    b.write(MAGIC)
    Header(profile="ros2", library="test").write(b)
    Schema(id=1, name="sensor_msgs/msg/Image", encoding="ros2msg", data=b"").write(b)
    Channel(id=1, schema_id=1, topic="/camera/image_raw", message_encoding="cdr", metadata={}).write(b)
    Chunk(compression=kind, data=zeros_compressed(kind, real_bytes), message_start_time=1, message_end_time=2,
          uncompressed_crc=0, uncompressed_size=declared_bytes).write(b)
    DataEnd(data_section_crc=0).write(b)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(b)
    b.write(MAGIC)
    path.write_bytes(b.end())
    return path


def peak_while(fn) -> tuple[BaseException | None, int]:
    """(exception raised by fn, peak traced memory in bytes)."""
    tracemalloc.start()
    try:
        fn()
        raised = None
    except BaseException as exc:  # noqa: BLE001 - returned to the test
        raised = exc
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    return raised, peak


# --- decompression bombs ---------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["zstd", "lz4"])
@pytest.mark.parametrize("declared,needle", [
    (2 * 2**30, "declares 2147483648 uncompressed bytes"),  # honest about its size: refused unread
    (MIB, "expands beyond the 1048576 bytes it declares"),    # lies about its size: stopped at the declared size
])
def test_decompression_bomb_is_refused_within_bounded_memory(tmp_path, kind, declared, needle):
    """A few-KB chunk expanding to 128 MiB: refused naming the bomb, and far less than 128 MiB allocated."""
    bag = bomb_mcap(tmp_path / f"bomb_{kind}.mcap", kind, 128 * MIB, declared)
    assert bag.stat().st_size < 700_000
    exc, peak = peak_while(lambda: open_bag(bag))
    assert isinstance(exc, BagError), exc
    assert "decompression bomb" in str(exc) and needle in str(exc) and str(bag) in str(exc)
    assert peak < 8 * MIB, f"{peak / MIB:.0f} MiB allocated"


def test_chunk_of_zeros_within_the_limit_is_refused_at_once(tmp_path):
    """Honest about its 32 MiB, but not MCAP records: refused after decompressing, not parsed for minutes."""
    bag = bomb_mcap(tmp_path / "zeros.mcap", "zstd", 32 * MIB, 32 * MIB)
    with pytest.raises(BagError, match="chunk does not hold MCAP records"):
        open_bag(bag)


def test_chunk_limit_follows_the_environment(tmp_path, monkeypatch):
    bag = bomb_mcap(tmp_path / "two_mib.mcap", "zstd", 2 * MIB, 2 * MIB)
    monkeypatch.setenv(bounded.LIMIT_VARIABLE, "1")
    with pytest.raises(BagError, match="declares 2097152 uncompressed bytes, more than the limit of 1048576"):
        open_bag(bag)
    monkeypatch.setenv(bounded.LIMIT_VARIABLE, "lots")
    with pytest.raises(BagError, match="NOISE_MONITOR_MAX_CHUNK_MIB must be a number of MiB"):
        open_bag(bag)


def test_decompression_bomb_is_one_line_exit_2_from_replay(tmp_path, capsys):
    bag = bomb_mcap(tmp_path / "bomb.mcap", "zstd", 64 * MIB, MAX_CHUNK_BYTES + 1)
    assert main(["replay", str(bag), "--out", str(tmp_path / "o"), "--no-plot"]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and "noise-monitor replay: error: cannot read bag" in err[0] and "(a decompression bomb?)" in err[0], err
    assert not (tmp_path / "o" / "replay.mcap").exists()


def test_per_message_compressed_rosbag2_bomb_is_refused(tmp_path, monkeypatch):
    """``compression_mode: message`` (ros2 bag record --compression-mode message): each message is its own
    zstd frame; one expanding to 64 MiB is refused at the per-message limit (lowered to 4 MiB here)."""
    monkeypatch.setattr(bounded, "MAX_CHUNK_BYTES", 4 * MIB)
    ts = typestore()
    path = tmp_path / "per_message"
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3)
    writer.set_compression(CompressionMode.MESSAGE, CompressionFormat.ZSTD)
    with writer:
        conn = writer.add_connection("/camera/image_raw", "sensor_msgs/msg/Image", typestore=ts)
        for i in range(3):
            img = image_msg(np.full((48, 64), 100, np.uint8), 10**9 * (i + 1))
            writer.write(conn, 10**9 * (i + 1), ts.serialize_cdr(img, "sensor_msgs/msg/Image"))
    with open_bag(path) as r:  # an ordinary per-message compressed bag reads
        assert [f.image_dn.shape for f in r.frames(load_profile("icx285"))] == [(48, 64)] * 3
    con = sqlite3.connect(next(path.glob("*.db3")))
    con.execute("update messages set data = ? where id = 2", (zeros_compressed("zstd", 64 * MIB),))
    con.commit()
    con.close()

    def read_all():
        with open_bag(path) as r:
            list(r.frames(load_profile("icx285")))

    exc, peak = peak_while(read_all)
    assert isinstance(exc, BagError) and "message expands beyond the limit" in str(exc), exc
    assert peak < 12 * MIB, f"{peak / MIB:.0f} MiB allocated"


def test_chunks_of_legitimate_bags_still_decompress(tmp_path):
    """The bound is not in the way of ordinary zstd-chunked bags (every frame read back)."""
    bag = simulate_bag(tmp_path / "ok.mcap", "icx285", "static", frames=4, width=64, height=48, hold_s=0.0)
    with open_bag(bag) as r:
        frames = list(r.frames(load_profile("icx285")))
    assert len(frames) == 4 and all(f.image_dn is not None and f.image_dn.shape == (48, 64) for f in frames)


# --- YAML alias bombs ------------------------------------------------------------------------------
def laughs(levels: int = 7, width: int = 10) -> str:
    """Anchors ``l0 .. l{levels}``, each a list of ``width`` aliases of the previous: width**levels leaves."""
    lines = ["l0: &l0 lol"]
    lines += [f"l{i}: &l{i} [{', '.join([f'*l{i - 1}'] * width)}]" for i in range(1, levels + 1)]
    return "\n".join(lines) + "\n"


def test_safe_yaml_refuses_alias_bombs_and_keeps_ordinary_aliases():
    with pytest.raises(safe_yaml.YamlError, match="aliases expand to more than 100000 nodes"):
        safe_yaml.loads(laughs(levels=9), "bomb.yaml")  # 10**9 leaves from a ~600 byte document
    assert safe_yaml.loads("base: &b {gain_db: 3}\ncopy: *b\n") == {"base": {"gain_db": 3}, "copy": {"gain_db": 3}}


def test_camera_profile_alias_bomb_is_refused(tmp_path):
    """The profile's name is an alias of 10**7 strings: before, str(name) built a 70 MB name."""
    p = tmp_path / "cam.yaml"
    p.write_text(laughs() + "name: *l7\nfull_well_e: 20000\n")
    exc, peak = peak_while(lambda: load_profile(p))
    assert isinstance(exc, MetadataError) and "alias bomb" in str(exc), exc
    assert peak < 8 * MIB


def test_node_params_alias_bomb_is_refused(tmp_path):
    p = tmp_path / "node.yaml"
    p.write_text(laughs() + "noise_monitor:\n  ros__parameters:\n    patches_per_frame: *l7\n")
    exc, peak = peak_while(lambda: MonitorConfig.from_mapping(read_ros_params(p)))
    assert isinstance(exc, ValueError) and "alias bomb" in str(exc), exc
    assert peak < 8 * MIB


def test_rosbag2_metadata_alias_bomb_is_refused(tmp_path):
    """A rosbag2 folder whose metadata.yaml is a billion-laughs document: refused before rosbags parses it
    (its errors echo metadata fields)."""
    src = simulate_bag(tmp_path / "src", "icx285", "static", frames=2, width=64, height=48, hold_s=0.0)
    meta = src / "metadata.yaml"
    text = meta.read_text()
    meta.write_text(laughs() + text.replace("storage_identifier: mcap", "storage_identifier: *l7"))
    exc, peak = peak_while(lambda: open_bag(src))
    assert isinstance(exc, BagError) and "alias bomb" in str(exc), exc
    assert peak < 8 * MIB


# --- symlinks in the output folder ------------------------------------------------------------------
@pytest.fixture(scope="module")
def estimator():
    from noise_monitor.estimator import load

    return load("full_meta", device="cpu")


@pytest.mark.parametrize("name", ["summary.json", "replay.csv", "replay.png", "replay.mcap"])
def test_replay_replaces_symlinks_in_the_output_folder_and_never_writes_through_them(tmp_path, estimator, name):
    bag = simulate_bag(tmp_path / "b.mcap", "icx285", "static", frames=2, width=64, height=64, hold_s=0.0)
    out = tmp_path / "out"
    out.mkdir()
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    (out / name).symlink_to(victim)
    replay(bag, "icx285", out, estimator=estimator, config=MonitorConfig(patches_per_frame=2), progress=False)
    assert victim.read_text() == "precious"
    assert not (out / name).is_symlink() and (out / name).is_file() and (out / name).stat().st_size > 0
    assert sorted(p.name for p in out.iterdir()) == ["replay.csv", "replay.mcap", "replay.png", "summary.json"]
