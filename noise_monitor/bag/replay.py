"""Replay a bag through the monitor pipeline (the node's code), faster than real time.

Every image is accounted for: processed, or skipped with the monitor's reason (image unusable, metadata
missing/invalid/stale, too few usable patches, ...). The node's behaviour is reproduced on bag time:
same model (profile effects included), same hardware id, same reject path for unusable images, and
``/diagnostics`` at ``diagnostics_rate_hz`` of bag time summarising each period
(``noise_monitor.monitor.period``; STALE after ``image_timeout_s`` in gaps between images, a last partial
period at the last image). Outputs in ``out_dir``: ``replay.mcap`` with exactly the node's topics
(``msg_adapters.outputs``: per frame ``<namespace>/frame`` and the stamped numbers, stamped with the
image's header; ``<namespace>/debug_image`` at ``debug_image_rate_hz`` in bag time), ``replay.csv`` (one line per frame),
``replay.png`` and ``summary.json``. A live view (:class:`msg_adapters.live_view.LiveView`) is served
every message written plus the evaluated gray image (``<namespace>/input_image``) while the replay
runs, paced to bag time with ``rate``.
"""
from __future__ import annotations

import json
import math
import time
from contextlib import ExitStack, nullcontext
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from msg_adapters.debug_image import debug_view
from msg_adapters.keymap import keymap_entries
from msg_adapters.outputs import (
    DEFAULT_NAMESPACE,
    IMAGE_TYPE,
    debug_image_topic,
    output_topics,
    rosbags_image,
    rosbags_messages,
)
from noise_monitor.monitor import Frame, FrameResult, GapCounter, MonitorConfig
from noise_monitor.monitor.black_level import BlackLevelCheck
from noise_monitor.monitor.period import PeriodSummary
from noise_monitor.monitor.runtime import MonitorRuntime
from noise_monitor.monitor.status import LEVEL_NAMES
from noise_monitor.physics import CameraProfile
from noise_monitor.physics.metadata import STATIC_FIELDS
from noise_monitor.text import clip

from .errors import BagError
from .plot import plot_replay
from .reader import open_bag
from .results import (
    CONDITION_KEYS,
    FrameTable,
    alarm_episodes,
    skip_reasons,
    skipped_frames,
    source_summaries,
    truth_check,
    write_csv,
    xi_measurements,
)
from .simulate import truth_path
from .staging import StagedOutputs
from .writer import BagWriter, typestore

#: Skipped frames listed one by one in the summary (the counts per reason and the CSV cover all).
MAX_LISTED_SKIPS = 1000
#: Idle /diagnostics reports written into one gap of the recording at most: a log-time jump (a robot without
#: a real-time clock going from 1970 to today) must not mean 1.7e9 reports. One hour at 1 Hz.
MAX_IDLE_REPORTS_PER_GAP = 3600
OUTPUT_FILES = {"mcap": "replay.mcap", "csv": "replay.csv", "png": "replay.png", "json": "summary.json"}
#: ``<namespace>/input_image`` in a live view: the gray image the monitor evaluated (mono8, mono16 above 8 bits).
INPUT_IMAGE = "input_image"


def live_topics(namespace: str = DEFAULT_NAMESPACE) -> dict[str, str]:
    """Topics a replay serves to a live view: the outputs, the debug image and the evaluated gray image."""
    return {**output_topics(namespace), debug_image_topic(namespace): IMAGE_TYPE,
            "/" + namespace.strip("/") + "/" + INPUT_IMAGE: IMAGE_TYPE}


class _Pacer:
    """Sleeps so that frames leave at ``rate`` times their recording's pace (log time); None: no waiting."""

    def __init__(self, rate: float | None) -> None:
        if rate is not None and not (np.isfinite(rate) and rate > 0):
            raise ValueError(f"rate must be > 0, got {rate}")
        self.rate = rate
        self._origin: tuple[float, int] | None = None

    def wait(self, log_time_ns: int | None) -> None:
        if self.rate is None or log_time_ns is None:
            return
        if self._origin is None:
            self._origin = (time.monotonic(), log_time_ns)
        wall0, log0 = self._origin
        delay = wall0 + (log_time_ns - log0) / 1e9 / self.rate - time.monotonic()
        if delay > 0:
            time.sleep(delay)


