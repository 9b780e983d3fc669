"""Camera drivers' metadata: FLIR, Basler, RealSense messages in bags written with the drivers' definitions,
a generic DiagnosticArray key map and parameter events (v4l2_camera / usb_cam)."""
from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from msg_adapters import AdapterError
from msg_adapters.keymap import metadata_from_keymap, parse_keymap
from msg_adapters.parameter_events import metadata_from_parameters, parameter_values, preset_keymap
from msg_adapters.vendor import BASLER, FLIR, REALSENSE, metadata_from_vendor
from noise_monitor.bag.reader import open_bag
from noise_monitor.bag.simulate import load_truth, simulate_bag
from noise_monitor.bag.writer import BagWriter, typestore
from noise_monitor.physics import MetadataError, load_profile
from noise_monitor.physics.metadata import profile_from_mapping

PROFILE = profile_from_mapping({**load_profile("ev76c661").values, "name": "ev76c661_basler",
                                "gain_range_db": [0.0, 24.0], "driver_gain_range": [0.0, 1.0]})


def _driver_bag(tmp_path, kind: str) -> tuple:
    """A simulated 4-frame campaign whose metadata topic is re-written as the driver publishes it."""
    src = simulate_bag(tmp_path / "src.mcap", "ev76c661", "gain_sweep", seed=4, frames=4, width=48, height=32)
    truth = load_truth(src)["frames"]
    store = typestore()
    from msg_adapters.vendor import register_vendor_types

    register_vendor_types(store)
    t = store.types
    dst = tmp_path / f"{kind}.mcap"
    with open_bag(src) as reader, BagWriter(dst, store=store) as w:  # the bag stores the drivers' definitions
        stated = iter(r["true_metadata"] for r in truth)
        for topic, log_time, msg in reader.messages(sorted(reader.topics)):
            if topic != reader.metadata_topic:
                w.write(topic, msg, log_time)
                continue
            m = next(stated)
            exp_us, gain_db, temp = m["exposure_time_s"] * 1e6, m["gain_db"], m["sensor_temperature_c"]
            if kind in ("flir", "realsense"):  # these report no temperature: a sensor_msgs/Temperature does
                w.write("/camera/temperature", t["sensor_msgs/msg/Temperature"](
                    header=msg.header, temperature=temp, variance=0.0), log_time)
            if kind == "flir":
                out = t[FLIR](header=msg.header, camera_time=0, brightness=-1, exposure_time=int(round(exp_us)),
                              max_exposure_time=200000, gain=np.float32(gain_db))
                w.write("/flir/meta", out, log_time)
            elif kind == "basler":
                kw = {name: 0 for name, _ in store.fielddefs[BASLER][1]}
                kw.update(reverse_x=False, reverse_y=False, is_sleeping=False, success=True, message="",
                          exposure=np.float32(exp_us), gain=np.float32(gain_db / 24.0), temperature=np.float32(temp),
                          roi=t["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0,
                                                                    do_rectify=False),
                          available_image_encoding=[], current_image_encoding="", current_image_ros_encoding="",
                          ptp_status="", ptp_servo_status="")
                for name, desc in store.fielddefs[BASLER][1]:
                    if desc[0] == 1 and desc[1][0] in ("float32", "float64"):
                        kw[name] = np.float32(kw[name])
                w.write("/basler/current_params", t[BASLER](**kw), log_time)  # no header: log time
            elif kind == "realsense":
                js = json.dumps({"frame_number": 1, "actual_exposure": int(round(exp_us)),
                                 "gain_level": gain_db / 24.0 * 232 + 16, "auto_exposure": 1})
                w.write("/camera/color/metadata", t[REALSENSE](header=msg.header, json_data=js), log_time)
            else:  # a driver's own DiagnosticArray key names and units
                kv = t["diagnostic_msgs/msg/KeyValue"]
                status = t["diagnostic_msgs/msg/DiagnosticStatus"](
                    level=0, name="acme_cam", message="", hardware_id="SN123",
                    values=[kv(key="ExposureMs", value=repr(exp_us / 1e3)), kv(key="GainX", value=repr(10 ** (gain_db / 20))),
                            kv(key="SensorTempK", value=repr(temp + 273.15))])
                w.write("/acme/metadata", t["diagnostic_msgs/msg/DiagnosticArray"](header=msg.header, status=[status]),
                        log_time)
    return dst, truth


@pytest.mark.parametrize("kind", ["flir", "basler", "realsense", "keymap"])
def test_driver_metadata_in_bags_gives_the_stated_metadata(tmp_path, kind):
    bag, truth = _driver_bag(tmp_path, kind)
    profile = PROFILE
    if kind == "realsense":
        profile = profile_from_mapping({**load_profile("ev76c661").values, "gain_range_db": [0.0, 24.0],
                                        "driver_gain_range": [16, 248]})
    keymap = ["acme_cam|ExposureMs|exposure_time_s|ms", "*|GainX|gain_db|factor",
              "acme_cam|SensorTempK|sensor_temperature_c|K"] if kind == "keymap" else None
    with open_bag(bag) as reader:
        frames = list(reader.frames(profile, metadata_keymap=keymap))
    assert len(frames) == 4
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
    basler = dict(__msgtype__=BASLER, exposure=1000.0, gain=0.5, temperature=40.0, success=True, message="")
    with pytest.raises(AdapterError, match="gain_range_db"):
        metadata_from_vendor(ns(**basler))  # no profile: a relative gain cannot be converted
    with pytest.raises(AdapterError, match="gain = 1.5 is outside the driver's gain range"):
        metadata_from_vendor(ns(**{**basler, "gain": 1.5}), PROFILE)
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
    assert flir


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
