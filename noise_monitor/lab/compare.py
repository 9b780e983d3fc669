"""Model vs measurement: the noise model's prediction for the measured cells, residuals in DN, tables.

The model is evaluated with ``NoiseModel.predict`` (joint mode, clip-aware) at every accepted block's
intensity with the segment's metadata (the ADC quantization, whose exact clip-aware tables are costly,
is added as its LSB^2/12), split into the measured components (temporal, fixed-pattern
white, column, row) by each effect's ``temporal`` flag and line structure, and averaged per cell like
the measurement. For fitting candidate effects, :meth:`Comparison.predict_with` adds the unclipped
change of variance a set of effects makes (cheap, no new tables) to this clip-aware baseline.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

import numpy as np
from scipy.special import ndtr

from ..physics import CameraMetadata, CameraProfile, Effect, NoiseModel, build_effects, make_effect
from ..physics.clipping import DN_MAX
from ..physics.effects import PAPER_EFFECTS
from ..physics.sensor import Conditions
from .measure import OUTLIER_PIXEL_SIGMAS, Cell, Measurements, SegmentMeasurement

MEASURED = ("temporal", "fixed", "column", "row")
#: assumed standard error of the quantization-step measurement beyond its statistical error (DN)
STEP_SYSTEMATIC_DN = 0.25


def component_of(effect: Effect) -> str | None:
    """Which measured component an effect's variance lands in (None: modifiers)."""
    if effect.distribution == "modifier":
        return None
    axis = getattr(type(effect), "axis", None)
    if axis == 1:
        return "column"
    if axis == 0:
        return "row"
    return "temporal" if effect.temporal else "fixed"


def baseline_effects(profile: CameraProfile | None, meta: CameraMetadata, integer_output: bool) -> list[Effect]:
    """The camera's model: the paper's sources, the profile's effects and the ADC quantization."""
    effects = [make_effect(n) for n in PAPER_EFFECTS] + build_effects(dict(profile.effects) if profile else None)
    bits = meta.bit_depth or (profile.bit_depth if profile else None) or (8 if integer_output else None)
    if bits and not any(e.distribution == "quantization" for e in effects):
        effects.append(make_effect("quantization", bits=int(bits)))
    return effects


def unclipped_components(effects: Sequence[Effect], meta: CameraMetadata, v: np.ndarray) -> dict[str, np.ndarray]:
    """Unclipped variance (DN^2) per measured component at intensities ``v``."""
    cond = Conditions.from_meta(meta)
    for e in effects:
        if e.distribution == "modifier":
            cond = e.modify(cond)
    out = {c: np.zeros(v.shape) for c in MEASURED}
    for e in effects:
        comp = component_of(e)
        if comp is None:
            continue
        if e.distribution == "mixture":  # offsets cannot push a pixel beyond the clipping limits
            frac, off = e.mixture(v, cond)
            var = frac * (1.0 - frac) * _clipped_offset(off, v) ** 2
        else:
            var = e.variance_dn2(v, cond)
        out[comp] = out[comp] + np.asarray(var, dtype=float)
    return out


def _clipped_offset(off: Any, v: np.ndarray) -> np.ndarray:
    return np.clip(np.broadcast_to(np.asarray(off, dtype=float), v.shape), -v, DN_MAX - v)


def tail_pixels(effects: Sequence[Effect], meta: CameraMetadata, v: np.ndarray, sigma: np.ndarray, pixels: int) -> float:
    """Expected outlier pixels (|residual| > OUTLIER_PIXEL_SIGMAS x sigma) from fixed-pattern mixtures."""
    cond = Conditions.from_meta(meta)
    for e in effects:
        if e.distribution == "modifier":
            cond = e.modify(cond)
    s = np.maximum(sigma, 1e-6)
    thr = OUTLIER_PIXEL_SIGMAS * s
    total = 0.0
    for e in effects:
        if e.distribution == "mixture" and not e.temporal:
            frac, off = e.mixture(v, cond)
            off = _clipped_offset(off, v)
            p = ndtr((off - thr) / s) + ndtr((-off - thr) / s)
            total += float(np.sum(frac * p)) * pixels
    return total


def predicted_step(effects: Sequence[Effect], meta: CameraMetadata, output_step: float) -> float:
    """Median gap between occupied output levels that the model's quantization produces."""
    lsbs = [e.lsb_dn(Conditions.from_meta(meta)) for e in effects if e.distribution == "quantization"]
    lsb = max(lsbs, default=0.0)
    if output_step <= 0.0:
        return lsb
    if lsb <= output_step:
        return output_step
    levels = np.unique(np.rint(np.arange(0.0, 255.0 + lsb, lsb) / output_step))
    return float(np.median(np.diff(levels))) * output_step


def model_curve(effects: Sequence[Effect], meta: CameraMetadata, v: np.ndarray) -> np.ndarray:
    """Model total sigma (DN) at intensities ``v``: clip-aware ``predict`` plus the quantization's LSB^2/12."""
    clip_model = NoiseModel([e for e in effects if e.distribution != "quantization"])
    quant = unclipped_components([e for e in effects if e.distribution == "quantization"], meta, np.asarray(v, float))
    return np.sqrt(np.asarray(clip_model.predict(v, meta)["total"]) ** 2 + sum(quant.values()))


