"""config/analyzers.yaml groups every camera's noise status for diagnostic_aggregator."""
from __future__ import annotations

import yaml

from noise_monitor.estimator import load
from noise_monitor.monitor import Monitor, MonitorConfig
from noise_monitor.paths import share_dir
from noise_monitor.physics import NoiseModel


def test_analyzers_match_the_monitor_status_names():
    group = yaml.safe_load((share_dir() / "config" / "analyzers.yaml").read_text())["analyzers"]["ros__parameters"][
        "camera_noise"]
    assert group["type"] == "diagnostic_aggregator/GenericAnalyzer"
    status = Monitor(MonitorConfig(), load("full_meta", device="cpu"), NoiseModel(), "left_cam", "cam-1").name
    assert any(status.startswith(p) for p in group["startswith"])
    assert status.removeprefix(group["remove_prefix"][0]) == "left_cam"
    assert group["timeout"] > MonitorConfig().image_timeout_s  # the node reports STALE itself first
