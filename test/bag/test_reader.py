"""Bag reading: formats, topic detection and overrides, vendor types from the bag, clear errors."""
from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from noise_monitor.bag import BagError
from noise_monitor.bag.messages import camera_info_msg, header, image_msg
from noise_monitor.bag.reader import open_bag
from noise_monitor.bag.simulate import load_truth, simulate_bag
from noise_monitor.bag.writer import BagWriter, typestore
from noise_monitor.paths import share_dir
from noise_monitor.physics import load_profile

SMALL = dict(frames=4, width=48, height=32, hold_s=0.0)


@pytest.fixture(scope="module")
def sim_bag(tmp_path_factory) -> Path:
    return simulate_bag(tmp_path_factory.mktemp("bags") / "sim.mcap", "ev76c661", "gain_sweep", seed=1, **SMALL)


@pytest.mark.parametrize("name,storage", [("bare.mcap", "mcap"), ("dir_mcap", "mcap"), ("dir_sqlite", "sqlite3")])
def test_formats_round_trip_images_and_metadata(tmp_path, name, storage):
    bag = simulate_bag(tmp_path / name, "icx285", "gain_sweep", storage=storage, seed=3, **SMALL)
    assert bag.is_file() == name.endswith(".mcap")
    truth = load_truth(bag)
    with open_bag(bag) as reader:
        assert (reader.image_topic, reader.metadata_topic, reader.camera_info_topic) == (
            "/camera/image_raw", "/camera/metadata", "/camera/camera_info")
        assert reader.temperature_topic is None
        assert len(reader) == 4
        frames = list(reader.frames())
    assert [f.stamp_ns for f in frames] == [r["stamp_ns"] for r in truth["frames"]]
    for f, r in zip(frames, truth["frames"]):
        assert f.skip_reason is None and f.missing == []
        assert f.image_dn.shape == (32, 48) and f.image_dn.dtype == np.float32
        assert f.metadata.gain_db == pytest.approx(r["true_metadata"]["gain_db"])
        assert f.metadata.sensor_type == "ccd" and f.metadata.full_well_e == 14000
        assert f.raw_metadata["gain_db"] == pytest.approx(r["true_metadata"]["gain_db"])
    assert frames[-1].metadata.gain_db == pytest.approx(24.0)


def test_rosbag2_directory_without_metadata_yaml_and_inner_file(tmp_path):
    bag = simulate_bag(tmp_path / "d", "icx285", "static", **SMALL)
    (bag / "metadata.yaml").unlink()
    with open_bag(bag) as reader:
        assert len(reader) == 4
    with open_bag(bag / "d.mcap") as reader:
        assert len(list(reader.frames())) == 4


def test_stated_metadata_is_what_the_reader_sees(tmp_path):
    bag = simulate_bag(tmp_path / "t.mcap", "ev76c661", "double_thermal_noise", frames=10, width=32, height=32,
                       hold_s=0.0)
    truth = load_truth(bag)
    w = load_profile("ev76c661").values["thermal_white_noise_v_per_sqrt_hz"]
    with open_bag(bag) as reader:
        seen = [f.metadata.thermal_white_noise_v_per_sqrt_hz for f in reader.frames()]
    expected = [2 * w if r["corrupted"] else w for r in truth["frames"]]
    assert seen == pytest.approx(expected) and 2 * w in seen


def test_profile_fills_fields_missing_from_the_bag(tmp_path):
    path = tmp_path / "dyn_only.mcap"
    img = np.full((16, 16), 100, np.uint8)
    store = typestore()
    t = store.types
    with BagWriter(path) as w:
        for i in range(3):
            stamp = 1_000_000_000 * (i + 1)
            w.write("/cam/image_raw", image_msg(img, stamp), stamp)
            w.write("/cam/temperature", t["sensor_msgs/msg/Temperature"](header=header(stamp), temperature=40.0 + i,
                                                                         variance=0.0), stamp)
    with open_bag(path) as reader:
        assert reader.metadata_topic is None and reader.temperature_topic == "/cam/temperature"
        no_profile = list(reader.frames())
        with_profile = list(reader.frames(profile="icx285"))
    assert no_profile[0].metadata is None and "full_well_e" in no_profile[0].missing
    assert no_profile[0].skip_reason.startswith("metadata missing: ")
    # the profile has no gain/exposure: still incomplete, the reason names exactly those
    assert with_profile[0].missing == ["gain_db", "exposure_time_s"]
    assert "gain_db, exposure_time_s" in with_profile[0].skip_reason


