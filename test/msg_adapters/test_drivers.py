"""Camera drivers' metadata: FLIR, Basler, RealSense messages in bags written with the drivers' definitions,
a generic DiagnosticArray key map and parameter events (v4l2_camera / usb_cam)."""
from __future__ import annotations

import csv
import dataclasses
import json
from collections.abc import Callable
from types import SimpleNamespace

import numpy as np
import pytest

from msg_adapters import AdapterError
from msg_adapters.keymap import metadata_from_json_keymap, metadata_from_keymap, parse_keymap
from msg_adapters.libcamera import metadata_from_camera_ros
from msg_adapters.parameter_events import metadata_from_parameters, parameter_values, preset_keymap
from msg_adapters.vendor import ARAVIS, BASLER, FLIR, ORBBEC, REALSENSE, metadata_from_vendor
from noise_monitor.bag.errors import BagError
from noise_monitor.bag.reader import open_bag
from noise_monitor.bag.simulate import load_truth, simulate_bag
from noise_monitor.bag.writer import BagWriter, typestore
from noise_monitor.physics import MetadataError, load_profile
from noise_monitor.physics.metadata import profile_from_mapping

PROFILE = profile_from_mapping({**load_profile("ev76c661").values, "name": "ev76c661_basler",
                                "gain_range_db": [0.0, 24.0], "driver_gain_range": [0.0, 1.0]})


