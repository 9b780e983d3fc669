"""The residual's signature in physics terms: what the model misses when no candidate effect explains it.

From a :class:`~.compare.Comparison` (measured vs model variance per cell and per measured component,
block positions on the sensor) the signature says

- **temporal or fixed**: which measured components carry a significant excess (or deficit) of variance;
- **its law**: the power of intensity, exposure time and gain, and whether it follows the dark
  current's temperature law, fitted to the per-cell excess of the dominant component; the gain power
  reads as electrons (before the gain: variance x gain^2) or DN (after it: independent of the gain);
  an excess towards a sensor corner is fitted with that corner's shape (each cell's mean over its
  blocks), so a scene that happens to be brighter near the corner is not read as an intensity law;
- **its spatial structure**: rows or columns (fixed, or changing from frame to frame), isolated pixels
  (outliers of the frame average, a sparse fixed pattern whose kurtosis the model's Gaussian patterns
  cannot give, or pixels blinking between frames), a corner or a gradient across
  the sensor (block excess vs position), or white pixel-wise noise;

and suggests how a plug-in would express it (distribution, temporal flag, structure, position).
:func:`plugin_skeleton` writes that plug-in, prefilled with the fitted law, for the user to complete.
"""
from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.stats import f as f_dist

from ..physics import Effect
from ..physics.sensor import dark_electrons
from .compare import Comparison, as_measured, at_block, gaussian_fixed
from .measure import CROSS_VIEW

#: a component's weighted mean excess must be this many standard errors from zero to count
Z_SIGNIFICANT = 5.0
#: the same for the amplitude of the best of the laws tried (more: it is picked among many)
Z_LAW_SIGNIFICANT = 10.0
#: ... and at least this fraction of the component's model variance plus the total, in the cells where it
#: is measured (guards 8-bit rounding details and residual scene texture that the errors do not capture)
MIN_RELATIVE_EXCESS = 0.03
#: excess outlier / blinking pixels must also reach this fraction of the pixels checked (a few 6-sigma
#: outliers are what 8-bit rounding and texture leave on clean data)
MIN_PIXEL_FRACTION = 1e-3
#: p-value of the F-test for a spatial pattern (block excess vs position) and for law terms
SPATIAL_P = 1e-6
#: a spatial pattern must also explain this fraction of the block excess variance beyond segment means
MIN_SPATIAL_R2 = 0.15
#: length scale (sensor heights/widths) of the corner shape tried against the block excess
CORNER_SCALE = 0.3
TEMPORAL = ("temporal", "temporal_row", "temporal_column")
FIXED = ("fixed", "row", "column", "outlier")
LINE_TRAITS = {
    "row": "rows (a fixed offset per row)",
    "column": "columns (a fixed offset per column)",
    "temporal_row": "rows changing from frame to frame",
    "temporal_column": "columns changing from frame to frame",
}
#: intensity laws tried: exponent of the intensity, or "full_well" (a variance change concentrated near
#: the top of the range: (v / 255)^8)
INTENSITY_LAWS: tuple[Any, ...] = (0, 1, 2, "full_well")
POWERS = (0, 1, 2)
REGIONS = {
    "top-left corner": (0.0, 0.0),
    "top-right corner": (0.0, 1.0),
    "bottom-left corner": (1.0, 0.0),
    "bottom-right corner": (1.0, 1.0),
}


@dataclass
class _Obs:
    """Per-cell (or per-segment, for pooled components) excess of one component."""

    excess: np.ndarray
    error: np.ndarray
    model: np.ndarray
    total: np.ndarray  # the cell's total model variance
    intensity: np.ndarray
    exposure: np.ndarray
    gain: np.ndarray
    dark_rate: np.ndarray
    pooled: bool
    #: the cells' mean of a corner shape the excess follows (ones: none), and that corner
    position: np.ndarray
    corner: str | None = None


def cross_view_condition(values: dict[int, float], here: int, partners: dict[int, float]) -> float:
    """A segment condition (exposure, gain, dark current) where a cross-view component is measured: the geometric
    mean of its value ``here`` and in the ``partners`` (segment -> share of the weight)."""
    logs = sum(share * math.log(max(values[j], 1e-300)) for j, share in partners.items())
    return math.exp(0.5 * (math.log(max(values[here], 1e-300)) + logs / max(sum(partners.values()), 1e-300)))


