"""Which segments the model is not compared with when the noise changed inside holds, and what they hold.

A change of the noise while the camera held still and its conditions stayed (:mod:`.hold_change`) is no function of
the conditions: no effect of the model can explain both sides of it, and a fit over both reads the mixture as a
missing law. So the side of each change that the model fits worse is *set apart* as an event, with every segment
between two changes facing each other (a fault seen to start and to end), and reported with its excess over the
model per component (a fault adding white noise of sigma s shows as +s^2 per pixel in the temporal component).

A fault that starts and ends between holds (in pans, at metadata changes) shows no change inside one. It shows as
noise no law of the conditions makes: every effect's temporal variance grows (in magnitude) with the gain, the
exposure, the temperature and the signal, so a cell under conditions at least as high in every one as another's
cannot hold much less excess over the model (but where the noise is small against a coarse quantization step, whose
added variance follows where the signal falls between two levels: such cells order nothing). The run of segments in
time from the first to the last such louder segment is set apart (:func:`lawless`), with its neighbours alike to it.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..monitor.noise_change import CHANGE_SIGMAS
from .compare import rms_error_raw
from .hold_change import CHANGE_DN
from .measure import BIN_WIDTH_DN, Measurements

#: smallest excess variance (DN^2 per pixel) of a set-apart run named in its line (also beyond 3 standard errors)
NOTABLE_DN2 = 0.1
#: the conditions a law's temporal variance grows with (in magnitude), as the cell table names them
CONDITIONS = ("gain_db", "exposure_time_s", "sensor_temperature_c", "intensity_dn")
#: cells whose model temporal sigma lies below this fraction of a measured quantization step coarser than the output's
#: are ordered by no condition: there the quantized variance follows where the signal falls between two levels (a
#: 6-bit output's 4 DN step on noise of 1 DN adds anything from -1 to +3 DN^2); from it on the step adds its
#: step^2 / 12 to every cell within 1 % of that
QUANTIZED_SIGMA = 0.5


@dataclass(frozen=True)
class Apart:
    """The segments set apart, those of them set apart by their likeness to an event seen at one end only, and those
    of a run seen to break every law of the conditions (no end inside a hold: :func:`lawless`)."""

    segments: set[int]
    alike: set[int]
    lawless: set[int]


def coarse_step(meas: Measurements) -> float:
    """The measured quantization step (DN) when it is coarser than the output's own (0 otherwise or not measured)."""
    step = meas.quant_step_dn
    return step if math.isfinite(step) and step > max(meas.output_step_dn, 1.0) else 0.0


def set_apart(meas: Measurements, rows: Sequence[dict[str, Any]]) -> Apart:
    """The segments set apart from the comparison: on each change's side whose part of the hold the model fits worse
    (the larger rms residual of its cells ``rows``), every segment between two changes that both face it (a fault
    seen to start and to end), and from each change's event side onwards, up to the next change, the segments whose
    excess variance over the model (mean over their cells) lies nearer the event part's than the other part's, until
    the first that does not (between holds a change is not seen: a fault that ends or starts in a pan)."""
    order = [s.index for s in meas.segments]
    changed = sorted(meas.after_changes())
    by_segment: dict[int, list[dict[str, Any]]] = {}
    for r in rows:
        by_segment.setdefault(r["segment"], []).append(r)

    cells = [by_segment.get(i, []) for i in order]
    error = [rms_error_raw(c) if c else math.nan for c in cells]
    excess = [float(np.mean([r["measured_sigma_dn"] ** 2 - r["model_sigma_dn"] ** 2 for r in c])) if c else math.nan
              for c in cells]
    # +1: the event is after the change, -1: before it, 0: unknown (a side without cells: NaN)
    side = [int(np.nan_to_num(np.sign(error[j] - error[j - 1]))) for j in changed]
    apart = {order[j] if s > 0 else order[j - 1] for j, s in zip(changed, side) if s}
    for (a, a_side), (b, b_side) in zip(zip(changed, side), zip(changed[1:], side[1:])):
        if a_side > 0 and b_side < 0:
            apart.update(order[a:b])
    alike: set[int] = set()
    for n, (j, s) in enumerate(zip(changed, side)):
        if not s:
            continue
        event, other = (excess[j], excess[j - 1]) if s > 0 else (excess[j - 1], excess[j])
        scan = (range(j + 1, changed[n + 1] if n + 1 < len(changed) else len(order)) if s > 0 else
                range(j - 2, (changed[n - 1] if n > 0 else 0) - 1, -1))
        for k in scan:
            x = excess[k]
            if math.isfinite(x) and abs(x - event) >= abs(x - other):
                break
            if math.isfinite(x) and order[k] not in apart:
                alike.add(order[k])
    apart |= alike
    rest = [i for i in order if i not in apart]
    run, like = lawless([r for r in rows if r["segment"] not in apart], rest, dict(zip(order, excess)), coarse_step(meas))
    return Apart(apart | run, alike | like, run)