class _Tee:
    """Writes each output message to the replay's MCAP (when there is one) and to a live view."""

    def __init__(self, bag: BagWriter | None, live: Any) -> None:
        self.bag, self.live = bag, live

    def write(self, topic: str, msg: Any, stamp_ns: int) -> None:
        if self.bag is not None:
            self.bag.write(topic, msg, stamp_ns)
        self.live.log({topic: msg}, stamp_ns)


def _gray_image(image_dn: np.ndarray, bit_depth: int | None) -> np.ndarray:
    """The evaluated DN image as it would travel: uint8 up to 8 bits, uint16 above."""
    high = bit_depth is not None and bit_depth > 8
    return np.clip(np.rint(image_dn), 0, 65535 if high else 255).astype(np.uint16 if high else np.uint8)


def _record(table: FrameTable, bf: Frame, res: FrameResult) -> None:
    meta = bf.metadata
    table.append(index=bf.index, stamp_ns=res.stamp_ns, processed=res.processed, level=res.level,
                 alarm_active=res.alarm_active, alarm_state=res.alarm_state, cause=res.cause,
                 skip_reason=res.skip_reason, numbers=res.numeric(),
                 conditions={k: getattr(meta, k) for k in CONDITION_KEYS} if meta else {},
                 xi_measurement=res.xi_measurement if res.processed else None, hold_event=res.hold_event)


def _black_level_summary(contradicted: list[BlackLevelCheck]) -> dict[str, Any] | None:
    """The frames whose stated black level the image contradicts: how many, and the tightest bound with the black
    level stated there and by whom."""
    if not contradicted:
        return None
    tightest = min(contradicted, key=lambda c: c.upper_dn if c.upper_dn is not None else math.inf)
    return {"frames": len(contradicted), "stated_dn": tightest.black_level_dn, "stated_by": tightest.source,
            "camera_at_most_dn": round(float(tightest.upper_dn or 0.0), 2)}


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


def _note_overrides(prof: CameraProfile, raw: dict[str, Any], seen: dict[str, dict[str, Any]]) -> None:
    """Record in ``seen`` (first occurrence) each camera constant a frame's metadata message sets other than the
    profile: the message's values win over the profile's, as in the node."""
    for key in STATIC_FIELDS:
        if key in seen or key not in raw or prof.values.get(key) is None:
            continue
        mine, theirs = prof.values[key], raw[key]
        try:
            same = math.isclose(float(mine), float(theirs), rel_tol=1e-9)
        except (TypeError, ValueError):
            same = str(mine).strip().lower() == str(theirs).strip().lower()
        if not same:
            seen[key] = {"profile": mine, "bag": theirs}


def replay(bag: str | Path, profile: str | Path | CameraProfile | None = None, out_dir: str | Path | None = None,
           **kwargs: Any) -> dict[str, Any]:
    """Run the monitor over every image of ``bag``; returns the JSON summary (and writes outputs to ``out_dir``).

    The outputs are written to new files and published together at the end (see
    :class:`~noise_monitor.bag.staging.StagedOutputs`): a failed or interrupted replay leaves ``out_dir`` as
    it was, links in it are replaced and never followed, and an output that is the input bag is refused.
    Keyword arguments: see :func:`run_replay`.
    """
    stage = StagedOutputs(out_dir, list(OUTPUT_FILES.values()), inputs=[Path(bag)]) if out_dir is not None else None
    with stage if stage is not None else nullcontext():
        return run_replay(bag, profile, stage, **kwargs)