def _observations(rows: Sequence[dict[str, Any]], comp: str, pooled: bool,
                  conditions: dict[str, dict[int, float]], corner: tuple[str, np.ndarray] | None = None) -> _Obs | None:
    """The component's excess per cell (per segment when pooled), with the conditions it is measured at (cross-view
    components: the geometric means over the views, ``cell_table``'s ``cross_view``); ``conditions``: per
    segment, its ``exposure``, ``gain`` (linear) and ``dark`` (dark current); ``corner``: (its name, each row's mean
    of its shape), a factor of the law."""
    seen: set[int] = set()
    data = []
    for i, r in enumerate(rows):
        if comp not in r["measured_var_dn2"]:
            continue
        if pooled:
            if r["segment"] in seen:
                continue
            seen.add(r["segment"])
        m, p = r["measured_var_dn2"][comp], r["model_var_dn2"].get(comp, 0.0)
        cross = r.get("cross_view") if comp in CROSS_VIEW else None
        at = ([r["intensity_dn"]] + [conditions[k][r["segment"]] for k in ("exposure", "gain", "dark")] if cross is None
              else [cross["intensity_dn"]] + [cross_view_condition(conditions[k], r["segment"], cross["partners"])
                                              for k in ("exposure", "gain", "dark")])
        data.append((m - p, max(r["measured_var_err_dn2"][comp], 1e-9), p, sum(r["model_var_dn2"].values()),
                     *at, 1.0 if corner is None else corner[1][i]))
    if not data:
        return None
    excess, error, model, total, intensity, exposure, gain, dark_rate, position = np.asarray(data, dtype=float).T
    return _Obs(excess=excess, error=error, model=model, total=total, intensity=intensity, exposure=exposure,
                gain=gain, dark_rate=dark_rate, pooled=pooled, position=position, corner=corner and corner[0])


def _component_stats(obs: _Obs) -> dict[str, Any]:
    """Weighted mean excess and its z; the best law's amplitude and its z (an excess concentrated in a few
    cells, e.g. near full well, shows there); significant if either clears its z threshold and is at
    least MIN_RELATIVE_EXCESS of the model where it is measured: the floor averaged with the excess's
    weights (a campaign's high-gain holds, whose large variance weighs little in the mean excess, do not
    raise it), or at the cell where the law is largest."""
    w = 1.0 / obs.error**2
    mean = float(np.sum(w * obs.excess) / np.sum(w))
    err = float(1.0 / math.sqrt(np.sum(w)))
    model = float(np.mean(obs.model))
    z = mean / err
    floor = MIN_RELATIVE_EXCESS * (obs.model + obs.total)
    law = fit_law(obs)
    f = _law_basis(obs, law["law"])
    z_law = law["amplitude_dn2"] * math.sqrt(float(np.sum(w * f * f)))
    peak = int(np.argmax(np.abs(law["amplitude_dn2"] * f)))
    significant = (abs(z) >= Z_SIGNIFICANT and abs(mean) >= float(np.sum(w * floor) / np.sum(w))) or \
        (abs(z_law) >= Z_LAW_SIGNIFICANT and abs(law["amplitude_dn2"] * f[peak]) >= floor[peak])
    return {"excess_dn2": mean, "excess_err_dn2": err, "model_dn2": model, "z": z, "law_z": z_law,
            "significant": bool(significant), "_law": law}


def _law_basis(obs: _Obs, law: tuple[Any, int, int, int]) -> np.ndarray:
    a, b, g, d = law
    v = np.maximum(obs.intensity, 1.0)
    f = (v / 255.0) ** 8 if a == "full_well" else (v / 128.0) ** a
    f = f * (obs.exposure / np.median(obs.exposure)) ** b * (obs.gain / np.median(obs.gain)) ** g
    return f * (obs.dark_rate / np.median(obs.dark_rate)) ** d * obs.position


