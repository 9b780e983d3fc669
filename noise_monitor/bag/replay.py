"""Replay a bag through the monitor pipeline (the node's code), faster than real time.

Every image is accounted for: processed, or skipped with the monitor's reason (image unusable, metadata
missing/invalid/stale, too few usable patches, ...). The node's behaviour is reproduced on bag time:
same model (profile effects included), same hardware id, same reject path for unusable images, and
the periodic ``/diagnostics`` idle report (STALE after ``image_timeout_s``) in gaps between images.
Outputs in ``out_dir``: ``replay.mcap`` with exactly the node's topics
(``msg_adapters.outputs``), ``replay.csv`` (one line per frame), ``replay.png`` and
``summary.json``.
"""
from __future__ import annotations

import json
import os
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from noise_monitor.monitor import Frame, FrameResult, Monitor, MonitorConfig
from noise_monitor.monitor.config import read_ros_params
from noise_monitor.monitor.status import LEVEL_NAMES
from msg_adapters.outputs import DEFAULT_NAMESPACE, output_topics, rosbags_messages
from noise_monitor.physics import CameraProfile, NoiseModel, load_profile

from .errors import BagError
from .plot import plot_replay
from .reader import BagFrame, open_bag
from .results import (CONDITION_KEYS, FrameTable, alarm_episodes, skip_reasons, skipped_frames, source_summaries,
                      truth_check, write_csv)
from .simulate import truth_path
from .writer import BagWriter, typestore

#: Skipped frames listed one by one in the summary (the counts per reason and the CSV cover all).
MAX_LISTED_SKIPS = 1000
OUTPUT_FILES = {"mcap": "replay.mcap", "csv": "replay.csv", "png": "replay.png", "json": "summary.json"}


def _settings(config: MonitorConfig | str | Path | None) -> tuple[MonitorConfig, dict[str, Any]]:
    """Monitor config and the node parameters (params file: default config/node.yaml)."""
    if isinstance(config, MonitorConfig):
        return config, {}
    params = read_ros_params(config)
    return MonitorConfig.from_mapping(params, ignore_unknown=True), params


def _record(table: FrameTable, bf: BagFrame, res: FrameResult) -> None:
    meta = bf.metadata
    table.append(index=bf.index, stamp_ns=res.stamp_ns, processed=res.processed, level=res.level,
                 alarm_active=res.alarm_active, alarm_state=res.alarm_state, cause=res.cause,
                 skip_reason=res.skip_reason, numbers=res.numeric(),
                 conditions={k: getattr(meta, k) for k in CONDITION_KEYS} if meta else {})


def evaluate(monitor: Monitor, bf: BagFrame) -> FrameResult:
    """One bag frame through the monitor exactly as the node's worker does it."""
    if bf.image_dn is None:
        return monitor.reject(bf.stamp_ns, bf.skip_reason or "image unusable")
    return monitor.process(Frame(stamp_ns=bf.stamp_ns, image_dn=bf.image_dn, metadata=bf.metadata,
                                 missing=list(bf.missing), metadata_age_s=bf.metadata_age_s,
                                 metadata_error=bf.metadata_error))


def set_inference_threads(threads: int) -> None:
    """torch intra-op threads: ``threads``, or all cores but one when 0 (the node's rule)."""
    import torch

    if threads < 0:
        raise ValueError(f"threads must be >= 0, got {threads}")
    torch.set_num_threads(threads or max(1, (os.cpu_count() or 2) - 1))


def _truth_episodes(bag: str | Path) -> list[dict[str, Any]] | None:
    """Corruption episodes of a simulated bag's truth sidecar; None for recorded bags (or unreadable truth)."""
    p = truth_path(bag)
    if not p.is_file():
        return None
    def light(d: dict[str, Any]) -> dict[str, Any] | None:  # per-frame records are dropped while parsing
        return None if "index" in d and "sigma" in d else d

    try:
        eps = json.loads(p.read_text(), object_hook=light)["episodes"]
        return [{k: e[k] for k in ("start_ns", "end_ns", "corrupted", "xi_sign")} for e in eps]
    except (ValueError, KeyError, TypeError):
        return None