def quieter_than_conditions(rows: Sequence[dict[str, Any]], step_dn: float = 0.0) -> set[tuple[int, int]]:
    """The pairs (segment a, segment b) of cells ``rows`` of one intensity bin where a's conditions
    (:data:`CONDITIONS`) are at least b's in every one and b's temporal excess variance over the model exceeds a's in
    magnitude beyond ``CHANGE_SIGMAS`` standard errors and by ``CHANGE_DN`` in sigma (at b's model): no law of the
    conditions makes them. One bin: a cell's intensity also says where its blocks lie (the scene's bright and dark
    parts), and a law of the position (an amplifier's glow in a corner) orders cells of other intensities by
    where they are. A condition not stated (NaN) orders nothing; nor do cells whose model noise lies below
    ``QUANTIZED_SIGMA`` of a coarse quantization step ``step_dn`` (:func:`coarse_step`)."""
    rows = [r for r in rows if "temporal" in r["measured_var_dn2"]  # a recording without holds has none
            and r["model_var_dn2"]["temporal"] >= (QUANTIZED_SIGMA * step_dn) ** 2]
    if not rows:
        return set()
    cond = np.array([[np.nan if r[c] is None else r[c] for c in CONDITIONS] for r in rows], dtype=float)
    model = np.array([r["model_var_dn2"]["temporal"] for r in rows])
    size = np.abs(np.array([r["measured_var_dn2"]["temporal"] for r in rows]) - model)
    err = np.array([r["measured_var_err_dn2"]["temporal"] for r in rows])
    seg = np.array([r["segment"] for r in rows])
    level = np.floor(cond[:, CONDITIONS.index("intensity_dn")] / BIN_WIDTH_DN)
    pairs: set[tuple[int, int]] = set()
    for one in np.unique(level):  # [a, b] within each bin
        i = np.flatnonzero(level == one)
        c, m, x, e, g = cond[i], model[i], size[i], err[i], seg[i]
        broken = (np.all(c[:, None, :] >= c[None, :, :], axis=2) & (g[:, None] != g[None, :])
                  & (x[None, :] - x[:, None] > CHANGE_SIGMAS * np.hypot(e[None, :], e[:, None]))
                  & (np.sqrt(m + x)[None, :] - np.sqrt(m[None, :] + x[:, None]) >= CHANGE_DN))
        pairs.update((int(g[a]), int(g[b])) for a, b in zip(*np.nonzero(broken)))
    return pairs


def lawless(rows: Sequence[dict[str, Any]], order: Sequence[int], excess: dict[int, float], step_dn: float = 0.0
            ) -> tuple[set[int], set[int]]:
    """(the run of segments set apart as noise no law of the conditions makes, those of them set apart by likeness).
    The run: the segments of ``order`` (segment indices in time) from the first to the last louder segment of a pair
    of :func:`quieter_than_conditions` (the shortest run that leaves no pair outside it); then its neighbours whose
    ``excess`` (mean over their cells, DN^2) lies nearer the run's mean than the rest's median, until the first that
    does not. Empty without a pair."""
    pairs = quieter_than_conditions(rows, step_dn)
    if not pairs:
        return set(), set()
    where = [order.index(b) for _, b in pairs]
    i, j = min(where), max(where) + 1
    run = set(order[i:j])
    event = float(np.nanmean([excess[k] for k in run]))
    other = float(np.nanmedian([excess[k] for k in order if k not in run])) if len(run) < len(order) else math.nan
    like: set[int] = set()
    for scan in (range(i - 1, -1, -1), range(j, len(order))):
        for k in scan:
            x = excess[order[k]]
            if not math.isfinite(other) or (math.isfinite(x) and abs(x - event) >= abs(x - other)):
                break
            if math.isfinite(x):
                like.add(order[k])
    return run | like, like