def fit_law(obs: _Obs) -> dict[str, Any]:
    """The product law intensity^a x exposure^b x gain^g x dark-rate(T)^d (x the cells' corner shape, if
    any: the amplitude is then the one at the corner) that best fits the excess (one amplitude; each
    non-zero power costs ln(n) in the BIC); axes that do not vary are not fitted."""
    varies = {
        "intensity": bool(not obs.pooled and np.ptp(obs.intensity) > 0.2 * np.mean(obs.intensity)),
        "exposure": bool(np.ptp(np.log(obs.exposure)) > 0.3),
        "gain": bool(np.ptp(np.log(obs.gain)) > 0.3),
        "temperature": bool(np.ptp(np.log(obs.dark_rate)) > 0.3),
    }
    w = 1.0 / obs.error**2
    n = obs.excess.size
    best = None
    for law in itertools.product(INTENSITY_LAWS if varies["intensity"] else (0,),
                                 POWERS if varies["exposure"] else (0,),
                                 POWERS if varies["gain"] else (0,),
                                 (0, 1) if varies["temperature"] else (0,)):
        f = _law_basis(obs, law)
        amp = float(np.sum(w * obs.excess * f) / max(np.sum(w * f * f), 1e-300))
        chi2 = float(np.sum(w * (obs.excess - amp * f) ** 2))
        terms = sum(1 for x in law if x != 0)
        bic = chi2 + terms * math.log(max(n, 2))
        if best is None or bic < best[0]:
            best = (bic, law, amp, chi2)
    assert best is not None
    _, (a, b, g, d), amp, chi2 = best
    return {"law": (a, b, g, d), "intensity_power": a, "exposure_power": b, "gain_power": g, "dark_current_law": bool(d),
            "amplitude_dn2": amp, "chi2": chi2, "observations": n, "varied": varies,
            "reference": {"intensity_dn": 128.0, "exposure_time_s": float(np.median(obs.exposure)),
                          "gain": float(np.median(obs.gain)), **({"at": obs.corner} if obs.corner else {})}}


def _law_text(law: dict[str, Any], pooled: bool) -> str:
    v = law["varied"]
    parts = []
    a = law["intensity_power"]
    if not v["intensity"]:
        parts.append("of unresolved intensity law" + (" (pooled over each segment)" if pooled else ""))
    else:
        parts.append({0: "independent of the intensity", 1: "proportional to the intensity (shot-noise-like)",
                      2: "proportional to the intensity squared (gain-like)",
                      "full_well": "concentrated near the top of the range (full well)"}[a])
    if v["exposure"]:
        parts.append({0: "independent of the exposure time", 1: "proportional to the exposure time",
                      2: "proportional to the exposure time squared"}[law["exposure_power"]])
    if v["gain"]:
        parts.append({0: "independent of the gain (arises after it: constant in DN)",
                      1: "proportional to the gain (like shot noise in DN)",
                      2: "proportional to the gain squared (arises before it: constant in electrons)"}[law["gain_power"]])
    if v["temperature"]:
        parts.append("following the dark current's temperature law" if law["dark_current_law"]
                     else "independent of the temperature")
    at = law["reference"].get("at")
    return "variance " + (f"(at the {at}, fitted with its shape) " if at else "") + ", ".join(parts)


def _rss(design: np.ndarray, x: np.ndarray) -> tuple[float, np.ndarray]:
    """(residual sum of squares, coefficients) of the least-squares fit of x on design's columns."""
    coef = np.linalg.lstsq(design, x, rcond=None)[0]
    return float(np.sum((x - design @ coef) ** 2)), coef


def _corner_shape(pos: np.ndarray, label: str) -> np.ndarray:
    """exp(-d / CORNER_SCALE), d: the distance of normalised (y, x) positions to the corner ``label``."""
    y0, x0 = REGIONS[label]
    return np.exp(-np.hypot(pos[:, 0] - y0, pos[:, 1] - x0) / CORNER_SCALE)


def _corner_factor(comp: Comparison, found: dict[str, Any] | None) -> tuple[str, np.ndarray] | None:
    """For a significant excess towards a corner: (the corner, each cell's mean of its shape over the cell's
    blocks, in cell-table order); None otherwise."""
    if not (found and found["significant"] and found["shape"] in REGIONS and found["pattern"].startswith("towards")):
        return None
    return found["shape"], np.concatenate([sb.average @ _corner_shape(sb.pos, found["shape"]) for sb in comp.segments])


