"""The estimator's view of the analysed frames: per frame, the monitor's xi and sigma_image (Full-Meta's
measurement of the noise in the image) for each camera model, so a user sees xi move towards 0 when the
missing effect is added (and again after fine-tuning the estimator with ``noise-monitor train --profile``)."""
from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..monitor import Frame, MonitorConfig
from ..monitor.runtime import HELD_EXACT_REQUESTS, PHYSICS_TABLES, MonitorRuntime
from ..physics import NoiseModel
from ..physics.table_grid import GridSpec

#: The view is the estimator's single-image measurement: frame differences (the monitor's sigma_temporal)
#: cannot see fixed-pattern effects, which the lab measures itself.
SINGLE_IMAGE = MonitorConfig(temporal_frames=0)
#: Per-frame numbers kept from the monitor (DN).
KEYS = ("xi", "sigma_image", "sigma_model")


def _stats(v: list[float]) -> dict[str, float | None]:
    """mean with its standard error (``sem``; frames taken as independent), p5 and p95."""
    a = np.asarray(v, dtype=float)
    if not a.size:
        return {"mean": None, "sem": None, "p5": None, "p95": None}
    sem = float(a.std(ddof=1) / np.sqrt(a.size)) if a.size > 1 else None
    return {"mean": round(float(a.mean()), 4), "sem": round(sem, 4) if sem is not None else None,
            "p5": round(float(np.percentile(a, 5)), 4), "p95": round(float(np.percentile(a, 95)), 4)}


def node_tables(model: NoiseModel, physics_tables: str = "interpolated") -> NoiseModel:
    """``model`` with the physics tables the node would use (its ``physics_tables`` parameter): interpolated
    over metadata that changes every frame, exact for held metadata; or exact for every metadata set."""
    if physics_tables not in PHYSICS_TABLES:
        raise ValueError(f"physics_tables must be one of {PHYSICS_TABLES}, got {physics_tables!r}")
    interpolate = GridSpec(held_exact_requests=HELD_EXACT_REQUESTS) if physics_tables == "interpolated" else False
    return NoiseModel(model.effects, interpolate=interpolate)


def estimator_views(frames: Iterable[Frame], models: Mapping[str, NoiseModel], estimator: str = "full_meta",
                    weights: str | Path | None = None, device: str = "cpu",
                    config: MonitorConfig = SINGLE_IMAGE, physics_tables: str = "interpolated") -> dict[str, dict[str, Any]]:
    """One pass over ``frames`` through the shared monitor runtime, one per model (the node's skip rules:
    frames the replay would skip are skipped here too; the node's physics tables, see :func:`node_tables`).

    Returns per model name: frames evaluated / skipped (by reason), xi / sigma_image / sigma_model
    statistics (mean, its standard error, p5, p95 in DN), the mean |xi| and the per-frame series
    (``time_s``, ``xi``).
    """
    params = {"model": estimator, "weights": str(weights) if weights else "", "device": device, "camera_name": "lab",
              "hardware_id": "lab"}
    runtimes = {name: MonitorRuntime(params, model=node_tables(model, physics_tables), config=config)
                for name, model in models.items()}
    series: dict[str, dict[str, list[float]]] = {name: {k: [] for k in ("time_s", *KEYS)} for name in models}
    skipped: dict[str, Counter] = {name: Counter() for name in models}
    t0 = None
    for f in frames:
        t0 = f.stamp_ns if t0 is None else t0
        for name, rt in runtimes.items():
            res = rt.process(f)
            if not res.processed:
                skipped[name][res.skip_reason or "not evaluated"] += 1
                continue
            nums = res.numeric()
            series[name]["time_s"].append((f.stamp_ns - t0) / 1e9)
            for k in KEYS:
                series[name][k].append(nums[k])
    out = {}
    for name, s in series.items():
        out[name] = {"estimator": estimator, "weights": str(weights) if weights else "bundled",
                     "frames": len(s["xi"]), "skipped": dict(skipped[name]),
                     **{f"{k}_dn": _stats(s[k]) for k in KEYS},
                     "mean_abs_xi_dn": round(float(np.mean(np.abs(s["xi"]))), 4) if s["xi"] else None,
                     "series": {"time_s": [round(t, 6) for t in s["time_s"]], "xi": [round(x, 5) for x in s["xi"]]}}
    return out