@dataclass
class _SegmentBase:
    seg: SegmentMeasurement
    cells: list[Cell]
    clip_aware: dict[str, np.ndarray]  # component -> per-block variance
    total: np.ndarray  # per-block clip-aware total variance
    unclipped: dict[str, np.ndarray]

    def __post_init__(self) -> None:
        self.average = np.zeros((len(self.cells), self.seg.intensity_dn.size))
        for i, c in enumerate(self.cells):
            self.average[i, c.block_index] = 1.0 / c.block_index.size
        self.observed = tuple(self.cells[0].values)
        self.values = np.array([[c.values[k] for k in self.observed] for c in self.cells])
        self.errors = np.maximum(np.array([[c.errors[k] for k in self.observed] for c in self.cells]), 1e-9)

    def model_cells(self, comps: dict[str, np.ndarray]) -> np.ndarray:
        """Model variance per cell (rows) and observed component (columns)."""
        cols = [comps["temporal"] + comps["fixed"] if k == "single" else comps[k] for k in self.observed]
        return self.average @ np.stack(cols, axis=1)


class Comparison:
    """Measurements paired with a model's prediction for the same segments and blocks."""

    def __init__(self, meas: Measurements, model: NoiseModel, progress: Any = None) -> None:
        self.meas = meas
        self.model = model
        self.effects = list(model.effects)
        by_seg: dict[int, list[Cell]] = {}
        for c in meas.cells:
            by_seg.setdefault(c.segment, []).append(c)
        self.segments: list[_SegmentBase] = []
        quant = [e for e in self.effects if e.distribution == "quantization"]
        clip_model = NoiseModel([e for e in self.effects if e.distribution != "quantization"])
        for seg in meas.segments:
            if seg.index not in by_seg:
                continue
            pred = clip_model.predict(seg.intensity_dn, seg.meta)
            comps = {c: np.zeros(seg.intensity_dn.shape) for c in MEASURED}
            for e in clip_model.noise_effects:
                comps[component_of(e)] = comps[component_of(e)] + np.asarray(pred[e.name], dtype=float) ** 2
            q = unclipped_components(quant, seg.meta, seg.intensity_dn)
            comps = {c: a + q[c] for c, a in comps.items()}
            total = np.asarray(pred["total"], dtype=float) ** 2 + sum(q.values())
            summed = sum(comps.values())
            scale = np.where(summed > 0, total / np.maximum(summed, 1e-300), 1.0)
            comps = {c: a * scale for c, a in comps.items()}
            self.segments.append(_SegmentBase(seg, by_seg[seg.index], comps, total,
                                              unclipped_components(self.effects, seg.meta, seg.intensity_dn)))
            if progress is not None:
                progress.update(1)

    # --- predictions -------------------------------------------------------------------------
    def replaced(self, extra: Sequence[Effect]) -> list[Effect]:
        """The model's effects with ``extra`` added (replacing effects of the same name)."""
        names = {e.name for e in extra}
        return [e for e in self.effects if e.name not in names] + list(extra)

    def predict_with(self, extra: Sequence[Effect] = ()) -> list[tuple[_SegmentBase, dict[str, np.ndarray]]]:
        """Per segment: per-block component variances of the model with ``extra`` effects added
        (replacing effects of the same name): clip-aware baseline + unclipped change."""
        if not extra:
            return [(sb, sb.clip_aware) for sb in self.segments]
        effects = self.replaced(extra)
        out = []
        for sb in self.segments:
            new = unclipped_components(effects, sb.seg.meta, sb.seg.intensity_dn)
            out.append((sb, {c: np.maximum(sb.clip_aware[c] + new[c] - sb.unclipped[c], 0.0) for c in MEASURED}))
        return out

    def residuals(self, extra: Sequence[Effect] = ()) -> np.ndarray:
        """Normalised residuals (measured - model) / error of every observable, for chi-square fits."""
        effects = self.replaced(extra) if extra else self.effects
        res = []
        for sb, comps in self.predict_with(extra):
            res.extend(((sb.values - sb.model_cells(comps)) / sb.errors).ravel())
            seg = sb.seg
            per_block = seg.pixels_checked // max(1, seg.intensity_dn.size)
            expected = tail_pixels(effects, seg.meta, seg.intensity_dn, seg.robust_sigma_dn, per_block)
            res.append((seg.outlier_pixels - expected) / math.sqrt(max(expected, seg.outlier_pixels, 1.0)))
        if math.isfinite(self.meas.quant_step_dn):
            step = predicted_step(effects, self.segments[0].seg.meta, self.meas.output_step_dn)
            err = math.hypot(self.meas.quant_step_err_dn, STEP_SYSTEMATIC_DN)
            res.append((self.meas.quant_step_dn - step) / err)
        return np.asarray(res)

    # --- reporting ---------------------------------------------------------------------------
    def cell_table(self, extra: Sequence[Effect] = ()) -> list[dict[str, Any]]:
        """One row per cell: conditions, measured and model sigma (DN) per component and in total
        (with ``extra`` effects: the additive approximation of :meth:`predict_with`)."""
        pairs = self.predict_with(extra)
        rows = []
        t0 = self.meas.segments[0].stamp_ns
        for sb, comps in pairs:
            seg = sb.seg
            for cell in sb.cells:
                model = _cell_model(cell, comps)
                meas_total = sum(cell.values.values())
                err_total = math.sqrt(sum(e * e for e in cell.errors.values()))
                model_total = sum(model[c] for c in MEASURED)
                ms, mm = math.sqrt(max(meas_total, 0.0)), math.sqrt(max(model_total, 0.0))
                rows.append({
                    "segment": seg.index,
                    "time_s": (seg.stamp_ns - t0) * 1e-9,
                    "gain_db": seg.meta.gain_db,
                    "exposure_time_s": seg.meta.exposure_time_s,
                    "sensor_temperature_c": seg.meta.sensor_temperature_c,
                    "intensity_dn": cell.intensity_dn,
                    "blocks": int(cell.block_index.size),
                    "frames": seg.n_frames,
                    "measured_sigma_dn": ms,
                    "measured_sigma_err_dn": err_total / (2.0 * max(ms, 1e-3)),
                    "model_sigma_dn": mm,
                    "residual_dn": ms - mm,
                    "measured_var_dn2": dict(cell.values),
                    "measured_var_err_dn2": dict(cell.errors),
                    "model_var_dn2": {c: model[c] for c in cell.values},
                })
        return rows