def _driver_bag(tmp_path, kind: str, src=None, raise_dn: Callable[[int], float] = lambda i: 0.0,
                black_units: Callable[[int], int] = lambda i: 0) -> tuple:
    """A simulated campaign (default: 4 frames) whose metadata topic is re-written as the driver publishes it;
    ``raise_dn(i)``: DN added to image i (a pedestal raised by the operator), ``black_units(i)``: the black level
    the Basler driver reports for it."""
    src = src or simulate_bag(tmp_path / "src.mcap", "ev76c661", "gain_sweep", seed=4, frames=4, width=48, height=32,
                              hold_s=0.2)  # a new gain every frame (0, 8, 16, 24 dB): a conversion's scale shows
    truth = load_truth(src)["frames"]
    store = typestore()
    from msg_adapters.vendor import register_vendor_types

    register_vendor_types(store)
    t = store.types
    dst = tmp_path / f"{kind}.mcap"
    with open_bag(src) as reader, BagWriter(dst, store=store) as w:  # the bag stores the drivers' definitions
        stated = iter(r["true_metadata"] for r in truth)
        frame = meta_i = 0
        for topic, log_time, msg in reader.messages(sorted(reader.topics)):
            if topic == reader.image_topic:
                img = np.frombuffer(msg.data, np.uint8).reshape(msg.height, msg.width)
                raised = np.clip(img + np.float32(raise_dn(frame)), 0, 255).astype(np.uint8)
                w.write(topic, dataclasses.replace(msg, data=raised.ravel()), log_time)
                frame += 1
                continue
            if topic != reader.metadata_topic:
                w.write(topic, msg, log_time)
                continue
            m, meta_i = next(stated), meta_i + 1
            exp_us, gain_db, temp = m["exposure_time_s"] * 1e6, m["gain_db"], m["sensor_temperature_c"]
            if kind in ("flir", "realsense", "realsense_color", "orbbec"):  # these report no temperature: a sensor_msgs/Temperature does
                w.write("/camera/temperature", t["sensor_msgs/msg/Temperature"](
                    header=msg.header, temperature=temp, variance=0.0), log_time)
            if kind == "flir":
                out = t[FLIR](header=msg.header, camera_time=0, brightness=-1, exposure_time=int(round(exp_us)),
                              max_exposure_time=200000, gain=np.float32(gain_db))
                w.write("/flir/meta", out, log_time)
            elif kind == "basler":
                kw = {name: 0 for name, _ in store.fielddefs[BASLER][1]}
                kw.update(reverse_x=False, reverse_y=False, is_sleeping=False, success=True, message="",
                          black_level=black_units(meta_i - 1),
                          exposure=np.float32(exp_us), gain=np.float32(gain_db / 24.0), temperature=np.float32(temp),
                          roi=t["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0,
                                                                    do_rectify=False),
                          available_image_encoding=[], current_image_encoding="", current_image_ros_encoding="",
                          ptp_status="", ptp_servo_status="")
                for name, desc in store.fielddefs[BASLER][1]:
                    if desc[0] == 1 and desc[1][0] in ("float32", "float64"):
                        kw[name] = np.float32(kw[name])
                w.write("/basler/current_params", t[BASLER](**kw), log_time)  # no header: log time
            elif kind == "realsense":  # an infrared stream: actual_exposure in us, valid under auto-exposure
                js = json.dumps({"frame_number": 1, "actual_exposure": int(round(exp_us)),
                                 "gain_level": gain_db / 24.0 * 232 + 16, "auto_exposure": 1, "laser_power": 150})
                header = dataclasses.replace(msg.header, frame_id="camera_infra1_optical_frame")
                w.write("/camera/infra1/metadata", t[REALSENSE](header=header, json_data=js), log_time)
            elif kind == "realsense_color":  # the RGB sensor: actual_exposure in 100 us, auto-exposure off
                js = json.dumps({"frame_number": 1, "actual_exposure": int(round(exp_us / 100)),
                                 "gain_level": gain_db / 24.0 * 232 + 16, "auto_exposure": 0, "white_balance": 4600})
                header = dataclasses.replace(msg.header, frame_id="camera_color_optical_frame")
                w.write("/camera/color/metadata", t[REALSENSE](header=header, json_data=js), log_time)
            elif kind == "orbbec":  # the SDK's frame metadata, exposure in 100 us on the color stream, gain a level
                js = json.dumps({"frame_number": meta_i, "auto_exposure": 0, "exposure": round(exp_us / 100),
                                 "gain": round(gain_db * 10), "white_balance": 4600})  # a level 0..240 (int)
                w.write("/camera/color/metadata", t[ORBBEC](header=msg.header, json_data=js), log_time)
            elif kind.startswith("aravis"):  # camera_aravis2: features published at its own rate (aravis_slow: before
                # every other frame), stamped when published
                kv, sent = t["diagnostic_msgs/msg/KeyValue"], msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec - 3_000_000
                header = t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](
                    sec=sent // 10**9, nanosec=sent % 10**9), frame_id="camera_driver_gv")
                data = [kv(key="ExposureTime", value=f"{exp_us:f}"), kv(key="GainAuto", value="Off"),
                        kv(key="Gain-AnalogAll", value=f"{gain_db - 1.5:f}"), kv(key="Gain-DigitalAll", value="1.500000"),
                        kv(key="DeviceTemperature-Mainboard", value=f"{temp + 12:f}"),
                        kv(key="DeviceTemperature-Sensor", value=f"{temp:f}")]
                if kind == "aravis" or meta_i % 2:
                    w.write("/camera_driver_gv/diagnostics", t[ARAVIS](header=header, data=data), log_time)
            elif kind.startswith("camera_ros"):  # libcamera's metadata among other nodes' diagnostics
                kv, st = t["diagnostic_msgs/msg/KeyValue"], t["diagnostic_msgs/msg/DiagnosticStatus"]
                arr = t["diagnostic_msgs/msg/DiagnosticArray"]
                w.write("/diagnostics", arr(header=msg.header, status=[st(level=0, name="battery", message="",
                        hardware_id="bms", values=[kv(key="voltage", value="12.1")])]), log_time)
                libcamera = [kv(key="AnalogueGain", value=f"{10 ** (gain_db / 20) / 2:.6f}"),
                             kv(key="DigitalGain", value="2.000000"), kv(key="ExposureTime", value=str(round(exp_us))),
                             kv(key="SensorTemperature", value=f"{temp:.6f}")]
                cams = [st(level=0, name="", message="", hardware_id="/base/imx708@1a", values=libcamera)]
                if kind == "camera_ros2":  # a second camera's status first, its own conditions
                    cams.insert(0, st(level=0, name="", message="", hardware_id="/base/imx477@1a", values=[
                        kv(key="AnalogueGain", value="1.0"), kv(key="ExposureTime", value="500")]))
                w.write("/diagnostics", arr(header=msg.header, status=cams), log_time)
            else:  # a driver's own DiagnosticArray key names and units
                kv = t["diagnostic_msgs/msg/KeyValue"]
                status = t["diagnostic_msgs/msg/DiagnosticStatus"](
                    level=0, name="acme_cam", message="", hardware_id="SN123",
                    values=[kv(key="ExposureMs", value=repr(exp_us / 1e3)), kv(key="GainX", value=repr(10 ** (gain_db / 20))),
                            kv(key="SensorTempK", value=repr(temp + 273.15))])
                w.write("/acme/metadata", t["diagnostic_msgs/msg/DiagnosticArray"](header=msg.header, status=[status]),
                        log_time)
    return dst, truth


@pytest.mark.parametrize("kind", ["flir", "basler", "realsense", "realsense_color", "orbbec", "aravis", "aravis_slow",
                                  "keymap", "camera_ros", "camera_ros2"])
def test_driver_metadata_in_bags_gives_the_stated_metadata(tmp_path, kind):
    """Each driver's metadata in a bag gives the stated metadata; camera_ros's on /diagnostics (found there, other
    nodes' arrays left aside), the camera named by hardware_id where two publish there (a clear error without)."""
    bag, truth = _driver_bag(tmp_path, kind)
    camera = {}
    if kind == "camera_ros2":
        with open_bag(bag) as reader, pytest.raises(BagError, match=r"/diagnostics carries the libcamera metadata of "
                                                                    r"several cameras \(/base/imx477@1a, /base/imx708@1a"):
            next(reader.frames(PROFILE))
        camera = {"hardware_id": "/base/imx708@1a"}
    profile = PROFILE
    if kind in ("realsense", "realsense_color", "orbbec"):
        profile = profile_from_mapping({**load_profile("ev76c661").values, "gain_range_db": [0.0, 24.0],
                                        "driver_gain_range": [0, 240] if kind == "orbbec" else [16, 248]})
    keymap = ["acme_cam|ExposureMs|exposure_time_s|ms", "*|GainX|gain_db|factor",
              "acme_cam|SensorTempK|sensor_temperature_c|K"] if kind == "keymap" else None
    if kind == "orbbec":
        keymap = ["*|exposure|exposure_time_s|100us", "*|gain|gain_db|relative"]
        with open_bag(bag) as reader:  # its units differ by sensor: read through a key map, asked for without one
            first = next(reader.frames(profile))
        assert "Orbbec frame metadata is read through metadata_keymap" in first.skip_reason
    with open_bag(bag) as reader:
        frames = list(reader.frames(profile, metadata_keymap=keymap, **camera))
        if kind.startswith("aravis"):  # stamped 3 ms before an image: the latest at or before it, its age not judged
            assert reader.metadata_topic == "/camera_driver_gv/diagnostics"
            assert all(f.metadata_age_s is None for f in frames)
    if kind == "aravis_slow":  # published before every other frame: the frames between hold the values before them
        truth = [truth[i - i % 2] for i in range(len(truth))]
        if kind.startswith("camera_ros"):
            assert reader.metadata_topic == "/diagnostics"
            assert reader.hardware_id() == (None if camera else "/base/imx708@1a")
    assert len(frames) == 4 and len({r["true_metadata"]["gain_db"] for r in truth}) == (2 if kind == "aravis_slow" else 4)
    for f, r in zip(frames, truth):
        assert f.skip_reason is None, f.skip_reason
        m = r["true_metadata"]
        assert f.metadata.exposure_time_s == pytest.approx(m["exposure_time_s"], abs=1e-6)
        assert f.metadata.gain_db == pytest.approx(m["gain_db"], abs=1e-4)
        assert f.metadata.sensor_temperature_c == pytest.approx(m["sensor_temperature_c"], abs=1e-4)


def test_driver_messages_with_bad_fields_name_them():
    ns = SimpleNamespace
    flir = type("ImageMetaData", (), {"__msgtype__": FLIR})
    with pytest.raises(AdapterError, match="exposure_time = 0 us is not a valid exposure"):
        metadata_from_vendor(ns(__msgtype__=FLIR, exposure_time=0, gain=3.0))
    basler = dict(__msgtype__=BASLER, exposure=1000.0, gain=0.5, temperature=40.0, success=True, message="",
                  black_level=0)
    with pytest.raises(AdapterError, match="gain_range_db"):
        metadata_from_vendor(ns(**basler))  # no profile: a relative gain cannot be converted
    with pytest.raises(AdapterError, match="gain = 1.5 is outside the driver's gain range"):
        metadata_from_vendor(ns(**{**basler, "gain": 1.5}), PROFILE)
    assert metadata_from_vendor(ns(**{**basler, "gain": 1.0 + 1e-7}), PROFILE)["gain_db"] == 24.0  # rounding: the end
    with pytest.raises(AdapterError, match="exposure = -10000 \\(not available"):
        metadata_from_vendor(ns(**{**basler, "exposure": -10000.0}), PROFILE)
    with pytest.raises(AdapterError, match="success = false \\(camera busy\\)"):
        metadata_from_vendor(ns(**{**basler, "success": False, "message": "camera busy"}), PROFILE)
    assert metadata_from_vendor(ns(**{**basler, "temperature": 0.0}), PROFILE) == {
        "exposure_time_s": pytest.approx(1e-3), "gain_db": pytest.approx(12.0)}  # 0.0 degC = not reported
    with pytest.raises(AdapterError, match="json_data is not JSON"):
        metadata_from_vendor(ns(__msgtype__=REALSENSE, json_data="{oops"), PROFILE)
    with pytest.raises(AdapterError, match="neither actual_exposure nor gain_level"):
        metadata_from_vendor(ns(__msgtype__=REALSENSE, json_data='{"frame_number": 3}'), PROFILE)
    # the colour stream counts in 100 us (librealsense#8243; read as us until 2026-12-04: 100x too short) and does
    # not update actual_exposure under its auto-exposure (librealsense#2549), told by its frame_id or colour keys
    colour = ns(frame_id="camera_color_optical_frame")
    assert metadata_from_vendor(ns(__msgtype__=REALSENSE, header=colour, json_data='{"actual_exposure": 200}'),
                                PROFILE) == {"exposure_time_s": pytest.approx(0.02)}
    assert metadata_from_vendor(ns(__msgtype__=REALSENSE, json_data='{"actual_exposure": 200, "hue": 0}'),
                                PROFILE) == {"exposure_time_s": pytest.approx(0.02)}
    assert metadata_from_vendor(ns(__msgtype__=REALSENSE, header=ns(frame_id="camera_depth_optical_frame"),
                                   json_data='{"actual_exposure": 200, "auto_exposure": 1}'),
                                PROFILE) == {"exposure_time_s": pytest.approx(200e-6)}
    with pytest.raises(AdapterError, match="colour stream under auto-exposure"):
        metadata_from_vendor(ns(__msgtype__=REALSENSE, header=colour,
                                json_data='{"actual_exposure": 200, "auto_exposure": 1}'), PROFILE)
    assert flir


def test_orbbec_json_metadata_through_a_key_map():
    """Orbbec's frame metadata (JSON) through the key map: 100 us exposure units, a gain level over the profile's range;
    JSON that is no object or lacks the mapped keys is named."""
    ns = SimpleNamespace
    km = parse_keymap(["*|exposure|exposure_time_s|100us", "*|gain|gain_db|relative"])
    profile = dataclasses.replace(PROFILE, driver_gain_range=(16.0, 248.0))
    msg = ns(__msgtype__=ORBBEC, json_data='{\n  "exposure": 200,\n  "gain": 132,\n  "frame_number": 7\n}')
    assert metadata_from_json_keymap(msg, km, profile) == {"exposure_time_s": pytest.approx(0.02),
                                                          "gain_db": pytest.approx(12.0)}
    with pytest.raises(AdapterError, match=r"none of the mapped keys \(exposure, gain; keys: frame_number\)"):
        metadata_from_json_keymap(ns(json_data='{"frame_number": 7}'), km, profile)
    with pytest.raises(AdapterError, match="json_data is not a JSON object"):
        metadata_from_json_keymap(ns(json_data="[1, 2]"), km, profile)
    with pytest.raises(AdapterError, match="Orbbec frame metadata is read through metadata_keymap"):
        metadata_from_json_keymap(msg, [], profile)


def test_aravis_diagnostics_conversion():
    """camera_aravis2's CameraDiagnostics: GenICam SFNC features as key/values (``Feature-Selector`` with a selector):
    exposure us, the overall gain in dB (All, else analog + digital, else GainAbs, else GainRaw through the profile's
    ranges), the sensor's temperature (not the mainboard's), BlackLevel through driver_black_level_dn."""
    ns = SimpleNamespace

    def meta(profile=PROFILE, **values):
        return metadata_from_vendor(ns(__msgtype__=ARAVIS, data=[ns(key=k.replace("_", "-"), value=v)
                                                                  for k, v in values.items()]), profile)

    assert meta(ExposureTime="20000.000000", Gain="6.000000", DeviceTemperature="41.5") == {
        "exposure_time_s": pytest.approx(0.02), "gain_db": pytest.approx(6.0), "sensor_temperature_c": pytest.approx(41.5)}
    assert meta(ExposureTimeAbs="500", Gain_AnalogAll="4.5", Gain_DigitalAll="2.0",
                DeviceTemperature_Mainboard="55.0") == {"exposure_time_s": pytest.approx(5e-4), "gain_db": pytest.approx(6.5)}
    assert meta(Gain_All="3.0", Gain_AnalogAll="9.0")["gain_db"] == pytest.approx(3.0)  # the overall gain first
    assert meta(GainAbs="12.0")["gain_db"] == pytest.approx(12.0)
    raw = dataclasses.replace(PROFILE, driver_gain_range=(0.0, 1023.0))
    assert meta(raw, GainRaw="511.5")["gain_db"] == pytest.approx(12.0)  # 0..1023 over 0..24 dB
    with pytest.raises(AdapterError, match="GainRaw = 511.5 is a relative gain: the camera profile needs gain_range_db"):
        meta(None, GainRaw="511.5")
    with pytest.raises(AdapterError, match="no overall gain, only Gain-Blue, Gain-Red: list Gain with the selector All"):
        meta(ExposureTime="100", Gain_Red="1.0", Gain_Blue="2.0")
    with pytest.raises(AdapterError, match=r"neither ExposureTime nor Gain \(keys: DeviceTemperature-Sensor, PtpStatus\)"):
        meta(DeviceTemperature_Sensor="40.0", PtpStatus="Slave")
    with pytest.raises(AdapterError, match="ExposureTime = -5 us is not a valid exposure"):
        meta(ExposureTime="-5.000000")
    with pytest.raises(AdapterError, match="Gain = 'x' is not a number"):
        meta(Gain="x")
    with pytest.raises(AdapterError, match="BlackLevel = 64 is in the camera's units: the camera profile needs "
                                           "driver_black_level_dn"):
        meta(Gain="0.0", BlackLevel="64")
    pedestal = dataclasses.replace(PROFILE, driver_black_level_dn=0.25)
    assert meta(pedestal, Gain="0.0", BlackLevel_All="64")["black_level_dn"] == pytest.approx(16.0)


def test_the_bundled_camera_aravis2_diagnostics_config_gives_what_the_monitor_reads():
    """config/camera_aravis2_diagnostics.yaml, published as camera_aravis2 names its features (``Feature`` or
    ``Feature-SelectorValue``), gives exposure, gain, temperature and black level."""
    import yaml

    from noise_monitor.paths import share_dir

    features = yaml.safe_load((share_dir() / "config" / "camera_aravis2_diagnostics.yaml").read_text())
    keys = [f["FeatureName"] + "".join(f"-{s['Value']}" for s in f.get("Selectors", [])[:1]) for f in features]
    value = {"ExposureTime": "8000.000000", "Gain": "12.000000", "DeviceTemperature": "47.250000", "BlackLevel": "32.0"}
    msg = SimpleNamespace(__msgtype__=ARAVIS, data=[SimpleNamespace(key=k, value=value[k.split("-")[0]]) for k in keys])
    assert metadata_from_vendor(msg, dataclasses.replace(PROFILE, driver_black_level_dn=0.25)) == {
        "exposure_time_s": pytest.approx(0.008), "gain_db": pytest.approx(12.0),
        "sensor_temperature_c": pytest.approx(47.25), "black_level_dn": pytest.approx(8.0)}


def test_camera_ros_metadata_conversion():
    """camera_ros's libcamera status: ExposureTime (us), AnalogueGain x DigitalGain (dB), SensorTemperature; an
    array without one (another node's), or with only another camera's when an id is asked for, is None; a bad value
    is named."""
    ns, kv = SimpleNamespace, lambda k, v: SimpleNamespace(key=k, value=v)  # noqa: E731
    cam = ns(name="", hardware_id="imx708", values=[kv("AnalogueGain", "4.000000"), kv("DigitalGain", "1.000000"),
                                                    kv("ExposureTime", "20000"), kv("SensorTemperature", "47.5")])
    other = ns(name="", hardware_id="ov5647", values=[kv("AnalogueGain", "1.0"), kv("ExposureTime", "100")])
    battery = ns(name="battery", hardware_id="bms", values=[kv("voltage", "12.1")])
    msg = ns(status=[battery, cam])
    assert metadata_from_camera_ros(msg) == {"exposure_time_s": pytest.approx(0.02), "gain_db": pytest.approx(12.0412),
                                             "raw_gain_db": pytest.approx(12.0412), "sensor_temperature_c": 47.5}
    assert metadata_from_camera_ros(ns(status=[battery])) is None and metadata_from_camera_ros(ns(status=[])) is None
    assert metadata_from_camera_ros(ns(status=[other, cam]))["exposure_time_s"] == pytest.approx(1e-4)  # the first
    assert metadata_from_camera_ros(ns(status=[other, cam]), "imx708")["exposure_time_s"] == pytest.approx(0.02)
    assert metadata_from_camera_ros(ns(status=[other]), "imx708") is None
    no_temp = ns(name="", hardware_id="", values=[kv("ExposureTime", "100")])
    assert metadata_from_camera_ros(ns(status=[no_temp])) == {"exposure_time_s": pytest.approx(1e-4)}
    for key, value, what in (("AnalogueGain", "0.0", "a positive number"), ("DigitalGain", "nan", "a positive number"),
                             ("SensorTemperature", "hot", None)):
        bad = ns(name="", hardware_id="", values=[kv(k.key, value if k.key == key else k.value) for k in cam.values])
        match = f"camera_ros metadata {key} = '{value}' is not " + (what or "a number")
        with pytest.raises(AdapterError, match=match):
            metadata_from_camera_ros(ns(status=[bad]))


def test_camera_ros_gain_and_black_level_of_a_raw_bayer_image_leave_out_the_isp():
    """AnalogueGain 4 x DigitalGain 2: a processed (mono8) image's gain is 18.06 dB, a raw Bayer image's (the sensor's
    output, before the ISP) 12.04 dB; the SensorBlackLevels' green sites (16-bit scale) come off the raw image alone,
    the ISP having taken them off its output; other drivers' gain is taken as it is for both."""
    from msg_adapters import prepare_frame
    from noise_monitor.monitor.runtime import FrameOptions

    kv, ns = lambda k, v: SimpleNamespace(key=k, value=v), SimpleNamespace  # noqa: E731
    values = [kv("AnalogueGain", "4.0"), kv("DigitalGain", "2.0"), kv("ExposureTime", "10000"),
              kv("SensorBlackLevels", "[ 4096, 4000, 4200, 4096 ]"), kv("SensorTemperature", "40.0")]
    meta = metadata_from_camera_ros(ns(status=[ns(name="", hardware_id="imx477", values=values)]))
    options = FrameOptions(load_profile("ev76c661"), None, "luma", None)
    pedestal = 4100 * 255 / 65535  # 15.95 DN: a 12-bit sensor's 256 codes

    def frame_of(encoding: str, metadata: dict):
        data = bytes(range(40, 56))
        img = ns(header=None, height=4, width=4, step=4, encoding=encoding, is_bigendian=0, data=data)
        frame = prepare_frame(img, 1, options, metadata=metadata)
        assert frame.metadata is not None, (frame.image_error, frame.metadata_error, frame.missing)
        assert frame.raw_metadata["gain_db"] == pytest.approx(frame.metadata.gain_db)  # what characterize reads
        return frame

    processed, bayer = frame_of("mono8", meta), frame_of("bayer_rggb8", meta)
    assert processed.metadata.gain_db == pytest.approx(18.0618, abs=1e-4)
    assert bayer.metadata.gain_db == pytest.approx(12.0412, abs=1e-4)
    assert (processed.black_level_dn, processed.black_level_source) == (0.0, "profile")
    assert (bayer.black_level_dn, bayer.black_level_source) == (pytest.approx(pedestal), "metadata")
    assert bayer.image_dn[0, 0] == pytest.approx(41 - pedestal)  # the green site of the first 2x2 cell (R G / G B)
    plain = {k: v for k, v in meta.items() if not k.startswith("raw_")}
    assert frame_of("bayer_rggb8", plain).metadata.gain_db == pytest.approx(18.0618, abs=1e-4)
    assert frame_of("bayer_rggb8", plain).black_level_dn == 0.0
    for bad in ("[ 4096, 4096 ]", "4096", "[ 4096, -1, 4096, 4096 ]", "[ a, b, c, d ]"):
        with pytest.raises(AdapterError, match=r"SensorBlackLevels = .* is not four levels \(R, Gr, Gb, B\)"):
            metadata_from_camera_ros(ns(status=[ns(name="", hardware_id="imx477", values=[
                kv("ExposureTime", "10000"), kv("SensorBlackLevels", bad)])]))


def test_the_bit_depth_a_frames_metadata_states_scales_its_16_bit_image():
    """12-bit data in mono16 with metadata bit_depth 12: the image is read on the 12-bit scale, as --bit-depth 12 reads
    it (until 2026-12-04 the metadata's bit depth went into the model but the image was scaled by the profile's: an
    8-bit profile refused every frame, none scaled it as 16-bit and read frames as black); a stated bit depth wins."""
    from types import SimpleNamespace

    from msg_adapters import prepare_frame
    from noise_monitor.monitor.runtime import FrameOptions

    values = np.array([[100, 2000], [4095, 0]], dtype="<u2")
    img = SimpleNamespace(header=None, height=2, width=2, step=4, encoding="mono16", is_bigendian=0,
                          data=values.tobytes())
    meta = {"gain_db": 6.0, "exposure_time_s": 0.01, "sensor_temperature_c": 30.0}
    profile = load_profile("ev76c661")  # 8 bit
    by_metadata = prepare_frame(img, 1, FrameOptions(profile), metadata={**meta, "bit_depth": 12})
    stated = prepare_frame(img, 1, FrameOptions(profile, 12), metadata=meta)
    np.testing.assert_allclose(by_metadata.image_dn, values * 255.0 / 4095.0, rtol=1e-6)
    np.testing.assert_array_equal(by_metadata.image_dn, stated.image_dn)
    assert by_metadata.metadata is not None and by_metadata.metadata.bit_depth == 12
    profile_only = prepare_frame(img, 1, FrameOptions(profile), metadata=meta)
    assert profile_only.image_dn is None and "8-bit" in profile_only.image_error
    overruled = prepare_frame(img, 1, FrameOptions(profile, 16), metadata={**meta, "bit_depth": 12})
    np.testing.assert_allclose(overruled.image_dn, values * 255.0 / 65535.0, rtol=1e-6)


def test_keymap_validation_and_conversion():
    with pytest.raises(ValueError, match="unknown field 'gain'"):
        parse_keymap(["cam|Gain|gain|dB"])
    with pytest.raises(ValueError, match="unit 'us' is not one of db, factor, relative"):
        parse_keymap(["cam|Gain|gain_db|us"])
    with pytest.raises(ValueError, match="scale must be a positive"):
        parse_keymap(["cam|Exp|exposure_time_s|us|-2"])
    with pytest.raises(ValueError, match="must be 'STATUS\\|KEY"):
        parse_keymap(["cam|Exp"])
    km = parse_keymap(["cam|Exp|exposure_time_s|us|10", "*|T|sensor_temperature_c|K"])
    kv = lambda k, v: SimpleNamespace(key=k, value=v)  # noqa: E731
    msg = SimpleNamespace(status=[SimpleNamespace(name="other", values=[kv("Exp", "1")]),
                                  SimpleNamespace(name="cam", values=[kv("Exp", "250"), kv("T", "300.15")])])
    assert metadata_from_keymap(msg, km) == {"exposure_time_s": pytest.approx(2.5e-3),
                                             "sensor_temperature_c": pytest.approx(27.0)}
    bad = SimpleNamespace(status=[SimpleNamespace(name="cam", values=[kv("Exp", "fast")])])
    with pytest.raises(AdapterError, match="cam/Exp = 'fast' is not a number"):
        metadata_from_keymap(bad, km)
    with pytest.raises(AdapterError, match="none of the mapped keys"):
        metadata_from_keymap(SimpleNamespace(status=[]), km)


def test_profile_gain_range_is_validated():
    with pytest.raises(MetadataError, match="gain_range_db must be \\[low, high\\]"):
        profile_from_mapping({"gain_range_db": [24.0, 0.0]})
    with pytest.raises(MetadataError, match="driver_gain_range must be a list"):
        profile_from_mapping({"driver_gain_range": "wide"})
    assert profile_from_mapping({"gain_range_db": [0, 36]}).gain_range_db == (0.0, 36.0)


def test_parameter_events_of_the_driver_node_only():
    from rcl_interfaces.msg import Parameter, ParameterEvent, ParameterType, ParameterValue

    ev = ParameterEvent(node="/cam/v4l2_camera", changed_parameters=[
        Parameter(name="exposure_time_absolute", value=ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=156)),
        Parameter(name="gain", value=ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=1)),
        Parameter(name="brightness", value=ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=7))])
    assert parameter_values(ev, "/other/node") is None
    values = parameter_values(ev, "/cam/v4l2_camera")
    assert values == {"exposure_time_absolute": 156, "gain": 1, "brightness": 7}
    profile = profile_from_mapping({"gain_range_db": [0.0, 24.0], "driver_gain_range": [0, 4]})
    assert metadata_from_parameters(values, preset_keymap("v4l2_camera"), profile) == {
        "exposure_time_s": pytest.approx(0.0156), "gain_db": pytest.approx(6.0)}
    with pytest.raises(ValueError, match="no parameter preset for driver 'ids'"):
        preset_keymap("ids")
    # under the camera's auto-exposure the exposure parameter is the manual setting (until 2026-12-04 read as the
    # frame's): v4l2_camera's auto_exposure 0 / 3 and usb_cam's autoexposure (its default) are refused
    with pytest.raises(AdapterError, match="v4l2_camera auto_exposure = 3: the camera's auto-exposure"):
        metadata_from_parameters({**values, "auto_exposure": 3}, preset_keymap("v4l2_camera"), profile, "v4l2_camera")
    assert metadata_from_parameters({**values, "auto_exposure": 1}, preset_keymap("v4l2_camera"), profile,
                                    "v4l2_camera")["exposure_time_s"] == pytest.approx(0.0156)  # manual
    usb = {"autoexposure": False, "exposure": 100, "gain": 2}
    assert metadata_from_parameters(usb, preset_keymap("usb_cam"), profile, "usb_cam") == {
        "exposure_time_s": pytest.approx(0.01), "gain_db": pytest.approx(12.0)}
    with pytest.raises(AdapterError, match="usb_cam autoexposure = True"):
        metadata_from_parameters({**usb, "autoexposure": True}, preset_keymap("usb_cam"), profile, "usb_cam")
    # gain -1: the device's own gain, not reported (the profile's applies; was an error: -1 outside the gain range)
    assert metadata_from_parameters({**usb, "gain": -1}, preset_keymap("usb_cam"), profile, "usb_cam") == {
        "exposure_time_s": pytest.approx(0.01)}


