"""The unit of work of a campaign: one bag through ``replay()`` in a worker (Ray task or pool process).

The worker hashes the bag, reads its camera id, picks the profile, replays the bag with the replay's own
code (estimator loaded once per worker and profile), writes ``bags/<sha>/frames.parquet`` and
``summary.json`` atomically and returns a small outcome (status, reason, the bag's record for the report).
A failure of any kind becomes an outcome with the reason; only a hang or a dead worker needs the driver.
"""
from __future__ import annotations

import _thread
import json
import os
import signal
import socket
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from noise_monitor.bag.reader import open_bag
from noise_monitor.bag.replay import replay
from noise_monitor.bag.results import CONDITION_KEYS, FrameTable
from noise_monitor.bag.staging import write_text_atomic
from noise_monitor.monitor.runtime import MonitorRuntime
from noise_monitor.physics import CameraProfile, load_plugin_file, load_profile

from .bags import content_hash, fingerprint
from .frames import to_arrow, write_parquet
from .profiles import ProfileMap

#: Alarm episodes kept per bag in the manifest and campaign.json (all are in the bag's summary.json).
MAX_EPISODES = 100
_PAGE_MB = os.sysconf("SC_PAGE_SIZE") / 2**20


@dataclass(frozen=True)
class CampaignSettings:
    """Everything a worker needs, the same for every bag (pickled once per worker / put once into Ray)."""

    out_dir: str
    profiles: ProfileMap = field(default_factory=ProfileMap)
    model: str | None = None
    weights: str | None = None
    device: str | None = None
    params: str | None = None
    plugins: tuple[str, ...] = ()
    threads: int = 1
    memory_limit_mb: float = 0.0  # 0 = no limit
    bag_outputs: bool = False  # also replay's MCAP + CSV + PNG per bag
    image_topic: str | None = None  # the camera to evaluate in bags that hold several (default: detected)
    metadata_topic: str | None = None
    key: str = ""  # what makes the results (:func:`..campaign.settings_key`): the bags' outputs go under it


def bag_dir(out_dir: str | Path, sha256: str, key: str = "") -> Path:
    """A bag's outputs under the settings that made them: a re-run with other settings never overwrites them."""
    return Path(out_dir) / "bags" / (key[:16] or "default") / sha256[:16]


def rss_mb() -> float:
    """Resident set size of this process (MB)."""
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * _PAGE_MB


class MemoryExceeded(BaseException):
    """Raised in the task when its worker's resident memory exceeds the limit."""


#: Exit code of a worker stopped by the memory limit where the task cannot be interrupted (not the main thread).
MEMORY_EXIT_CODE = 87


def _raise_memory_exceeded(signum: int, frame: Any) -> None:
    raise MemoryExceeded


class MemoryLimit:
    """Stops the task when the process's resident memory exceeds the limit (checked every 50 ms): raises
    MemoryExceeded in the task (SIGUSR1 to the main thread), or ends the process with MEMORY_EXIT_CODE."""

    def __init__(self, limit_mb: float) -> None:
        self.limit_mb, self.tripped_mb, self.peak_mb = limit_mb, 0.0, rss_mb()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True)
        self._interruptible = False
        self._previous: Any = None

    def _watch(self) -> None:
        while not self._stop.wait(0.05):
            rss = rss_mb()
            self.peak_mb = max(self.peak_mb, rss)
            if self.limit_mb and rss > self.limit_mb:
                self.tripped_mb = rss
                if not self._interruptible:
                    os._exit(MEMORY_EXIT_CODE)
                _thread.interrupt_main(signal.SIGUSR1)
                return

    def __enter__(self) -> MemoryLimit:
        if self.limit_mb and threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGUSR1, _raise_memory_exceeded)
            self._interruptible = True
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        if self._interruptible:
            signal.signal(signal.SIGUSR1, self._previous)
        self.peak_mb = max(self.peak_mb, rss_mb())


def camera_id(bag: Path, image_topic: str | None = None, metadata_topic: str | None = None) -> str | None:
    """The hardware_id of the bag's first metadata message (DiagnosticArray), or None."""
    with open_bag(bag, image_topic=image_topic, metadata_topic=metadata_topic) as reader:
        return reader.hardware_id()


_ESTIMATORS: dict[tuple[Any, ...], Any] = {}
_PLUGINS: set[str] = set()


def _estimator(settings: CampaignSettings, prof: CameraProfile | None) -> Any:
    """The estimator replay's runtime loads for this profile (same parameters), once per worker process."""
    effects = tuple(sorted((k, tuple(sorted(v.items()))) for k, v in prof.effects.items())) if prof else ()
    key = (settings.params, settings.model, settings.weights, settings.device, settings.threads, effects)
    if key not in _ESTIMATORS:
        if len(_ESTIMATORS) >= 8:  # bounded: a fleet has few distinct effect sets
            _ESTIMATORS.pop(next(iter(_ESTIMATORS)))
        rt = MonitorRuntime.from_params_file(settings.params, _overrides(settings), profile=prof)
        _ESTIMATORS[key] = rt.estimator
    return _ESTIMATORS[key]