ACME = """\
std_msgs/Header header
float64 gain_db
float64 exposure_time_s
float32 sensor_temperature_c
string firmware
"""


def test_vendor_type_definition_is_taken_from_the_bag(tmp_path):
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg(ACME, "acme_msgs/msg/CameraState"))
    path = tmp_path / "vendor.mcap"
    img = np.full((16, 16), 80, np.uint8)
    with BagWriter(path, store=store) as w:
        for i in range(2):
            stamp = 1_000_000_000 * (i + 1)
            w.write("/acme/state", store.types["acme_msgs/msg/CameraState"](
                header=header(stamp), gain_db=3.0 * i, exposure_time_s=0.01, sensor_temperature_c=30.0,
                firmware="1.2"), stamp)
            w.write("/acme/image_raw", image_msg(img, stamp), stamp)
    assert "acme_msgs/msg/CameraState" not in typestore().types  # only the bag knows it
    with open_bag(path) as reader:
        assert reader.metadata_topic == "/acme/state"
        frames = list(reader.frames(profile="ev76c661"))
    assert [f.metadata.gain_db for f in frames] == [0.0, 3.0]
    assert all(f.skip_reason is None for f in frames)


def test_topic_overrides_and_ambiguity(tmp_path):
    path = tmp_path / "two.mcap"
    with BagWriter(path) as w:
        for topic, value in (("/left/image", 10), ("/right/image", 200)):
            w.write(topic, image_msg(np.full((8, 8), value, np.uint8), 5), 5)
            w.write(topic.replace("image", "camera_info"), camera_info_msg(8, 8, 5), 5)
    with pytest.raises(BagError, match="several image topics.*--image-topic"):
        open_bag(path)
    with open_bag(path, image_topic="/right/image") as reader:  # the camera info of the same namespace
        assert reader.camera_info_topic == "/right/camera_info"
        assert float(next(reader.frames()).image_dn.mean()) == 200.0
    with pytest.raises(BagError, match="'/nope' is not in bag"):
        open_bag(path, image_topic="/nope")


def test_topics_recorded_without_messages_and_a_recorded_monitors_debug_view_are_no_candidates(tmp_path):
    """``ros2 bag record -a`` keeps every advertised topic, also those that carried nothing (until 2026-12-04 an
    empty /camera/image_raw beside the frames' topic was chosen: "0 frames", exit 0), and a bag recorded with the
    monitor running holds its ~/debug_image too."""
    t = typestore().types
    frame = np.full((8, 8), 90, np.uint8)
    png = np.frombuffer(cv2.imencode(".png", frame)[1].tobytes(), np.uint8)
    cases = {
        "compressed": ({"/camera/image_raw": "sensor_msgs/msg/Image"},
                       [("/camera/image_raw/compressed", t["sensor_msgs/msg/CompressedImage"](
                           header=header(k), format="mono8; png compressed", data=png)) for k in range(1, 4)],
                       "/camera/image_raw/compressed"),
        "image": ({"/camera/image_raw": "sensor_msgs/msg/Image", "/camera/metadata_extra":
                   "diagnostic_msgs/msg/DiagnosticArray"},
                  [("/camera/image", image_msg(frame, k)) for k in range(1, 4)], "/camera/image"),
        "debug": ({}, [(topic, image_msg(frame, k)) for k in range(1, 4)
                       for topic in ("/camera/image", "/noise_monitor/debug_image")], "/camera/image"),
    }
    for name, (empty, messages, chosen) in cases.items():
        path = tmp_path / f"{name}.mcap"
        with BagWriter(path) as w:
            w.declare(empty)
            for topic, msg in messages:
                w.write(topic, msg, msg.header.stamp.nanosec)
        with open_bag(path) as reader:
            assert reader.image_topic == chosen, name
            frames = list(reader.frames("icx285"))
        assert len(frames) == 3 and all(f.image_dn is not None and f.image_dn.mean() == 90 for f in frames), name


