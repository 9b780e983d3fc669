"""Bad-input matrix of bags and replay: empty, truncated and corrupt MCAP and sqlite3 bags, bags without an
image topic, unknown vendor types, bad/missing/late/duplicated/out-of-order metadata, CameraInfo that
disagrees, header stamps out of order, a plug-in effect that raises or returns NaN.

Expected outcomes: a BagError (exit code 2 and one line on stderr from the CLI) naming the bag and the
problem, or the frame skipped with the monitor's reason; every image accounted for, never a hang.
"""
from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path

import numpy as np
import pytest
import torch
from mcap.reader import make_reader
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from msg_adapters import WARN, StatusReport, reports_from_msg
from msg_adapters.diagnostics import jazzy_typestore
from msg_adapters.outputs import DIAGNOSTICS_TOPIC, frame_topic
from noise_monitor.bag import BagError
from noise_monitor.bag.messages import camera_info_msg, header, image_msg, metadata_msg
from noise_monitor.bag.reader import open_bag
from noise_monitor.bag.replay import replay
from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.bag.writer import BagWriter
from noise_monitor.cli import main
from noise_monitor.monitor import MonitorConfig
from noise_monitor.physics import CameraProfile, load_plugin_file, load_profile
from noise_monitor.physics.effects import registry

torch.set_num_threads(1)
PROFILE = load_profile("icx285")
META = PROFILE.metadata(gain_db=12.0, exposure_time_s=0.01, sensor_temperature_c=30.0)
CONFIG = MonitorConfig(patches_per_frame=2)
T0 = 1_700_000_000 * 10**9
PERIOD = 100_000_000  # 10 Hz
SMALL = dict(frames=6, width=48, height=32, hold_s=0.0)


@pytest.fixture(scope="module")
def estimator():
    from noise_monitor.estimator import load

    return load("full_meta", device="cpu")


@pytest.fixture(scope="module")
def src(tmp_path_factory) -> dict[str, Path]:
    """A small simulated bag as bare MCAP and as a sqlite3 rosbag2 folder."""
    d = tmp_path_factory.mktemp("src")
    return {"mcap": simulate_bag(d / "ok.mcap", "icx285", "static", seed=2, **SMALL),
            "sqlite3": simulate_bag(d / "ok_sqlite", "icx285", "static", seed=2, storage="sqlite3", **SMALL)}


def textured(size: int, seed: int = 0) -> np.ndarray:
    """A mono8 frame with a gradient and noise (usable patches everywhere)."""
    y, x = np.mgrid[0:size, 0:size]
    clean = 60 + 100 * (x + y) / (2 * size)
    return np.clip(np.rint(clean + np.random.default_rng(seed).normal(0, 2.0, clean.shape)), 0, 255).astype(np.uint8)


def replay_cli(bag: Path, capsys, *extra: str) -> tuple[int, str]:
    code = main(["replay", str(bag), "--out", str(bag.parent / f"out_{bag.name}"), "--no-plot", *extra])
    return code, capsys.readouterr().err


def assert_one_line_error(err: str, *needles: str) -> None:
    lines = [ln for ln in err.splitlines() if ln.strip() and "%|" not in ln]  # ignore progress bars
    assert len(lines) == 1 and lines[0].startswith("noise-monitor replay: error: "), err
    assert "Traceback" not in err and all(n in lines[0] for n in needles), err


# --- unusable bags ---------------------------------------------------------------------------------
@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_bags_without_messages_are_empty_errors(tmp_path, storage):
    for name in ("empty.mcap", "empty_dir"):
        if storage == "sqlite3" and name.endswith(".mcap"):
            continue
        with BagWriter(tmp_path / name, storage=storage):
            pass
        with pytest.raises(BagError, match=f"bag {tmp_path / name} is empty \\(no messages\\)"):
            open_bag(tmp_path / name)