def run_replay(
    bag: str | Path,
    profile: str | Path | CameraProfile | None = None,
    stage: StagedOutputs | None = None,
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
    physics_tables: str | None = None,
    table: FrameTable | None = None,
    live: Any = None,
    rate: float | None = None,
) -> dict[str, Any]:
    """Run the monitor over every image of ``bag``; returns the JSON summary (outputs written to ``stage``).

    The monitor is the node's (:class:`MonitorRuntime`): ``config`` is a node params YAML (default
    config/node.yaml, whose model, weights, device, camera_name, hardware_id, bit_depth, color,
    sync_tolerance_s, diagnostics_rate_hz and threads apply unless given here) or a MonitorConfig (the
    other parameters then take their defaults). ``estimator``: an object honouring the estimator contract
    (default: ``noise_monitor.estimator.load(model_name, device)``). ``threads``: torch CPU threads as the
    node sets them (0 = all cores but one; more threads than free cores slow inference down several-fold).
    ``physics_tables``: ``interpolated`` (default) or ``exact`` tables per metadata set (for comparisons).
    The params' ``metadata_keymap`` reads a DiagnosticArray with a driver's own key names.
    ``table``: an empty FrameTable to receive the per-frame results (a campaign keeps them).
    ``live``: a :class:`msg_adapters.live_view.LiveView` advertising :func:`live_topics` (``namespace``),
    served every message as it is produced; ``rate``: pace the frames to ``rate`` x their recording's
    speed (default: as fast as processed).
    """
    pacer = _Pacer(rate)
    overrides = {"model": model_name, "weights": str(weights) if weights else None, "device": device,
                 "camera_name": camera_name, "hardware_id": hardware_id, "bit_depth": bit_depth, "threads": threads,
                 "physics_tables": physics_tables}
    mcap_path = stage.path(OUTPUT_FILES["mcap"]) if stage is not None else None
    if table is None:
        table = FrameTable()
    elif len(table):
        raise ValueError("replay needs an empty FrameTable")
    truth = _truth_episodes(bag)  # before the loop: a long simulation's sidecar is parsed while memory is fresh
    with ExitStack() as stack:
        # the bag first: an unusable bag is reported before the estimator is loaded
        reader = stack.enter_context(open_bag(bag, image_topic=image_topic, metadata_topic=metadata_topic,
                                              camera_info_topic=camera_info_topic,
                                              temperature_topic=temperature_topic))
        if isinstance(config, MonitorConfig):
            rt = MonitorRuntime({k: v for k, v in overrides.items() if v is not None}, profile=profile,
                                estimator=estimator, config=config)
        else:
            rt = MonitorRuntime.from_params_file(config, overrides, profile=profile, estimator=estimator)
        if not rt.params["hardware_id"]:  # the driver's device id names the camera, as in the node
            rt.hardware_id = rt.monitor.hardware_id = reader.hardware_id() or rt.hardware_id
        prof, cfg, monitor, hw = rt.profile, rt.config, rt.monitor, rt.hardware_id
        diag_period_ns = rt.diagnostics_period_ns
        debug_hz = float(rt.params["debug_image_rate_hz"])
        debug_topic, last_debug = debug_image_topic(namespace), None
        input_topic = "/" + namespace.strip("/") + "/" + INPUT_IMAGE
        bag_writer = stack.enter_context(BagWriter(mcap_path)) if mcap_path else None
        if bag_writer is not None:  # the node's publishers, also those a bag may give nothing (a still hold's)
            bag_writer.declare(output_topics(namespace))
        # everything written to the MCAP is also served to a live view, as it is produced
        writer = _Tee(bag_writer, live) if live is not None else bag_writer
        t_wall = time.perf_counter()
        n_images, bag_duration = len(reader), reader.duration_s
        topics = {role: clip(t, 200) if t else t for role, t in (
            ("image", reader.image_topic), ("metadata", reader.metadata_topic),
            ("camera_info", reader.camera_info_topic), ("temperature", reader.temperature_topic))}
        opts = rt.frame_options
        frames = reader.frames(prof, bit_depth=opts.bit_depth, sync_tolerance_s=rt.params["sync_tolerance_s"],
                               color=opts.color, metadata_keymap=keymap_entries(rt.params["metadata_keymap"]) or None,
                               black_level_dn=opts.black_level_dn, hardware_id=rt.params["hardware_id"])
        periods: PeriodSummary | None = None  # /diagnostics summaries every diag_period_ns of bag time
        next_report = last_stamp = 0
        last_log = 0
        capped_gaps = 0
        black_bounds: list[BlackLevelCheck] = []  # frames contradicting the stated black level (the camera's is lower)
        gaps = GapCounter(expected_rate_hz=float(rt.params["expected_rate_hz"]))  # frames the recording lacks
        constants: dict[str, dict[str, Any]] = {}  # camera constants the bag's metadata set over the profile's

        def report(t: int) -> None:
            assert periods is not None
            status = periods.report(monitor, t)
            if writer is not None:
                for topic, msg in rosbags_messages(status, stamp_ns=t, typestore=typestore()).items():
                    writer.write(topic, msg, t)

        for bf in tqdm(frames, total=n_images, unit="frame", desc=f"replay {Path(bag).name}", disable=not progress):
            if periods is None:
                periods, next_report = PeriodSummary(bf.stamp_ns), bf.stamp_ns + diag_period_ns
            else:  # the node's timer: one summary per period, idle ones (STALE when long) over gaps
                # only while time really passed in the recording: a header stamp jumping by years (out of
                # order, bogus clock) must not produce years of reports
                end = min(bf.stamp_ns, last_stamp + bf.log_time_ns - last_log)
                if (end - next_report) // diag_period_ns >= MAX_IDLE_REPORTS_PER_GAP:  # a clock jump (1970 -> today)
                    end, capped_gaps = next_report + (MAX_IDLE_REPORTS_PER_GAP - 1) * diag_period_ns, capped_gaps + 1
                while next_report <= end:
                    report(next_report)
                    next_report += diag_period_ns
                if not next_report - diag_period_ns <= bf.stamp_ns < next_report:  # the stamps jumped: a new grid
                    next_report = bf.stamp_ns + diag_period_ns
            pacer.wait(bf.log_time_ns)
            if prof is not None:
                _note_overrides(prof, bf.raw_metadata, constants)
            implausible = gaps.implausible
            monitor.count_lost(gaps.observe(bf.stamp_ns), gaps.implausible - implausible)  # as the node counts them
            res = rt.process(bf)
            if res.black_level is not None and res.black_level.upper_dn is not None:
                black_bounds.append(res.black_level)
            _record(table, bf, res)
            periods.add(res)
            if writer is not None:
                for topic, msg in rosbags_messages(res, namespace=namespace, typestore=typestore(),
                                                   frame_id=bf.frame_id).items():
                    writer.write(topic, msg, res.stamp_ns)
            if (writer is not None and debug_hz > 0 and res.processed and res.patches is not None
                    and bf.image_dn is not None and (last_debug is None or res.stamp_ns - last_debug >= 1e9 / debug_hz)):
                last_debug = res.stamp_ns  # ~/debug_image at debug_image_rate_hz in bag time
                rgb = debug_view(bf.image_dn, res.patches.corners, res.patches.size, res.patch_xi, cfg.xi_threshold_dn)
                writer.write(debug_topic, rosbags_image(rgb, res.stamp_ns, bf.frame_id, typestore()), res.stamp_ns)
            if live is not None:
                if bf.image_dn is not None and live.has_subscribers(input_topic):
                    live.log_image(input_topic, _gray_image(bf.image_dn, opts.depth(bf.raw_metadata.get("bit_depth"))), res.stamp_ns)
                live.broadcast_time(res.stamp_ns)
            last_stamp, last_log = res.stamp_ns, bf.log_time_ns
        monitor.count_lost(gaps.flush())  # the last intervals, judged at the recording's end
        if periods is not None and periods.frames:  # the last, partial period ends with the last image
            report(last_stamp)
    wall = time.perf_counter() - t_wall
    if len(table) < n_images:
        raise BagError(f"bag {bag}: read {len(table)} images but its index lists {n_images}")
    episodes = alarm_episodes(table)
    processed = int(table.column("processed").sum())
    levels = table.column("level")
    summary: dict[str, Any] = {
        "bag": str(bag),
        "profile": prof.name if prof else None,
        "estimator": getattr(rt.estimator, "name", str(rt.params["model"])),
        # the checkpoint (None: the bundled weights of the model; an estimator given in-process: not known here)
        "weights": str(Path(rt.params["weights"]).resolve()) if rt.params.get("weights") else None,
        "hardware_id": hw,
        "topics_in": topics,
        "topics_out": {**output_topics(namespace), **({debug_topic: IMAGE_TYPE} if last_debug is not None else {})},
        "frames_total": len(table),
        # images beyond those the bag's index (metadata.yaml) lists: a stale index, every one replayed
        "frames_beyond_index": len(table) - n_images,
        "frames_processed": processed,
        "frames_skipped": len(table) - processed,
        # images missing from the recording (lost before it), inferred from header-stamp gaps as the node does
        "frames_lost": int(monitor.counters["frames_lost"]),
        # changes of the camera's noise that cut a still hold's window (the temporal measurement restarted)
        "temporal_noise_changes": int(monitor.counters["temporal_noise_changes"]),
        # steps of the light that cut a still hold's window (the same restart, not a fault)
        "temporal_light_steps": int(monitor.counters["temporal_light_steps"]),
        "skip_reasons": skip_reasons(table),
        "skipped": skipped_frames(table)[:MAX_LISTED_SKIPS],  # all of them are in the CSV
        "xi_measurement": xi_measurements(table),  # processed frames by the measurement that drove their xi
        "alarms": episodes,
        **source_summaries(table),
        "levels": {name: int(np.sum(levels == lvl)) for lvl, name in LEVEL_NAMES.items()},
        "bag_duration_s": round(bag_duration, 6),
        "wall_time_s": round(wall, 3),
        "frames_per_s": round(len(table) / wall, 3) if wall > 0 else None,
        "realtime_factor": round(bag_duration / wall, 3) if wall > 0 and bag_duration > 0 else None,
        "config": {k: getattr(cfg, k) for k in cfg.field_names()},
        "idle_gaps_capped": capped_gaps,
        "metadata_overrides": constants,
        "black_level_contradicted": _black_level_summary(black_bounds),
        # keys of the params file's every-node sections that are not the monitor's (other nodes'; a typo?)
        "params_ignored": rt.params_ignored,
    }
    if truth is not None:
        summary["truth_check"] = truth_check(episodes, truth)
    if stage is not None:
        write_csv(table, stage.path(OUTPUT_FILES["csv"]))
        files = {"mcap": str(stage.final(OUTPUT_FILES["mcap"])), "csv": str(stage.final(OUTPUT_FILES["csv"]))}
        if plot and table:
            period = bag_duration / (len(table) - 1) if len(table) > 1 else 0.0
            title = f"{Path(bag).name}: {summary['estimator']} on {prof.name if prof else 'bag metadata'}"
            t0 = int(table.column("stamp_ns")[0])
            spans = [((e["start_ns"] - t0) / 1e9, (e["end_ns"] - t0) / 1e9, "; ".join(e["corrupted"]))
                     for e in truth or []]
            plot_replay(table, episodes, stage.path(OUTPUT_FILES["png"]), title, cfg.xi_threshold_dn, period, spans)
            files["png"] = str(stage.final(OUTPUT_FILES["png"]))
        files["json"] = str(stage.final(OUTPUT_FILES["json"]))
        summary["outputs"] = files
        stage.path(OUTPUT_FILES["json"]).write_text(json.dumps(summary, indent=2))
        stage.commit()
    return summary
