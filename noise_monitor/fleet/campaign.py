"""The campaign driver: find the bags, skip those finished before, run the rest on Ray or a local pool,
record each in the manifest as it ends, then write the per-frame Parquet table, campaign.json and the
HTML report.

The driver keeps O(workers) tasks in flight and a small record per bag (no per-frame data): its memory
grows with the number of bags (~2 KB each), not with their frames.
"""
from __future__ import annotations

import hashlib
import json
import resource
import time
from collections.abc import Iterable
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

from tqdm import tqdm

from noise_monitor.bag.staging import write_text_atomic
from noise_monitor.estimator.inference import weights_path
from noise_monitor.monitor.config import default_params_path, read_ros_params
from noise_monitor.paths import camera_profile_path
from noise_monitor.physics import load_profile

from .bags import content_hash, find_bags, fingerprint
from .frames import merge, require_pyarrow
from .manifest import Manifest
from .pool import LocalPool
from .profiles import ProfileMap
from .ray_pool import RayPool, RayUnavailable
from .report import summarize, write_html
from .task import CampaignSettings, bag_dir

OUTPUTS = {"json": "campaign.json", "parquet": "frames.parquet", "html": "report.html"}


def _file_digest(path: str | None) -> str | None:
    if not path or not Path(path).is_file():
        return path
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def settings_key(settings: CampaignSettings) -> str:
    """What makes a bag's results: the contents of the profiles (bundled ones too), the params file (the default
    config/node.yaml too), the estimator's weights (the bundled ones of the model in effect too) and plug-ins; the
    device, threads and whether the per-bag outputs are written."""
    specs = [*settings.profiles.cameras.values(), settings.profiles.default]
    params = settings.params or str(default_params_path())
    values = read_ros_params(params)
    model = settings.model or str(values.get("model") or "full_meta")
    weights = settings.weights or str(values.get("weights") or "")
    weight_files = [weights] if weights else [str(weights_path(model).with_suffix(s)) for s in (".pt", ".onnx")]
    doc = {"profiles": {"cameras": settings.profiles.cameras, "default": settings.profiles.default},
           "profile_files": {s: _file_digest(str(camera_profile_path(s))) for s in specs if s},
           "model": model, "weights": [_file_digest(w) for w in weight_files], "device": settings.device,
           "params": _file_digest(params), "plugins": [_file_digest(p) for p in settings.plugins],
           "threads": settings.threads, "bag_outputs": settings.bag_outputs,
           "topics": [settings.image_topic, settings.metadata_topic]}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:16]


def _duplicates(paths: list[str], sizes: dict[str, tuple[int, int]], manifest: Manifest) -> dict[str, dict[str, Any]]:
    """Manifest entries for the bags to run (``sizes``: their fingerprints) whose content a bag before them in
    ``paths`` has (to be replayed now, or finished before): ``duplicate_of`` names it. Only bags of a size another
    bag has are hashed here; the others' content is hashed by the worker that replays them."""
    known = {p: manifest.entries[p] for p in paths if p not in sizes and p in manifest.entries}
    by_size: dict[int, list[str]] = {}
    for p in paths:
        size = sizes[p][0] if p in sizes else known[p].get("size") if p in known else None
        if size is not None:
            by_size.setdefault(size, []).append(p)
    out: dict[str, dict[str, Any]] = {}
    for group in by_size.values():
        if len(group) < 2 or not any(p in sizes for p in group):
            continue
        first: dict[str, str] = {}
        for p in group:
            sha = known[p].get("sha256") if p in known else content_hash(Path(p))
            if not sha:
                continue
            if sha not in first:
                first[sha] = p
            elif p in sizes:
                out[p] = {"path": p, "status": "ok", "sha256": sha, "size": sizes[p][0], "mtime_ns": sizes[p][1],
                          "duplicate_of": first[sha]}
    return out


def _executor(backend: str, ray_address: str | None, workers: int,
              timeout_s: float | None) -> tuple[LocalPool | RayPool, str | None]:
    """Ray (local or the cluster at ray_address) or the local pool, and why Ray was not used where it was asked for
    (the pool runs instead)."""
    if backend == "pool":
        return LocalPool(workers, timeout_s), None
    try:
        return RayPool(ray_address, workers, timeout_s), None
    except RayUnavailable as exc:
        if backend == "auto" and ray_address is None and "not installed" in str(exc):
            return LocalPool(workers, timeout_s), None  # Ray is optional: the pool gives the same results
        return LocalPool(workers, timeout_s), f"Ray at {ray_address or 'local'}: {exc}; ran on the local process pool"


def _entry(outcome: dict[str, Any]) -> dict[str, Any]:
    """A manifest line from a worker's outcome (fingerprint filled in for failures the driver saw)."""
    e = {k: outcome.get(k) for k in ("path", "status", "reason", "sha256", "size", "mtime_ns", "frames", "record",
                                      "wall_s", "cpu_s", "task_s", "peak_rss_mb", "worker", "hardware_id")}
    if e["size"] is None:
        try:
            e["size"], e["mtime_ns"] = fingerprint(Path(outcome["path"]))
        except OSError:
            pass
    return {k: v for k, v in e.items() if v is not None}