def test_the_basler_drivers_black_level_converted_by_the_profile():
    ns = SimpleNamespace
    basler = dict(__msgtype__=BASLER, exposure=1000.0, gain=0.5, temperature=40.0, success=True, message="")
    scaled = dataclasses.replace(PROFILE, driver_black_level_dn=0.0625)  # BlackLevelRaw at Mono8: 16 per DN
    assert metadata_from_vendor(ns(**basler, black_level=256), scaled)["black_level_dn"] == pytest.approx(16.0)
    assert "black_level_dn" not in metadata_from_vendor(ns(**basler, black_level=-10000), scaled)  # none: profile's
    assert "black_level_dn" not in metadata_from_vendor(ns(**basler, black_level=0), PROFILE)  # 0 in any unit
    with pytest.raises(AdapterError, match="black_level = 256 is in the camera's units: the camera profile needs "
                                           "driver_black_level_dn"):
        metadata_from_vendor(ns(**basler, black_level=256), PROFILE)
    stated = dataclasses.replace(PROFILE, black_level_dn=16.0)  # a stated black level stands without a conversion
    assert "black_level_dn" not in metadata_from_vendor(ns(**basler, black_level=256), stated)
    with pytest.raises(AdapterError, match="black_level = 4096 DN is not a black level on the 8-bit scale"):
        metadata_from_vendor(ns(**basler, black_level=4096), dataclasses.replace(PROFILE, driver_black_level_dn=1.0))
    with pytest.raises(MetadataError, match="driver_black_level_dn must be a number > 0"):
        profile_from_mapping({"driver_black_level_dn": 0})
    assert profile_from_mapping({"driver_black_level_dn": 0.25}).driver_black_level_dn == 0.25
    km = parse_keymap(["cam|BlackLevel|black_level_dn|dn12"])  # a 12-bit camera's 256 codes
    msg = ns(status=[ns(name="cam", values=[ns(key="BlackLevel", value="256")])])
    assert metadata_from_keymap(msg, km) == {"black_level_dn": pytest.approx(256 * 255 / 4095)}