def position_pattern(comp: Comparison, name: str, extra: Sequence[Effect] = (),
                     shape: str | None = None) -> dict[str, Any] | None:
    """Best corner or gradient shape (or the given ``shape``) for the block excess of component ``name``
    over the model with ``extra`` effects (scaled per segment, beyond a level and intensity law per
    segment); ``strength``: the block excess variance (DN^4 summed over blocks) the shape explains.

    The fixed component counts only in segments measured across views: a single view's fixed pattern is
    the hold mean's residual, where a region of fine scene texture would read as a position law (so does a single
    frame's noise where the view shows the scene: ``SegmentMeasurement.scene_dn2``). A
    component whose partner views showed the scene (``Measurements.scene_in_views``) has no position
    pattern: the scene's share of each block follows the optics (vignetting), not the sensor."""
    if name in comp.meas.scene_in_views:
        return None
    xs, segs, pos, vs = [], [], [], []
    for j, (sb, comps) in enumerate(comp.predict_with(extra)):
        if (name not in sb.seg.values or (name == "fixed" and not sb.seg.partners)
                or (name == "single" and sb.seg.scene_dn2 is not None)):
            continue
        model = at_block(comps, name) if name == "fixed" else as_measured(sb, comps, name)
        xs.append(sb.seg.values[name][sb.rep] - model)
        segs.append(np.full(sb.rep.size, j))
        pos.append(sb.pos)
        vs.append(sb.v / 128.0)
    if not xs:
        return None
    x, seg, p, v = np.concatenate(xs), np.concatenate(segs), np.concatenate(pos), np.concatenate(vs)
    ids = np.unique(seg)
    rows = [np.flatnonzero(seg == i) for i in ids]
    # per segment: a level and an intensity law (v, v^2), so intensity-driven excess is not read as position;
    # the design is block-diagonal over segments, so each segment is fitted on its own (same least squares)
    nuisance = np.stack([np.ones_like(v), v, v**2], axis=1)
    rss0_by = np.array([_rss(nuisance[r], x[r])[0] for r in rows])
    rss0 = float(rss0_by.sum())
    shapes = {k: _corner_shape(p, k) for k in REGIONS}
    shapes["gradient from top to bottom"] = p[:, 0] - 0.5
    shapes["gradient from left to right"] = p[:, 1] - 0.5
    if shape is not None:
        shapes = {shape: shapes[shape]}
    best = None
    for label, h in shapes.items():
        design = np.concatenate([nuisance, h[:, None]], axis=1)
        fits = [_rss(design[r], x[r]) for r in rows]
        rss = float(sum(f[0] for f in fits))
        if best is None or rss < best[1]:
            best = (label, rss, np.array([f[1][-1] for f in fits]), np.array([f[0] for f in fits]))
    assert best is not None
    label, rss1, scale, rss1_by = best
    sizes = np.array([r.size for r in rows])
    drop = max(rss0 - rss1, 0.0)
    p_value = _f_p_value(drop, rss1, len(ids), x.size)
    # a pattern of the sensor shows in every view: with three views or more it must hold without the one that
    # carries most of it (a few blocks where the scene leaks, e.g. a checkerboard's edges, sit in one view)
    top = int(np.argmax(rss0_by - rss1_by))
    p_rest = p_value if len(ids) < 3 else _f_p_value(max(drop - (rss0_by[top] - rss1_by[top]), 0.0),
                                                     rss1 - rss1_by[top], len(ids) - 1, x.size - int(sizes[top]))
    r2 = drop / rss0 if rss0 > 0 else 0.0
    sign = float(np.sign(np.mean(scale)))
    if label.startswith("gradient"):
        where = label if sign > 0 else label.replace("top to bottom", "bottom to top").replace("left to right",
                                                                                            "right to left")
    else:
        where = f"towards the {label}" if sign > 0 else f"away from the {label}"
    return {"pattern": where, "shape": label, "p_value": p_value, "p_value_without_strongest_view": p_rest,
            "explained_fraction": r2, "strength": drop, "blocks": int(x.size),
            "significant": bool(max(p_value, p_rest) < SPATIAL_P and r2 >= MIN_SPATIAL_R2 and sign != 0)}