def test_zero_byte_files_and_folders_without_a_bag(tmp_path, src, capsys):
    (tmp_path / "zero.mcap").write_bytes(b"")
    with pytest.raises(BagError, match="cannot read bag .*zero.mcap"):
        open_bag(tmp_path / "zero.mcap")
    sq = shutil.copytree(src["sqlite3"], tmp_path / "zero_sqlite")
    next(sq.glob("*.db3")).write_bytes(b"")
    with pytest.raises(BagError, match="cannot read bag .*zero_sqlite"):
        open_bag(sq)
    (tmp_path / "nothing").mkdir()
    with pytest.raises(BagError, match="folder without metadata.yaml and 0 .mcap/.db3 files"):
        open_bag(tmp_path / "nothing")
    code, err = replay_cli(tmp_path / "zero.mcap", capsys)
    assert code == 2
    assert_one_line_error(err, "cannot read bag", "zero.mcap", "(corrupt or truncated?)")


@pytest.mark.parametrize("fraction", [0.02, 0.3, 0.6, 0.9, 0.999])
def test_truncated_mcap_is_a_bag_error(tmp_path, src, fraction):
    data = src["mcap"].read_bytes()
    bad = tmp_path / "cut.mcap"
    bad.write_bytes(data[: int(len(data) * fraction)])
    with pytest.raises(BagError, match="cut.mcap"):
        with open_bag(bad) as reader:
            list(reader.frames(PROFILE))


def rewrite_with_checksums(src: Path, dst: Path) -> Path:
    """The bag re-written by the mcap library: uncompressed chunks with CRCs, as ``ros2 bag record`` writes
    them (rosbags, our writer, leaves the chunk CRC at 0)."""
    with open(src, "rb") as fh, open(dst, "wb") as out:
        reader = make_reader(fh)
        summary = reader.get_summary()
        w = McapWriter(out, compression=CompressionType.NONE)
        w.start(profile="ros2", library="test")
        schemas = {k: w.register_schema(v.name, v.encoding, v.data) for k, v in summary.schemas.items()}
        channels = {k: w.register_channel(c.topic, c.message_encoding, schemas[c.schema_id])
                    for k, c in summary.channels.items()}
        for _, channel, m in reader.iter_messages(log_time_order=True):
            w.add_message(channels[channel.id], m.log_time, m.data, m.publish_time)
        w.finish()
    return dst


def summaries(path: Path, topic: str = DIAGNOSTICS_TOPIC) -> list[StatusReport]:
    """The statuses on ``topic`` (default the /diagnostics period summaries) of a replay's MCAP."""
    with open(path, "rb") as fh:
        return [reports_from_msg(jazzy_typestore().deserialize_cdr(m.data, schema.name))[0]
                for schema, _, m in make_reader(fh).iter_messages(topics=[topic])]


def frames_of(bag: Path) -> list[tuple[int, bytes | None, str | None]]:
    with open_bag(bag) as reader:
        return [(f.stamp_ns, None if f.image_dn is None else f.image_dn.tobytes(), f.skip_reason)
                for f in reader.frames(PROFILE)]


@pytest.mark.parametrize("where", [0.2, 0.4, 0.6, 0.8])
def test_flipped_byte_in_a_checksummed_mcap_is_a_bag_error(tmp_path, src, where):
    good = rewrite_with_checksums(src["mcap"], tmp_path / "crc.mcap")
    assert frames_of(good) == frames_of(src["mcap"])
    data = bytearray(good.read_bytes())
    data[int(len(data) * where)] ^= 0x5A
    bad = tmp_path / "flipped.mcap"
    bad.write_bytes(bytes(data))
    with pytest.raises(BagError, match="flipped.mcap"):
        frames_of(bad)