def replay(
    bag: str | Path,
    profile: str | Path | CameraProfile | None = None,
    out_dir: str | Path | None = None,
    *,
    estimator: Any = None,
    model_name: str | None = None,
    weights: str | Path | None = None,
    device: str | None = None,
    config: MonitorConfig | str | Path | None = None,
    camera_name: str | None = None,
    hardware_id: str | None = None,
    namespace: str = DEFAULT_NAMESPACE,
    image_topic: str | None = None,
    metadata_topic: str | None = None,
    camera_info_topic: str | None = None,
    temperature_topic: str | None = None,
    bit_depth: int | None = None,
    threads: int | None = None,
    progress: bool = True,
    plot: bool = True,
) -> dict[str, Any]:
    """Run the monitor over every image of ``bag``; returns the JSON summary (and writes outputs).

    ``config``: a MonitorConfig or a node params YAML (default config/node.yaml, whose model, weights, device,
    camera_name, hardware_id, bit_depth, color, sync_tolerance_s, diagnostics_rate_hz and threads apply
    too unless given here). ``estimator``: an object honouring the estimator contract (default:
    ``noise_monitor.estimator.load(model_name, device)``). ``threads``: torch CPU threads as the node sets
    them (0 = all cores but one; more threads than free cores slow inference down several-fold).
    """
    cfg, params = _settings(config)
    prof = load_profile(profile) if isinstance(profile, (str, Path)) else profile
    out = Path(out_dir) if out_dir is not None else None
    mcap_path = out / OUTPUT_FILES["mcap"] if out is not None else None
    table = FrameTable()
    truth = _truth_episodes(bag)  # before the loop: a long simulation's sidecar is parsed while memory is fresh
    with ExitStack() as stack:
        # the bag first: an unusable bag is reported before the estimator is loaded
        reader = stack.enter_context(open_bag(bag, image_topic=image_topic, metadata_topic=metadata_topic,
                                              camera_info_topic=camera_info_topic,
                                              temperature_topic=temperature_topic))
        model = NoiseModel(extra=prof.effects if prof else None)
        if estimator is None:  # the estimator's physics prior is the profile's model, as in the node
            from noise_monitor.estimator import load

            estimator = load(model_name or params.get("model", "full_meta"),
                             device=device or params.get("device", "cpu"),
                             weights=weights or params.get("weights") or None, model=model)
        set_inference_threads(int(params.get("threads", 0)) if threads is None else threads)
        camera = camera_name or params.get("camera_name") or "camera"
        hw = hardware_id or params.get("hardware_id") or f"{prof.name if prof else 'unknown'}/{camera}"
        monitor = Monitor(cfg, estimator, model, camera, hw)
        depth = bit_depth or int(params.get("bit_depth", 0)) or None
        diag_period_ns = int(1e9 / float(params.get("diagnostics_rate_hz", 1.0)))
        if mcap_path is not None:
            out.mkdir(parents=True, exist_ok=True)
            mcap_path.unlink(missing_ok=True)
        writer = stack.enter_context(BagWriter(mcap_path)) if mcap_path else None
        t_wall = time.perf_counter()
        n_images, bag_duration = len(reader), reader.duration_s
        topics = {"image": reader.image_topic, "metadata": reader.metadata_topic,
                  "camera_info": reader.camera_info_topic, "temperature": reader.temperature_topic}
        frames = reader.frames(prof, bit_depth=depth, sync_tolerance_s=float(params.get("sync_tolerance_s", 0.01)),
                               color=str(params.get("color", "luma")))
        last_pub: int | None = None
        last_log = 0
        for bf in tqdm(frames, total=n_images, unit="frame", desc=f"replay {Path(bag).name}", disable=not progress):
            if writer is not None and last_pub is not None:  # the node's timer fills gaps (STALE when long)
                # only while time really passed in the recording: a header stamp jumping by years (out of
                # order, bogus clock) must not produce years of idle reports
                end = min(bf.stamp_ns, last_pub + bf.log_time_ns - last_log)
                t = last_pub + diag_period_ns
                while t < end:
                    for topic, msg in rosbags_messages(monitor.idle_report(t), stamp_ns=t, namespace=namespace,
                                                       typestore=typestore()).items():
                        writer.write(topic, msg, t)
                    t += diag_period_ns
            res = evaluate(monitor, bf)
            _record(table, bf, res)
            if writer is not None:
                for topic, msg in rosbags_messages(res, namespace=namespace, typestore=typestore()).items():
                    writer.write(topic, msg, res.stamp_ns)
            last_pub, last_log = res.stamp_ns, bf.log_time_ns
    wall = time.perf_counter() - t_wall
    if len(table) != n_images:
        raise BagError(f"bag {bag}: read {len(table)} images but its index lists {n_images}")
    episodes = alarm_episodes(table)
    processed = int(table.column("processed").sum())
    levels = table.column("level")
    summary: dict[str, Any] = {
        "bag": str(bag),
        "profile": prof.name if prof else None,
        "estimator": getattr(estimator, "name", str(model_name)),
        "hardware_id": hw,
        "topics_in": topics,
        "topics_out": output_topics(namespace),
        "frames_total": len(table),
        "frames_processed": processed,
        "frames_skipped": len(table) - processed,
        "skip_reasons": skip_reasons(table),
        "skipped": skipped_frames(table)[:MAX_LISTED_SKIPS],  # all of them are in the CSV
        "alarms": episodes,
        **source_summaries(table),
        "levels": {name: int(np.sum(levels == lvl)) for lvl, name in LEVEL_NAMES.items()},
        "bag_duration_s": round(bag_duration, 6),
        "wall_time_s": round(wall, 3),
        "frames_per_s": round(len(table) / wall, 3) if wall > 0 else None,
        "realtime_factor": round(bag_duration / wall, 3) if wall > 0 and bag_duration > 0 else None,
        "config": {k: getattr(cfg, k) for k in cfg.field_names()},
    }
    if truth is not None:
        summary["truth_check"] = truth_check(episodes, truth)
    if out is not None:
        write_csv(table, out / OUTPUT_FILES["csv"])
        files = {"mcap": str(mcap_path), "csv": str(out / OUTPUT_FILES["csv"])}
        if plot and table:
            period = bag_duration / (len(table) - 1) if len(table) > 1 else 0.0
            title = f"{Path(bag).name}: {summary['estimator']} on {prof.name if prof else 'bag metadata'}"
            t0 = int(table.column("stamp_ns")[0])
            spans = [((e["start_ns"] - t0) / 1e9, (e["end_ns"] - t0) / 1e9, "; ".join(e["corrupted"]))
                     for e in truth or []]
            plot_replay(table, episodes, out / OUTPUT_FILES["png"], title, cfg.xi_threshold_dn, period, spans)
            files["png"] = str(out / OUTPUT_FILES["png"])
        files["json"] = str(out / OUTPUT_FILES["json"])
        summary["outputs"] = files
        (out / OUTPUT_FILES["json"]).write_text(json.dumps(summary, indent=2))
    return summary