def _f_p_value(drop: float, rss1: float, segments: int, blocks: int) -> float:
    """F-test p-value of a shape scaled per segment explaining ``drop`` of the block excess (``rss1`` left,
    4 parameters per segment)."""
    dof = max(blocks - 4 * segments, 1)
    return float(f_dist.sf((drop / segments) / max(rss1 / dof, 1e-300), segments, dof)) if drop > 0 else 1.0


def _pixel_counts(comp: Comparison) -> dict[str, float]:
    """Outlier pixels of the frame averages (in views whose outliers are not the scene's specks) and temporal
    spikes: observed, expected, z."""
    out_obs = out_exp = spk_obs = spk_exp = checked = 0.0
    for sb, count in zip(comp.segments, comp.outlier_expectation()[0]):
        seg = sb.seg
        if seg.outliers_measured:
            out_obs += seg.outlier_pixels
            out_exp += float(count)
        spk_obs += seg.temporal_spikes
        spk_exp += seg.temporal_spikes_expected
        checked += seg.pixels_checked
    return {
        "pixels_checked": checked,
        "outlier_pixels": out_obs, "outlier_pixels_expected": out_exp,
        "outlier_z": (out_obs - out_exp) / math.sqrt(max(out_exp, 1.0)),
        "temporal_spikes": spk_obs, "temporal_spikes_expected": spk_exp,
        "temporal_spike_z": (spk_obs - spk_exp) / math.sqrt(max(spk_exp, 1.0)),
    }