def run_campaign(
    inputs: Iterable[str | Path],
    out_dir: str | Path,
    *,
    profile: str | None = None,
    profile_map: str | Path | None = None,
    model: str | None = None,
    weights: str | None = None,
    device: str | None = None,
    params: str | None = None,
    plugins: Iterable[str] = (),
    backend: str = "auto",
    ray_address: str | None = None,
    workers: int = 2,
    timeout_s: float | None = 600.0,
    memory_limit_mb: float = 0.0,
    bag_outputs: bool = False,
    image_topic: str | None = None,
    metadata_topic: str | None = None,
    progress: bool = True,
    report: bool = True,
) -> dict[str, Any]:
    """Replay every bag of ``inputs`` into ``out_dir``; returns the campaign summary (campaign.json).

    ``backend``: ``auto`` (Ray when installed, else the pool), ``ray`` or ``pool``. Raises ValueError for an
    unusable campaign (profile, profile map, workers); bad bags are reported in the summary instead.
    """
    if backend not in ("auto", "ray", "pool"):
        raise ValueError(f"backend must be auto, ray or pool, got {backend!r}")
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if timeout_s is not None and timeout_s <= 0:
        raise ValueError(f"timeout must be > 0 s, got {timeout_s}")
    require_pyarrow()
    if profile and profile_map:
        raise ValueError("give --profile or --profiles, not both")
    if profile:
        load_profile(profile)  # an unusable profile stops the campaign before any work
    profiles = ProfileMap.load(profile_map) if profile_map else ProfileMap.single(profile)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    plugins = tuple(str(Path(p).resolve()) for p in plugins)
    settings = CampaignSettings(out_dir=str(out.resolve()), profiles=profiles, model=model, weights=weights,
                                device=device, params=str(Path(params).resolve()) if params else None,
                                plugins=plugins, memory_limit_mb=memory_limit_mb, bag_outputs=bag_outputs,
                                image_topic=image_topic, metadata_topic=metadata_topic)
    t0 = time.perf_counter()
    bags, problems = find_bags(inputs, skip=out)
    paths = [str(b.resolve()) for b in bags]
    settings = replace(settings, key=settings_key(settings))  # the bags' outputs of these settings: their own folder
    manifest = Manifest(out, settings.key)
    prints = {p: fingerprint(Path(p)) for p in paths}
    todo = [p for p in paths if not manifest.finished(p, *prints[p])]
    resumed = len(paths) - len(todo)
    for path, entry in _duplicates(paths, {p: prints[p] for p in todo}, manifest).items():  # content replayed once
        manifest.record(entry)
        todo.remove(path)
    executor, backend_note = _executor(backend, ray_address, workers, timeout_s) if todo else (None, None)
    run_info: dict[str, Any] = executor.describe() if executor else {"backend": "none (every bag finished before)"}
    if backend_note:
        run_info["backend_note"] = backend_note
    finished = frames = 0
    interrupted = False
    bar = tqdm(total=len(todo), unit="bag", desc="campaign", disable=not progress, position=0)
    fbar = tqdm(unit="frame", desc="frames", disable=not progress, position=1)
    try:
        for outcome in executor.run(todo, settings) if executor else ():
            manifest.record(_entry(outcome))
            finished += 1
            frames += outcome.get("frames", 0)
            bar.update(1)
            fbar.update(outcome.get("frames", 0))
            if outcome["status"] != "ok":
                bar.write(f"failed: {outcome['path']}: {outcome['reason']}")
    except KeyboardInterrupt:
        interrupted = True
    finally:
        bar.close()
        fbar.close()
        manifest.close()
        if executor:
            executor.close()
    wall = time.perf_counter() - t0
    run_info.update(bags_run=finished, frames_run=frames, wall_time_s=round(wall, 3),
                    frames_per_s=round(frames / wall, 2) if wall > 0 else None, bags_resumed=resumed,
                    driver_peak_rss_mb=round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1))
    entries = [manifest.entries[p] for p in paths if p in manifest.entries]
    campaign = summarize(paths, entries, problems, run_info)
    campaign["settings"] = {**{k: v for k, v in asdict(settings).items() if k != "profiles"},
                            "profiles": {"cameras": profiles.cameras, "default": profiles.default,
                                         "source": profiles.source}, "key": manifest.settings_key}
    campaign["interrupted"] = interrupted
    outputs = {"json": str(out / OUTPUTS["json"]), "manifest": str(manifest.path)}
    if not interrupted:
        try:  # Ctrl-C here still leaves campaign.json, marked interrupted (the table and report are rewritten on resume)
            parts = [(bag_dir(out, b["sha256"], settings.key) / "frames.parquet", b["path"]) for b in campaign["bags"]]
            if parts:
                campaign["frames_in_table"] = merge(parts, out / OUTPUTS["parquet"])
                outputs["parquet"] = str(out / OUTPUTS["parquet"])
            if report:
                write_html(campaign, out / OUTPUTS["html"])
                outputs["html"] = str(out / OUTPUTS["html"])
        except KeyboardInterrupt:
            interrupted = campaign["interrupted"] = True
            campaign.pop("frames_in_table", None)
            outputs = {k: v for k, v in outputs.items() if k in ("json", "manifest")}
    campaign["outputs"] = outputs
    write_text_atomic(out / OUTPUTS["json"], json.dumps(campaign, indent=1))
    if interrupted:
        raise KeyboardInterrupt(f"campaign interrupted: {len(campaign['bags'])} of {len(paths)} bags finished "
                                f"and recorded in {manifest.path}; re-run the same command to resume")
    return campaign