def without_segments(meas: Measurements, apart: set[int]) -> Measurements:
    """``meas`` with the cells of the ``apart`` segments left out (the segments stay: their views still separate
    the fixed pattern of others)."""
    return replace(meas, cells=[c for c in meas.cells if c.segment not in apart])


def events(meas: Measurements, apart: Apart, rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The runs of consecutive set-apart segments: time span, whether a change was seen at each end, frames, cells and
    the mean excess variance (measured - model, DN^2 per pixel) per component with its standard error."""
    t0 = meas.segments[0].stamp_ns
    after_change = meas.after_changes()
    runs: list[list[int]] = []
    for j, seg in enumerate(meas.segments):
        if seg.index in apart.segments:
            if runs and runs[-1][-1] == j - 1:
                runs[-1].append(j)
            else:
                runs.append([j])
    out = []
    for run in runs:
        segs = [meas.segments[j] for j in run]
        mine = [r for r in rows if r["segment"] in {s.index for s in segs}]
        excess = {}
        for c in (mine[0]["measured_var_dn2"] if mine else {}):
            d = np.array([r["measured_var_dn2"][c] - r["model_var_dn2"][c] for r in mine])
            err = math.sqrt(sum(r["measured_var_err_dn2"][c] ** 2 for r in mine)) / len(mine)
            excess[c] = {"dn2": round(float(d.mean()), 4), "err_dn2": round(err, 4)}
        after = run[-1] + 1
        out.append({
            "segments": [s.index for s in segs],
            "from_s": round((segs[0].stamp_ns - t0) * 1e-9, 4),
            "to_s": round((segs[-1].last_stamp_ns - t0) * 1e-9, 4),
            "starts_at_change": run[0] in after_change,
            "ends_at_change": after in after_change,
            "frames": sum(s.n_frames for s in segs),
            "alike": [s.index for s in segs if s.index in apart.alike],
            "lawless": [s.index for s in segs if s.index in apart.lawless],
            "cells": len(mine),
            "mean_residual_dn": round(float(np.mean([r["residual_dn"] for r in mine])), 4) if mine else None,
            "excess_var_dn2": excess,
        })
    return out


def events_text(changes: Sequence[dict[str, Any]], apart: Sequence[dict[str, Any]]) -> list[str]:
    """Lines for people: the changes and what was set apart."""
    lines = ["noise changed inside holds (camera still, conditions unchanged): " + ", ".join(
        f"{c['time_s']:.2f} s ({_dn(c['sigma_before_dn'])} -> {_dn(c['sigma_after_dn'])} DN)" for c in changes)
             ] if changes else []
    for ev in apart:
        strong = [(c, v) for c, v in ev["excess_var_dn2"].items()
                  if abs(v["dn2"]) > max(3.0 * v["err_dn2"], NOTABLE_DN2)]
        what = "; ".join(f"{c} {v['dn2']:+.2f} +- {v['err_dn2']:.2f} DN^2 per pixel"
                         + (f" (sigma {math.sqrt(v['dn2']):.2f} DN)" if v["dn2"] > 0 else "") for c, v in strong)
        ends = {(True, True): "between two changes", (True, False): "from a change", (False, True): "up to a change",
                (False, False): "next to a change"}[(ev["starts_at_change"], ev["ends_at_change"])]
        if ev["lawless"] and not (ev["starts_at_change"] or ev["ends_at_change"]):
            ends = ("no change seen inside a hold: further from the model than segments under a gain, exposure, temperature and "
                    "intensity at least as high, which no law of the conditions makes")
        like = "the side of the change" if ev["starts_at_change"] or ev["ends_at_change"] else "the rest of the run"
        alike = f", {len(ev['alike'])} of them by their likeness to {like}" if ev["alike"] else ""
        lines.append(f"set apart {ev['from_s']:.2f}-{ev['to_s']:.2f} s ({ends}; {len(ev['segments'])} segment(s){alike}, {ev['frames']} "
                     f"frames, {ev['cells']} cells): beyond the model {what or 'nothing significant'}; not a function of "
                     "the conditions (a fault, interference, the driver switching its processing, metadata misstating them): the model is "
                     "compared with the rest")
    return lines


def _dn(value: float | None) -> str:
    return "?" if value is None else f"{value:.2f}"