def signature(comp: Comparison, rows: Sequence[dict[str, Any]] | None = None) -> dict[str, Any]:
    """The residual of ``comp`` (model vs measurement) described in physics terms (see module doc)."""
    rows = comp.cell_table() if rows is None else rows
    conditions = {"exposure": {s.index: s.meta.exposure_time_s for s in comp.meas.segments},
                  "gain": {s.index: 10.0 ** (s.meta.gain_db / 20.0) for s in comp.meas.segments},
                  "dark": {s.index: dark_electrons(s.meta, 1.0, s.meta.temperature_k) for s in comp.meas.segments}}
    pooled_names = ("column", "row", "temporal_column", "temporal_row")
    stats: dict[str, dict[str, Any]] = {}
    observations: dict[str, _Obs] = {}
    spatial_by: dict[str, dict[str, Any] | None] = {}
    for name in ("temporal", "fixed", "single") + pooled_names:
        pixelwise = name in ("temporal", "fixed", "single")
        found = position_pattern(comp, name) if pixelwise and any(name in r["measured_var_dn2"] for r in rows) else None
        obs = _observations(rows, name, name in pooled_names, conditions, _corner_factor(comp, found))
        if obs is None:
            continue
        observations[name] = obs
        stats[name] = _component_stats(obs)
        if pixelwise:
            spatial_by[name] = found
            stats[name]["position_significant"] = bool(found and found["significant"])
            stats[name]["significant"] = bool(stats[name]["significant"] or stats[name]["position_significant"])
    counts = _pixel_counts(comp)
    least = MIN_PIXEL_FRACTION * counts["pixels_checked"]
    # a sparse fixed pattern (kurtosis far above a Gaussian's) the model's Gaussian patterns cannot give: pixels
    # offset below the outlier threshold
    shape = comp.meas.fixed_shape
    sparse = bool(shape is not None and shape.sparse and gaussian_fixed(comp.effects))
    counts["fixed_pattern_sparse"] = sparse
    isolated_fixed = bool(counts["outlier_z"] >= Z_SIGNIFICANT
                          and counts["outlier_pixels"] - counts["outlier_pixels_expected"] >= least) or sparse
    isolated_temporal = bool(counts["temporal_spike_z"] >= Z_SIGNIFICANT
                             and counts["temporal_spikes"] - counts["temporal_spikes_expected"] >= least)
    sig = [k for k, s in stats.items() if s["significant"]]
    temporal = any(k in TEMPORAL for k in sig) or isolated_temporal
    fixed = any(k in FIXED for k in sig) or isolated_fixed
    if "single" in sig and not (temporal or fixed):
        kind = "temporal or fixed (single frames only)"
    else:
        kind = "temporal and fixed" if temporal and fixed else "temporal" if temporal else "fixed" if fixed else "none"
    significant = bool(sig) or isolated_fixed or isolated_temporal
    laws = {k: st.pop("_law") for k, st in stats.items()}
    out: dict[str, Any] = {"residual_significant": significant, "kind": kind, "components": stats,
                           "pixels": counts, "traits": []}
    if not significant:
        out["scene_may_explain"] = False
        out["reading"] = "the residual is within the measurement's uncertainty"
        return out
    dominant = max(sig, key=lambda k: (stats[k].get("position_significant", False),
                                       max(abs(stats[k]["z"]), abs(stats[k]["law_z"])))) if sig else None
    sign = 1.0
    if dominant:
        st = stats[dominant]
        sign = float(np.sign(st["excess_dn2"] if abs(st["z"]) >= abs(st["law_z"]) else laws[dominant]["amplitude_dn2"]))
    traits = []
    if sign < 0:
        traits.append("less noise than the model predicts (an effect that reduces variance)")
    traits += [LINE_TRAITS[k] for k in sig if k in LINE_TRAITS]
    if isolated_fixed:
        traits.append("isolated pixels offset in every frame")
    if isolated_temporal:
        traits.append("isolated pixels blinking from frame to frame")
    if any(k in ("temporal", "fixed", "single") for k in sig) and not any(k in LINE_TRAITS for k in sig):
        traits.append("pixel-wise (white)")
    law = None
    spatial = None
    if dominant:
        law = {k: v for k, v in laws[dominant].items() if k != "law"}
        if dominant in ("temporal", "fixed", "single"):
            spatial = spatial_by[dominant]
            if spatial and spatial["significant"]:
                traits.append(f"a region: {spatial['pattern']}")
    scene = _scene_may_explain(comp, stats, sig) and not isolated_fixed and not isolated_temporal
    # no still view at all: every component is a single frame's, where texture finer than a block reads as noise
    unheld = bool(sig) and not any(len(s.frames) >= 2 for s in comp.meas.segments)
    out.update({
        "sign": "excess" if sign > 0 else "deficit",
        "dominant_component": dominant,
        "traits": traits,
        "law": law,
        "spatial": spatial,
        "scene_may_explain": scene or unheld,
    })
    out["suggested"] = _suggest(out)
    law_text = _law_text(law, observations[dominant].pooled) if law and dominant else ""
    out["reading"] = (f"{kind} noise the model lacks ({'; '.join(traits)}), strongest in the {dominant} "
                      f"component: {law_text}" if dominant else f"{kind} noise the model lacks: {'; '.join(traits)}")
    if unheld:
        out["reading"] += ("; or the scene's texture: the recording holds no still view, so every component is measured "
                           "in single frames, where texture finer than a block cannot be told from noise (a still "
                           "camera or a flat chart tells them apart)")
    elif scene:
        out["reading"] += ("; or the scene's texture: most of it is measured in views from one camera pose whose fixed "
                           "pattern shows the scene, with as much variance (a moved camera or a flat chart tells them "
                           "apart)")
    return out


def _scene_may_explain(comp: Comparison, stats: dict[str, dict[str, Any]], significant: Sequence[str]) -> bool:
    """Whether the significant components are fixed-pattern ones (fixed, column, row), most of the views they are
    measured in come from one camera pose and show the scene (``SegmentMeasurement.scene_dn2``), and each excess is
    no larger than the scene's variance in those views (its mean over their blocks: the scene's whole variance bounds
    its line parts). One pose cannot tell the scene's texture finer than a block from a fixed pattern, so the excess
    may be the scene's."""
    if not significant or not set(significant) <= {"fixed", "column", "row"}:
        return False
    views = [s for s in comp.meas.segments if s.intensity_dn.size and any(k in s.values for k in significant)]
    scenes = [abs(float(np.mean(s.scene_dn2))) for s in views if not s.partners and s.scene_dn2 is not None]
    return len(scenes) > len(views) / 2 and all(stats[k]["excess_dn2"] <= np.mean(scenes) for k in significant)