def test_a_black_level_the_operator_raises_follows_the_drivers_metadata(tmp_path):
    """A pedestal camera (16 DN) whose black level the operator raises to 40 DN at frame 12 of a held-out campaign
    (inside a still hold), its Basler driver reporting BlackLevelRaw (16 per DN). With the conversion in the profile
    every frame reads as the same camera at a constant 16 DN does (per-frame xi to 1e-4 DN but where it saturates)
    and the lab cuts the hold there; with the profile's static 16 DN the raised frames read 24 DN of pedestal as
    signal (xi +0.07 and +0.25 DN on the two measured from the image, at ~20 DN of noise, 2026-11-29); without the
    conversion or a stated black level the driver's value is refused per frame, named."""
    import torch

    from noise_monitor.bag.replay import replay
    from noise_monitor.estimator import load

    torch.set_num_threads(1)
    STEP = 12  # inside a still hold (frames 11-13)
    base = dataclasses.replace(PROFILE, name="EV76C661 pedestal", black_level_dn=16.0)
    src = simulate_bag(tmp_path / "ped.mcap", base, "campaign_heldout", frames=16, width=192, height=128,
                       fps=10.0, seed=33)
    bag, _ = _driver_bag(tmp_path, "basler", src=src, raise_dn=lambda i: 24.0 * (i >= STEP),
                         black_units=lambda i: 256 + 384 * (i >= STEP))
    kw = {"estimator": load("full_meta", device="cpu"), "progress": False, "plot": False}

    def xi(out_dir):  # per frame; NaN where no patch was measurable (xi from the image's bound)
        rows = list(csv.DictReader((out_dir / "replay.csv").open()))
        return np.array([float(r["xi"]) if r["xi_measurement"] == "image" else np.nan for r in rows])

    constant = replay(src, base, tmp_path / "constant", **kw)
    followed = replay(bag, dataclasses.replace(base, black_level_dn=0.0, driver_black_level_dn=0.0625),
                      tmp_path / "followed", metadata_topic="/basler/current_params", **kw)
    static = replay(bag, base, tmp_path / "static", metadata_topic="/basler/current_params", **kw)
    assert constant["frames_processed"] == followed["frames_processed"] == static["frames_processed"] == 16
    a, b, c = xi(tmp_path / "constant"), xi(tmp_path / "followed"), xi(tmp_path / "static")
    # the raised camera saturates 24 DN lower: one frame's bright patch is left out there (0.048 DN)
    assert np.isfinite(a).sum() >= 12 and np.array_equal(np.isnan(a), np.isnan(b))
    assert np.nansum(np.abs(b - a) > 1e-4) <= 1 and np.nanmax(np.abs(b - a)) <= 0.06
    assert np.nanmax(np.abs(c[:STEP] - a[:STEP])) <= 1e-4 and np.nanmean(c[STEP:] - a[STEP:]) >= 0.1
    rows = list(csv.DictReader((tmp_path / "followed" / "replay.csv").open()))
    assert [float(r["black_level_dn"]) for r in rows] == [16.0] * STEP + [40.0] * (16 - STEP)
    from noise_monitor.lab.measure import measure_frames

    followed_profile = dataclasses.replace(base, black_level_dn=0.0, driver_black_level_dn=0.0625)
    with open_bag(bag, metadata_topic="/basler/current_params") as reader:  # the lab: no hold across the change
        held = [seg.frames for seg in measure_frames(reader.frames(followed_profile)).segments]
    assert held and all(max(f) < STEP or min(f) >= STEP for f in held)  # frames 11-13 were one hold
    refused = replay(bag, dataclasses.replace(base, black_level_dn=0.0), None, metadata_topic="/basler/current_params",
                     **kw)
    assert refused["frames_processed"] == 0  # 256 units at frame 0 already: no conversion, no stated level
    assert "driver_black_level_dn" in next(iter(refused["skip_reasons"]))