def _overrides(settings: CampaignSettings) -> dict[str, Any]:
    return {"model": settings.model, "weights": settings.weights, "device": settings.device,
            "threads": settings.threads}


def _record(summary: dict[str, Any], table: FrameTable) -> dict[str, Any]:
    """What the campaign report keeps of a bag (small: no per-frame data)."""
    processed = table.column("processed")
    stamps = table.column("stamp_ns")
    conditions = {}
    for k in CONDITION_KEYS:
        v = table.numbers(k)[processed]
        v = v[~np.isnan(v)]
        conditions[k] = round(float(v.mean()), 6) if v.size else None
    keep = ("start_ns", "end_ns", "duration_s", "frames", "sign", "peak_xi_dn", "mean_xi_dn", "cause", "active_at_end")
    return {
        "hardware_id": summary["hardware_id"], "profile": summary["profile"], "estimator": summary["estimator"],
        "start_ns": int(stamps[0]) if len(stamps) else None, "end_ns": int(stamps[-1]) if len(stamps) else None,
        "frames_total": summary["frames_total"], "frames_processed": summary["frames_processed"],
        "frames_skipped": summary["frames_skipped"], "skip_reasons": summary["skip_reasons"],
        "frames_lost": summary["frames_lost"],  # images missing from the recording (stamp gaps)
        "frames_in_alarm": int(table.column("alarm")[processed].sum()),
        "alarm_episodes": len(summary["alarms"]),
        "temporal_noise_changes": int(summary.get("temporal_noise_changes", 0)),
        "temporal_light_steps": int(summary.get("temporal_light_steps", 0)),
        "alarms": [{k: e[k] for k in keep} for e in summary["alarms"][:MAX_EPISODES]],
        "stats": {k: summary[k] for k in ("sigma_pn", "sigma_dcsn", "sigma_rn", "sigma_model", "sigma_image", "xi",
                                          "sigma_temporal", "sigma_temporal_model")},
        "conditions": conditions,
        "xi_threshold_dn": summary["config"]["xi_threshold_dn"],
        "metadata_overrides": summary.get("metadata_overrides") or {},  # camera constants the bag set over the profile
    }


def run_bag(path: str, settings: CampaignSettings) -> dict[str, Any]:
    """Replay one bag; never raises for a bad bag: the outcome's status is ``ok`` or ``failed`` with a reason."""
    t0, cpu0 = time.perf_counter(), time.process_time()
    bag = Path(path)
    outcome: dict[str, Any] = {"path": path, "status": "failed", "worker": f"{socket.gethostname()}:{os.getpid()}"}
    guard = MemoryLimit(settings.memory_limit_mb)
    try:
        with guard:
            outcome["size"], outcome["mtime_ns"] = fingerprint(bag)
            for plugin in settings.plugins:
                if plugin not in _PLUGINS:
                    load_plugin_file(plugin)
                    _PLUGINS.add(plugin)
            sha = outcome["sha256"] = content_hash(bag)
            hw = outcome["hardware_id"] = camera_id(bag, settings.image_topic, settings.metadata_topic)
            spec = settings.profiles.resolve(hw)
            prof = load_profile(spec) if spec else None
            out = bag_dir(settings.out_dir, sha, settings.key)
            out.mkdir(parents=True, exist_ok=True)
            table = FrameTable()
            summary = replay(bag, prof, out if settings.bag_outputs else None, estimator=_estimator(settings, prof),
                             config=settings.params, hardware_id=hw, threads=settings.threads, progress=False,
                             image_topic=settings.image_topic, metadata_topic=settings.metadata_topic,
                             plot=settings.bag_outputs, table=table)
            summary["sha256"] = sha
            write_parquet(to_arrow(table, summary["hardware_id"], sha), out / "frames.parquet")
            write_text_atomic(out / "summary.json", json.dumps(summary, indent=1))
            outcome.update(status="ok", record=_record(summary, table), frames=summary["frames_total"])
    except MemoryExceeded:
        outcome.update(reason=f"worker memory limit exceeded: resident {guard.tripped_mb:.0f} MB > "
                              f"{settings.memory_limit_mb:.0f} MB", restart_worker=True)
    except (ValueError, OSError, LookupError) as exc:  # bad input: BagError, MetadataError, profile map, files
        outcome["reason"] = " ".join(str(exc).split()) or type(exc).__name__
    except Exception as exc:  # a bug or a plug-in's failure: reported with where it happened, the rest continue
        where = traceback.extract_tb(exc.__traceback__)[-1]
        outcome["reason"] = (f"{type(exc).__name__}: {' '.join(str(exc).split())} "
                             f"({Path(where.filename).name}:{where.lineno})")
    outcome["wall_s"] = round(time.perf_counter() - t0, 4)
    outcome["cpu_s"] = round(time.process_time() - cpu0, 4)  # all threads of the worker
    outcome["peak_rss_mb"] = round(guard.peak_mb, 1)
    return outcome