def test_metadata_without_header_stamps_is_matched_by_the_time_it_was_recorded(tmp_path, sim_bag):
    """A driver that leaves its metadata's header stamp zero, recorded 40 ms after capture as the images are: matched
    by the recording's times (until 2026-12-04 its recording time met the images' header stamps: every frame got the
    previous frame's gain, the first none)."""
    from rosbags.highlevel import AnyReader

    latency = 40_000_000
    unstamped = tmp_path / "unstamped.mcap"
    with AnyReader([sim_bag], default_typestore=typestore()) as reader, BagWriter(unstamped) as w:
        for conn, _, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            if conn.topic.endswith("metadata"):
                msg.header.stamp.sec, msg.header.stamp.nanosec = 0, 0
            w.write(conn.topic, msg, stamp + latency)
    truth = [r["true_metadata"]["gain_db"] for r in load_truth(sim_bag)["frames"]]
    with open_bag(unstamped) as reader:
        frames = list(reader.frames("ev76c661"))
    assert len(set(truth)) == 4 and [f.metadata.gain_db for f in frames] == pytest.approx(truth)
    assert all(f.metadata_age_s == pytest.approx(0.0) for f in frames)


def test_a_ros1_bag_is_read_as_its_rosbag2_conversion(tmp_path, sim_bag):
    """Field campaigns recorded with ROS 1: the .bag file's frames are the same as those of the rosbag2 bag it was
    converted from (rosbags reads both; until 2026-12-04 a .bag was "not a bag"); play, which publishes the recorded
    CDR bytes, asks for the conversion; an upper-case suffix is named."""
    from rosbags.convert import convert
    from rosbags.typesys import Stores

    ros1 = tmp_path / "field.bag"
    convert([sim_bag], ros1, dst_storage="sqlite3", dst_version=None, compress=None, compress_mode="file",
            default_typestore=typestore(), typestore=get_typestore(Stores.ROS1_NOETIC), exclude_topics=[],
            include_topics=[], exclude_msgtypes=[], include_msgtypes=[])
    with open_bag(sim_bag) as reader:
        ref = list(reader.frames("ev76c661"))
    with open_bag(ros1) as reader:
        assert (reader.image_topic, reader.metadata_topic) == ("/camera/image_raw", "/camera/metadata")
        frames = list(reader.frames("ev76c661"))
        with pytest.raises(BagError, match="is a ROS 1 bag.*rosbags-convert"):
            next(reader.raw_messages())
    assert len(frames) == len(ref) == 4
    for f, r in zip(frames, ref):
        assert f.stamp_ns == r.stamp_ns and f.metadata == r.metadata and np.array_equal(f.image_dn, r.image_dn)
    upper = tmp_path / "FIELD.MCAP"
    shutil.copy(sim_bag, upper)
    with pytest.raises(BagError, match="rename it to FIELD.mcap"):
        open_bag(upper)


def test_bad_image_is_skipped_with_reason(tmp_path):
    path = tmp_path / "bad.mcap"
    msg = image_msg(np.zeros((8, 8), np.uint8), 7)
    msg.encoding = "yuv422_weird"
    with BagWriter(path) as w:
        w.write("/camera/image_raw", msg, 7)
    with open_bag(path) as reader:
        (frame,) = reader.frames(profile="icx285")
    assert frame.image_dn is None and frame.skip_reason.startswith("image unusable: unsupported image encoding")


def test_camera_info_mismatch_is_a_skip_reason(tmp_path):
    path = tmp_path / "info.mcap"
    with BagWriter(path) as w:
        w.write("/camera/camera_info", camera_info_msg(100, 200, 1), 1)
        w.write("/camera/image_raw", image_msg(np.zeros((8, 8), np.uint8), 1), 1)
    with open_bag(path) as reader:
        (frame,) = reader.frames()
    assert "CameraInfo implies 200x100" in frame.skip_reason