def test_damaged_mcap_never_loses_frames_silently(tmp_path, src, capsys):
    """16 zeroed bytes anywhere in a bag without chunk CRCs: a BagError, or every frame read (damaged pixel
    bytes cannot be detected without a checksum; damaged records and lengths are)."""
    data = src["mcap"].read_bytes()
    good = frames_of(src["mcap"])
    errors, bad = 0, tmp_path / "zeroed.mcap"
    for offset in range(0, len(data), len(data) // 40):
        damaged = bytearray(data)
        damaged[offset : offset + 16] = bytes(16)
        bad.write_bytes(bytes(damaged))
        try:
            got = frames_of(bad)
        except BagError as exc:
            assert "zeroed.mcap" in str(exc)
            errors += 1
            continue
        assert [f[0] for f in got] == [f[0] for f in good], f"frames lost silently (zeroed at {offset})"
    assert errors >= 10
    damaged = bytearray(data)
    damaged[len(data) // 3 : len(data) // 3 + 16] = bytes(16)
    bad.write_bytes(bytes(damaged))
    code, err = replay_cli(bad, capsys, "--profile", "icx285")
    assert code == 2
    assert_one_line_error(err, "zeroed.mcap", "damaged")
    assert not (tmp_path / "out_zeroed.mcap" / "replay.mcap").exists()  # no half-written results


@pytest.mark.parametrize("fraction", [0.1, 0.5, 0.9])
def test_truncated_sqlite3_bag_is_a_bag_error(tmp_path, src, fraction):
    bag = shutil.copytree(src["sqlite3"], tmp_path / "cut")
    db = next(bag.glob("*.db3"))
    db.write_bytes(db.read_bytes()[: int(db.stat().st_size * fraction)])
    with pytest.raises(BagError, match="cannot read bag .*cut.*malformed"):
        open_bag(bag)


@pytest.mark.parametrize("damage", ["half", "bad length", "random", "trailing junk"])
@pytest.mark.parametrize("topic, skipped", [("/camera/image_raw", "image unusable: damaged sensor_msgs/msg/Image"),
                                            ("/camera/metadata", "metadata invalid: /camera/metadata: damaged "),
                                            ("/camera/camera_info", None)])
def test_damaged_message_in_sqlite3_bag_skips_only_its_frame_naming_it(tmp_path, src, damage, topic, skipped):
    """One message that does not decode: the frame it concerns is skipped with the reason, the others are
    read as before (a damaged CameraInfo is ignored like any unusable one)."""
    bag = shutil.copytree(src["sqlite3"], tmp_path / "damaged")
    con = sqlite3.connect(next(bag.glob("*.db3")))
    mid, blob = con.execute("select m.id, m.data from messages m join topics t on m.topic_id = t.id "
                            "where t.name = ? order by m.timestamp limit 1 offset 2", (topic,)).fetchone()
    b = bytearray(blob)
    if damage == "half":
        b = b[: len(b) // 2]
    elif damage == "bad length":
        b[20:24] = b"\xff\xff\xff\x7f"
    elif damage == "random":
        b = bytearray(np.random.default_rng(3).integers(0, 256, len(b), dtype=np.uint8).tobytes())
    else:
        b += b"junk"
    con.execute("update messages set data = ? where id = ?", (bytes(b), mid))
    con.commit()
    con.close()
    with open_bag(src["sqlite3"]) as reader:
        good = list(reader.frames(PROFILE))
    with open_bag(bag) as reader:
        frames = list(reader.frames(PROFILE))
    assert [f.index for f in frames] == [f.index for f in good] == list(range(SMALL["frames"]))
    for f, g in zip(frames, good):
        if skipped is not None and f.index == 2:
            assert f.image_dn is None or f.metadata is None
            assert f.skip_reason.startswith(skipped) and "does not decode" in f.skip_reason
        else:
            assert f.skip_reason is None and np.array_equal(f.image_dn, g.image_dn) and f.metadata == g.metadata


def test_bag_without_image_topic_lists_what_it_has(tmp_path, capsys):
    bag = tmp_path / "no_image.mcap"
    with BagWriter(bag) as w:
        w.write("/camera/camera_info", camera_info_msg(8, 8, T0), T0)
        w.write("/camera/metadata", metadata_msg(META, T0, "t"), T0)
    with pytest.raises(BagError, match="no image topic \\(sensor_msgs/msg/Image or sensor_msgs/msg/CompressedImage\\).*topics: /camera/camera_info "
                                       "\\[sensor_msgs/msg/CameraInfo\\], /camera/metadata"):
        open_bag(bag)
    code, err = replay_cli(bag, capsys)
    assert code == 2
    assert_one_line_error(err, "no image topic")


# --- vendor types and metadata problems inside usable bags ----------------------------------------
STATUS_MSG = "std_msgs/Header header\nuint8 mode\nstring note\n"
EXPOSURE_MSG = "std_msgs/Header header\nfloat64 gain_db\nfloat64 exposure_time_us\nfloat64 sensor_temperature_c\n"


def vendor_bag(path: Path, values: list[tuple[float, float, float]]) -> Path:
    """Images plus two vendor types unknown to ROS Jazzy, their definitions only in the bag."""
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register({**get_types_from_msg(STATUS_MSG, "acme_msgs/msg/Status"),
                    **get_types_from_msg(EXPOSURE_MSG, "acme_msgs/msg/Exposure")})
    t = store.types
    with BagWriter(path, store=store) as w:
        for i, (gain, exp_us, temp) in enumerate(values):
            stamp = T0 + i * PERIOD
            w.write("/acme/status", t["acme_msgs/msg/Status"](header=header(stamp), mode=3, note="ok"), stamp)
            w.write("/acme/exposure", t["acme_msgs/msg/Exposure"](
                header=header(stamp), gain_db=gain, exposure_time_us=exp_us, sensor_temperature_c=temp), stamp)
            w.write("/acme/image_raw", image_msg(textured(32, i), stamp), stamp)
    return path


def test_unknown_vendor_types_deserialise_from_the_bag_and_bad_values_are_named(tmp_path):
    nan, inf = float("nan"), float("inf")
    bag = vendor_bag(tmp_path / "vendor.mcap", [(6.0, 10000.0, 35.0), (nan, 10000.0, 35.0), (6.0, -inf, 35.0),
                                                (6.0, -10000.0, 35.0), (60.0, 10000.0, 35.0), (6.0, 10000.0, 35.0)])
    with open_bag(bag) as reader:
        assert reader.metadata_topic == "/acme/exposure"  # found by its field names, not its type name
        frames = list(reader.frames(PROFILE))
    reasons = [f.skip_reason for f in frames]
    assert reasons[0] is None and frames[0].metadata.exposure_time_s == pytest.approx(0.01)
    assert reasons[1] == "metadata invalid: /acme/exposure: metadata value gain_db=nan is not finite"
    assert reasons[2] == "metadata invalid: /acme/exposure: metadata value exposure_time_us=-inf is not finite"
    assert reasons[3].startswith("metadata invalid: exposure_time_s = -0.01 s is outside the allowed range")
    assert reasons[4].startswith("metadata invalid: gain_db = 60 dB is outside the allowed range")
    assert reasons[5] is None and frames[5].metadata.gain_db == 6.0
    assert all(f.image_dn is not None for f in frames)


def test_vendor_type_without_metadata_fields_is_not_mistaken_for_metadata(tmp_path):
    bag = vendor_bag(tmp_path / "status_only.mcap", [(6.0, 10000.0, 35.0)] * 2)
    with open_bag(bag, metadata_topic=None) as reader:
        assert reader.topics["/acme/status"] == "acme_msgs/msg/Status"
    with open_bag(bag, metadata_topic="/acme/status") as reader:  # forced: it has no usable field
        (f0, _) = list(reader.frames(PROFILE))
    assert f0.metadata is None and f0.skip_reason == "metadata missing: gain_db, exposure_time_s, sensor_temperature_c"


def timing_bag(path: Path, size: int) -> Path:
    """Ten images at 10 Hz with metadata (gain = 2 x frame index dB) that is missing, late, duplicated
    or written out of stamp order; frame 9 carries a NaN."""
    with BagWriter(path) as w:
        later = []
        for i in range(10):
            stamp = T0 + i * PERIOD
            meta = metadata_msg(META.replace(gain_db=2.0 * i), stamp, "t")
            if i == 9:
                meta.status[0].values[0].value = "nan"
            if i in (1, 2):  # missing: frame 1 and 2 have none
                pass
            elif i == 4:  # late: stamped 50 ms after its image (beyond the 10 ms tolerance)
                late = metadata_msg(META.replace(gain_db=2.0 * i), stamp + 50_000_000, "t")
                later.append((late, stamp + 60_000_000))
            elif i == 6:  # out of order: written after frame 7's
                later.append((meta, T0 + 7 * PERIOD + 1))
            else:
                w.write("/camera/metadata", meta, stamp - 1)
                if i == 5:  # duplicated
                    w.write("/camera/metadata", meta, stamp)
            w.write("/camera/image_raw", image_msg(textured(size, i), stamp), stamp)
            for msg, log in [x for x in later if x[1] <= stamp + PERIOD - 2]:
                w.write("/camera/metadata", msg, log)
                later.remove((msg, log))
    return path


def test_metadata_missing_late_duplicated_and_out_of_order_in_a_bag(tmp_path):
    with open_bag(timing_bag(tmp_path / "timing.mcap", 32)) as reader:
        frames = list(reader.frames(PROFILE))
    assert len(frames) == 10
    gains = [f.metadata.gain_db if f.metadata else None for f in frames]
    # frames 1, 2: no metadata of their own -> the latest older one (frame 0's), sample-and-hold, 0.1/0.2 s old
    assert gains[:3] == [0.0, 0.0, 0.0] and frames[2].metadata_age_s == pytest.approx(0.2)
    # frame 4's metadata is 50 ms late: frame 4 holds frame 3's; frame 5 (duplicated) gets its own
    assert gains[3:6] == [6.0, 6.0, 10.0]
    # out-of-order writing does not matter: matching is by header stamp
    assert gains[6:9] == [12.0, 14.0, 16.0]
    assert gains[9] is None and frames[9].skip_reason.startswith("metadata invalid: /camera/metadata: "
                                                                 "metadata value gain_db='nan' is not finite")


def test_replay_accounts_for_every_frame_of_a_bag_with_timing_problems(tmp_path, estimator):
    bag = timing_bag(tmp_path / "timing.mcap", estimator.patch_size)
    s = replay(bag, PROFILE, tmp_path / "out", estimator=estimator, config=MonitorConfig(
        patches_per_frame=2, metadata_timeout_s=0.15), progress=False, plot=False)
    assert (s["frames_total"], s["frames_processed"], s["frames_skipped"]) == (10, 8, 2)
    reasons = {d["index"]: d["reason"] for d in s["skipped"]}
    assert set(reasons) == {2, 9}
    assert reasons[2] == "metadata stale: 0.20 s between image and metadata (timeout 0.15 s)"
    assert "gain_db='nan' is not finite" in reasons[9]
    frame_statuses = summaries(tmp_path / "out" / "replay.mcap", frame_topic())
    assert len(frame_statuses) == 10  # one per frame, the skipped ones saying why at WARN or above (an alarm raised
    # on frames 7-8, whose stated gain puts the model 1.4-1.8 DN above the image, is still active at frame 9)
    skipped = [i for i, r in enumerate(frame_statuses) if r.message.startswith("frame not evaluated")]
    assert skipped == [2, 9] and all(frame_statuses[i].level >= WARN for i in skipped)
    (period,) = summaries(tmp_path / "out" / "replay.mcap")  # 0.9 s of bag time: one (partial) 1 Hz period
    assert (period.values["period_frames"], period.values["period_skipped"]) == ("10", "2")
    assert period.values["skipped: metadata stale"] == period.values["skipped: metadata invalid"] == "1"


def test_camera_info_disagreeing_with_every_image_skips_them_with_the_reason(tmp_path, estimator):
    size = estimator.patch_size
    bag = tmp_path / "info.mcap"
    with BagWriter(bag) as w:
        for i in range(3):
            stamp = T0 + i * PERIOD
            w.write("/camera/camera_info", camera_info_msg(2 * size, 2 * size, stamp), stamp)
            w.write("/camera/metadata", metadata_msg(META, stamp, "t"), stamp)
            w.write("/camera/image_raw", image_msg(textured(size, i), stamp), stamp)
    s = replay(bag, None, tmp_path / "o", estimator=estimator, config=CONFIG, progress=False, plot=False)
    assert s["frames_total"] == 3 and s["frames_processed"] == 0 and s["levels"]["WARN"] == 3
    assert s["skip_reasons"] == {f"image unusable: image is {size}x{size} but CameraInfo implies "
                                 f"{2 * size}x{2 * size} (sensor {2 * size}x{2 * size}, binning 1x1, roi None)": 3}


def test_image_stamps_out_of_order_or_bogus_do_not_hang_the_replay(tmp_path, estimator):
    """Header stamps jumping back by 50 years (a camera clock reset) and forward again: every frame is
    evaluated once; idle reports only fill gaps that really passed in the recording (log time)."""
    size = estimator.patch_size
    stamps = [T0, T0 + PERIOD, 5 * 10**9, T0 + 3 * PERIOD, T0 + 2 * PERIOD, T0 + 4 * PERIOD + 3 * 10**9]
    logs = [T0 + i * PERIOD for i in range(5)] + [T0 + 4 * PERIOD + 3 * 10**9]  # a real 3 s pause at the end
    bag = tmp_path / "clock.mcap"
    with BagWriter(bag) as w:
        for i, (stamp, log) in enumerate(zip(stamps, logs)):
            w.write("/camera/metadata", metadata_msg(META, stamp, "t"), log)
            w.write("/camera/image_raw", image_msg(textured(size, i), stamp), log)
    s = replay(bag, PROFILE, tmp_path / "o", estimator=estimator, config=CONFIG, progress=False, plot=False)
    assert s["frames_total"] == 6 and s["frames_processed"] == 6
    statuses = summaries(tmp_path / "o" / "replay.mcap")
    # the 1 Hz grid restarts where the stamps jump; reports fill only the 3 s pause that really passed
    # (log time): the first five frames' period, two idle periods, the last frame's partial period
    assert [r.values["period_frames"] for r in statuses] == ["5", "0", "0", "1"]


# --- plug-in effects that fail ---------------------------------------------------------------------
PLUGIN = '''
import numpy as np
from noise_monitor.physics.effects import Effect


class RaisingEffect(Effect):
    name = "reliability_raises"
    distribution = "gaussian"

    def sigma_dn(self, signal_dn, cond):
        raise RuntimeError("sensor model not calibrated")


class NanEffect(Effect):
    name = "reliability_nan"
    distribution = "gaussian"

    def sigma_dn(self, signal_dn, cond):
        return np.full(np.shape(signal_dn), np.nan)
'''


@pytest.fixture
def plugin(tmp_path, monkeypatch) -> Path:
    """The failing effects registered for one test only (the registry is process-wide)."""
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    path = tmp_path / "failing_effects.py"
    path.write_text(PLUGIN)
    assert sorted(load_plugin_file(path)) == ["reliability_nan", "reliability_raises"]
    return path


@pytest.mark.parametrize("effect,reason", [
    ("reliability_raises", "evaluation failed: effect 'reliability_raises' failed to evaluate: sensor model not "
                           "calibrated"),
    ("reliability_nan", "evaluation failed: effect(s) reliability_nan returned a NaN, infinite or negative variance"),
])
def test_replay_with_a_failing_plugin_effect_skips_every_frame_naming_it(tmp_path, estimator, plugin, effect,
                                                                        reason):
    """As the node does: each frame is a WARN with the reason; the replay completes with its outputs."""
    bag = simulate_bag(tmp_path / "p.mcap", "icx285", "static", frames=2, width=estimator.patch_size,
                       height=estimator.patch_size, hold_s=0.0)
    profile = CameraProfile("ICX285+broken", dict(PROFILE.values), {effect: {}})
    s = replay(bag, profile, tmp_path / "o", estimator=estimator, config=CONFIG, progress=False, plot=False)
    assert s["frames_total"] == 2 and s["frames_processed"] == 0 and s["skip_reasons"] == {reason: 2}
    assert s["levels"]["WARN"] == 2 and (tmp_path / "o" / "replay.mcap").is_file()


@pytest.mark.parametrize("value,reason", [(255, "saturated"), (0, "black")])
def test_bag_of_only_unusable_frames_gives_reasons_and_no_numbers(tmp_path, estimator, value, reason):
    size = estimator.patch_size
    bag = tmp_path / "flat.mcap"
    with BagWriter(bag) as w:
        for i in range(4):
            stamp = T0 + i * PERIOD
            w.write("/camera/metadata", metadata_msg(META, stamp, "t"), stamp)
            w.write("/camera/image_raw", image_msg(np.full((2 * size, 2 * size), value, np.uint8), stamp), stamp)
    s = replay(bag, PROFILE, tmp_path / "o", estimator=estimator, config=CONFIG, progress=False, plot=False)
    assert (s["frames_total"], s["frames_processed"], s["levels"]["WARN"]) == (4, 0, 4)
    (text, n), = s["skip_reasons"].items()
    assert n == 4 and text.startswith("0 usable patches (need 1): ") and f"{reason} of" in text
    for key in ("sigma_pn", "sigma_dcsn", "sigma_rn", "xi"):
        assert s[key] == {"mean": None, "p5": None, "p95": None, "n": 0}  # no numbers rather than NaN