def _cell_model(cell: Cell, comps: dict[str, np.ndarray]) -> dict[str, float]:
    idx = cell.block_index
    out = {c: float(np.mean(comps[c][idx])) for c in MEASURED}
    out["single"] = out["temporal"] + out["fixed"]
    return out


def rms_error(rows: Iterable[dict[str, Any]]) -> float:
    r = np.asarray([row["residual_dn"] for row in rows])
    return float(np.sqrt(np.mean(r**2))) if r.size else float("nan")


def _group_key(row: dict[str, Any], key: str, time_edges: np.ndarray) -> Any:
    if key == "intensity_dn":
        return int(row["intensity_dn"] // 32) * 32
    if key == "gain_db":
        return round(row["gain_db"], 1)
    if key == "exposure_time_s":
        return float(f"{row['exposure_time_s']:.3g}")
    if key == "sensor_temperature_c":
        return round(row["sensor_temperature_c"] / 5.0) * 5.0
    if key == "time_s":
        i = int(np.searchsorted(time_edges, row["time_s"], side="right")) - 1
        return round(float(time_edges[max(i, 0)]), 3)
    raise KeyError(key)


def by_condition(rows: Sequence[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    """Where the model fails: residual tables per intensity, gain, exposure, temperature, time and
    per component (temporal vs fixed-pattern vs column / row structure)."""
    out: dict[str, list[dict[str, Any]]] = {}
    if not rows:
        return out
    times = np.asarray([r["time_s"] for r in rows])
    time_edges = np.linspace(times.min(), times.max() + 1e-9, min(8, len(set(times.tolist()))) + 1)[:-1]
    for key in ("intensity_dn", "gain_db", "exposure_time_s", "sensor_temperature_c", "time_s"):
        groups: dict[Any, list[dict[str, Any]]] = {}
        for r in rows:
            groups.setdefault(_group_key(r, key, time_edges), []).append(r)
        table = []
        for value in sorted(groups):
            g = groups[value]
            res = np.asarray([r["residual_dn"] for r in g])
            table.append({
                key: value,
                "cells": len(g),
                "measured_sigma_dn": float(np.sqrt(np.mean([r["measured_sigma_dn"] ** 2 for r in g]))),
                "model_sigma_dn": float(np.sqrt(np.mean([r["model_sigma_dn"] ** 2 for r in g]))),
                "mean_residual_dn": float(res.mean()),
                "rms_residual_dn": float(np.sqrt(np.mean(res**2))),
            })
        out[key] = table
    comp_table = []
    for comp in ("temporal", "fixed", "column", "row", "single"):
        g = [r for r in rows if comp in r["measured_var_dn2"]]
        if not g:
            continue
        ms = np.sqrt(np.maximum([r["measured_var_dn2"][comp] for r in g], 0.0))
        mm = np.sqrt(np.maximum([r["model_var_dn2"][comp] for r in g], 0.0))
        comp_table.append({
            "component": comp,
            "cells": len(g),
            "measured_sigma_dn": float(np.sqrt(np.mean(ms**2))),
            "model_sigma_dn": float(np.sqrt(np.mean(mm**2))),
            "mean_residual_dn": float(np.mean(ms - mm)),
            "rms_residual_dn": float(np.sqrt(np.mean((ms - mm) ** 2))),
        })
    out["component"] = comp_table
    return out