def test_unusable_bags_raise_bag_error(tmp_path, sim_bag):
    with pytest.raises(FileNotFoundError):
        open_bag(tmp_path / "missing.mcap")
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"not a bag at all" * 100)
    truncated = tmp_path / "truncated.mcap"
    truncated.write_bytes(sim_bag.read_bytes()[: sim_bag.stat().st_size // 2])
    for bad in (empty, garbage, truncated):
        with pytest.raises(BagError, match="cannot read bag"):
            open_bag(bad)
    flipped = bytearray((share_dir() / "bags" / "icx285_lab.mcap").read_bytes())  # damage a compressed chunk
    mid = len(flipped) // 2
    flipped[mid:mid + 2000] = bytes(b ^ 0xFF for b in flipped[mid:mid + 2000])
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(flipped))
    with pytest.raises(BagError, match="damaged|cannot read"):
        with open_bag(damaged) as reader:
            list(reader.frames())
    text = tmp_path / "notes.txt"
    text.write_text("hello")
    with pytest.raises(BagError, match="not a bag"):
        open_bag(text)
    info_only = tmp_path / "info_only.mcap"
    with BagWriter(info_only) as w:
        w.write("/camera/camera_info", camera_info_msg(8, 8, 1), 1)
    with pytest.raises(BagError, match="no image topic"):
        open_bag(info_only)
    compressed = tmp_path / "compressed.mcap"
    t = typestore().types
    with BagWriter(compressed) as w:
        w.write("/camera/image_raw/compressed", t["sensor_msgs/msg/CompressedImage"](
            header=header(1), format="jpeg", data=np.zeros(4, np.uint8)), 1)
    with open_bag(compressed) as reader:  # opened; its lossy frame is skipped with the reason
        assert [f.skip_reason for f in reader.frames("icx285")] == [
            "image unusable: compressed image format 'jpeg' is lossy (jpeg): lossy compression destroys the noise "
            "the monitor measures; publish raw images or lossless PNG/zstd"]
    no_msgs = tmp_path / "no_msgs"
    shutil.copytree(simulate_bag(tmp_path / "src", "icx285", "static", frames=1, width=16, height=16), no_msgs)
    (no_msgs / "src.mcap").write_bytes(b"")
    with pytest.raises(BagError):
        open_bag(no_msgs)


def test_flir_vendor_metadata_temperature_topic_and_invalid_values(tmp_path):
    from msg_adapters.vendor import FLIR_IMAGE_METADATA

    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg(FLIR_IMAGE_METADATA, "flir_camera_msgs/msg/ImageMetaData"))
    t = store.types
    path = tmp_path / "flir.mcap"
    with BagWriter(path, store=store) as w:
        for i, gain in enumerate((6.0, 99.0)):  # 99 dB is outside the valid range
            stamp = 1_000_000_000 * (i + 1)
            w.write("/flir/meta", t["flir_camera_msgs/msg/ImageMetaData"](
                header=header(stamp), camera_time=0, brightness=0, exposure_time=2500, max_exposure_time=10000,
                gain=gain), stamp)
            w.write("/flir/temperature", t["sensor_msgs/msg/Temperature"](header=header(stamp), temperature=31.5,
                                                                          variance=0.0), stamp)
            w.write("/flir/image_raw", image_msg(np.full((16, 16), 60, np.uint8), stamp), stamp)
    with open_bag(path) as reader:
        assert (reader.metadata_topic, reader.temperature_topic) == ("/flir/meta", "/flir/temperature")
        ok, bad = reader.frames(profile="icx285")
    # the frame's metadata as recorded, the Temperature topic's reading with it (characterize reads it there)
    assert ok.raw_metadata == {"exposure_time_s": pytest.approx(0.0025), "gain_db": 6.0, "sensor_temperature_c": 31.5}
    assert ok.skip_reason is None and ok.metadata.sensor_temperature_c == 31.5
    assert ok.metadata.exposure_time_s == pytest.approx(0.0025)
    assert bad.metadata is None and "gain_db" in bad.metadata_error
    assert bad.skip_reason.startswith("metadata invalid")


def test_the_monitors_own_outputs_are_not_taken_for_metadata(tmp_path):
    """A recording of a running monitor holds /diagnostics and <ns>/frame (DiagnosticArray): neither is the
    camera's metadata; a plain DiagnosticArray topic of the camera still is."""
    from msg_adapters.diagnostics import to_rosbags
    from noise_monitor.monitor.status import OK, StatusReport

    report = StatusReport(level=OK, name="noise_monitor: camera", message="ok", hardware_id="", values={"xi": "0.1"})
    path = tmp_path / "recorded.mcap"
    with BagWriter(path) as w:
        w.write("/camera/image_raw", image_msg(np.full((8, 8), 50, np.uint8), 5), 5)
        for topic in ("/diagnostics", "/noise_monitor/frame"):
            w.write(topic, to_rosbags([report], 5, typestore()), 5)
    with open_bag(path) as reader:
        assert reader.metadata_topic is None
    with BagWriter(path2 := tmp_path / "camera_status.mcap") as w:
        w.write("/camera/image_raw", image_msg(np.full((8, 8), 50, np.uint8), 5), 5)
        for topic in ("/noise_monitor/frame", "/camera/status"):
            w.write(topic, to_rosbags([report], 5, typestore()), 5)
    with open_bag(path2) as reader:
        assert reader.metadata_topic == "/camera/status"