def _suggest(sig: dict[str, Any]) -> dict[str, Any]:
    """How a plug-in would express the signature."""
    traits = " ".join(sig["traits"])
    dominant = sig["dominant_component"] or ""
    spatial = bool(sig.get("spatial") and sig["spatial"]["significant"])
    if sig["sign"] == "deficit":
        return {"distribution": "response", "temporal": True, "structure": "pixel", "spatial": spatial,
                "temporal_share": None}
    if "isolated pixels" in traits:
        both = "blinking" in traits and sig["kind"] == "temporal and fixed"
        return {"distribution": "mixture", "temporal": "blinking" in traits, "structure": "pixel",
                "spatial": spatial, "temporal_share": "both" if both else None}
    # a line component seen beside a pixel-wise dominant one (a single view's: no hold to split it) is the structure
    # the traits name; the skeleton's description says the same
    lines = [k for k in ("row", "column") if {LINE_TRAITS[k], LINE_TRAITS[f"temporal_{k}"]} & set(sig["traits"])]
    structure = ("row" if dominant.endswith("row") else "column" if dominant.endswith("column")
                 else lines[0] if len(lines) == 1 else "pixel")
    return {"distribution": "gaussian", "temporal": dominant.startswith("temporal"), "structure": structure,
            "spatial": spatial, "temporal_share": "both" if sig["kind"] == "temporal and fixed" else None}


def unexplained(comp: Comparison, rows: Sequence[dict[str, Any]], candidates: Sequence[Any]) -> dict[str, Any]:
    """``analyze``'s ``unexplained`` entry: significant when the residual is, no candidate explains it and the scene's
    texture cannot (``scene_may_explain``: then the residual is unexplained or the scene's, which these data cannot
    tell apart)."""
    sig = signature(comp, rows)
    claimed = [c.effect for c in candidates if c.significant]
    return {"significant": bool(sig["residual_significant"] and not claimed and not sig.get("scene_may_explain")),
            "explained_by": claimed, **sig}


def scene_or_effect(un: dict[str, Any]) -> bool:
    """Whether an ``unexplained`` entry's residual is significant, unclaimed, and may be the scene's texture."""
    return bool(un["residual_significant"] and not un["explained_by"] and un.get("scene_may_explain"))


# --- plug-in skeleton ------------------------------------------------------------------------------
_HEADER = '''"""Plug-in skeleton written by `noise-monitor analyze --write-plugin-skeleton` from the residual's signature:

{reading}

It runs as it is (the law and shape below are the ones fitted to the residual); make it physical:
name it, replace the fitted law by the effect's physics, give the parameters meaningful bounds. Then:

    noise-monitor analyze BAG --profile P --effect-plugin {filename} --add-effect {name}=fit
"""
import numpy as np

from noise_monitor.physics.effects import Effect, Param
{imports}
'''


def plugin_skeleton(sig: dict[str, Any], filename: str = "my_effect.py") -> str:
    """Python source of an Effect plug-in prefilled from a signature (see :func:`signature`)."""
    if not sig.get("residual_significant"):
        raise ValueError("the residual has no significant signature to write a plug-in for")
    sug = sig["suggested"]
    law = sig["law"] or {"intensity_power": 0, "exposure_power": 0, "gain_power": 0, "dark_current_law": False,
                         "amplitude_dn2": 1.0, "reference": {"intensity_dn": 128.0, "exposure_time_s": 0.01, "gain": 1.0}}
    name = "unexplained_effect"
    ref = law["reference"]
    a = law["intensity_power"]
    v_term = "(v / 255.0) ** 8" if a == "full_well" else f"(v / {ref['intensity_dn']:g}) ** {a}"
    law_lines = [
        "        v = np.maximum(np.asarray(signal_dn, dtype=float), 0.0)",
        f"        law = {v_term}",
        f"        law = law * (cond.exposure_time_s / {ref['exposure_time_s']:.6g}) ** {law['exposure_power']}",
        f"        law = law * (cond.gain / {ref['gain']:.6g}) ** {law['gain_power']}",
    ]
    if law["dark_current_law"]:
        law_lines.append("        law = law * dark_electrons(cond.meta, 1.0, cond.temperature_k) "
                         "/ dark_electrons(cond.meta, 1.0, 298.15)")
    spatial = sig.get("spatial") if sug["spatial"] else None
    if spatial:
        shape = spatial["shape"]
        if shape in REGIONS:
            y0, x0 = REGIONS[shape]
            law_lines.append(f"        # {spatial['pattern']}: cond.where holds the pixels' normalised (y, x)")
            law_lines.append(f"        law = law * np.exp(-np.hypot(cond.where.y - {y0}, cond.where.x - {x0}) "
                             "/ self.radius)")
        else:
            axis = "y" if "top" in shape else "x"
            law_lines.append(f"        law = law * np.clip(1.0 + self.slope_xy * (cond.where.{axis} - 0.5), 0.0, None)")
    amp = math.sqrt(abs(law["amplitude_dn2"]))
    params = [f'Param("amplitude", "DN", {amp:.4g}, (0.0, {max(10 * amp, 1.0):.4g}), '
              'description="TODO: noise sigma at the reference conditions")']
    if spatial and spatial["shape"] in REGIONS:
        params.append(f'Param("radius", "1", {CORNER_SCALE}, (0.02, 2.0), description="extent, in sensor sizes")')
    elif spatial:
        params.append('Param("slope_xy", "1", 1.0, (-2.0, 2.0), description="relative change across the sensor")')
    attrs = [f'    name = "{name}"  # TODO: your name for it', f'    distribution = "{sug["distribution"]}"',
             f"    temporal = {bool(sug['temporal'])}", f'    structure = "{sug["structure"]}"',
             f"    spatial = {bool(spatial)}",
             "    params = (\n" + "".join(f"        {p},\n" for p in params) + "    )",
             f'    description = "TODO: the physics. Seen: {sig["kind"]}; {"; ".join(sig["traits"])}"',
             '    signature = "TODO: how it shows in the residual, e.g. amplitude {amplitude:.2f} DN"']
    if sug["distribution"] == "response":
        params[0] = 'Param("strength", "1", 0.1, (0.0, 1.0), description="TODO: loss of slope at full well")'
        attrs[5] = "    params = (\n        " + params[0] + ",\n    )"
        body = ["    def slope(self, signal_dn, cond):",
                "        # TODO: the response's local slope d(output)/d(signal); 1 is linear",
                "        v = np.maximum(np.asarray(signal_dn, dtype=float), 0.0)",
                "        return np.clip(1.0 - self.strength * (v / 255.0) ** 4, 0.0, None)"]
    elif sug["distribution"] == "mixture":
        params = ['Param("fraction", "1", 0.01, (0.0, 0.2), description="TODO: fraction of pixels affected")',
                  f'Param("amplitude", "DN", {max(4 * amp, 1.0):.4g}, (0.0, 255.0), description="TODO: their offset")']
        attrs[5] = "    params = (\n" + "".join(f"        {p},\n" for p in params) + "    )"
        body = ["    def mixture(self, signal_dn, cond):",
                "        # TODO: (fraction of pixels, their offset in DN)",
                "        return self.fraction, np.broadcast_to(self.amplitude, np.shape(signal_dn))"]
        if sug["temporal_share"] == "both":
            body += ["", "    def temporal_share(self, signal_dn, cond):",
                     "        # TODO: share of the variance that changes from frame to frame (blinking pixels)",
                     "        return 0.5",
                     "", "    def fixed_mixture(self, signal_dn, cond):",
                     "        # TODO: (fraction, offset) the frame average shows: what stands out as outlier pixels",
                     "        return self.fraction, np.broadcast_to(0.5 * self.amplitude, np.shape(signal_dn))"]
    else:
        body = ["    def sigma_dn(self, signal_dn, cond):",
                f"        # fitted: {_law_text(law, False) if sig['law'] else 'no law'}",
                *law_lines,
                "        return self.amplitude * np.sqrt(law)"]
        if sug["temporal_share"] == "both":
            body += ["", "    def temporal_share(self, signal_dn, cond):",
                     "        # TODO: share of the variance that changes from frame to frame",
                     "        return 0.5"]
    imports = "from noise_monitor.physics.sensor import dark_electrons\n" if law["dark_current_law"] else ""
    head = _HEADER.format(reading=sig["reading"], filename=filename, name=name, imports=imports)
    return head + "\nclass UnexplainedEffect(Effect):\n" + "\n".join(attrs) + "\n\n" + "\n".join(body) + "\n"
