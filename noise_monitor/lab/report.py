"""Self-contained HTML report of an analysis (plots embedded as base64 PNG) plus its JSON summary."""
from __future__ import annotations

import base64
import html
import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..bag.staging import write_text_atomic  # noqa: E402
from ..physics import NoiseModel  # noqa: E402
from .analyze import component_change_text  # noqa: E402
from .compare import Comparison, as_measured, model_curve, signed_sigma  # noqa: E402
from .diagnose import Candidate, diagnosis_line  # noqa: E402
from .left import left_text  # noqa: E402
from .measure import BLOCK, field_conditions_text, scene_in_single_views_text, scene_in_views_text  # noqa: E402
from .noise_events import events_text  # noqa: E402
from .shape import fixed_shape_text  # noqa: E402
from .signature import scene_or_effect  # noqa: E402

CONDITION_LABELS = {
    "intensity_dn": "intensity [DN]",
    "gain_db": "gain [dB]",
    "exposure_time_s": "exposure time [s]",
    "sensor_temperature_c": "sensor temperature [°C]",
    "time_s": "time since first frame [s]",
    "region": "image region (3x3 grid, row-major)",
}


def _png(fig: plt.Figure) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _nlf_plot(summary: dict[str, Any], comp: Comparison, after: NoiseModel | None) -> str:
    segs = comp.segments
    pick = sorted({0, len(segs) - 1, len(segs) // 3, 2 * len(segs) // 3})[:4]
    fig, axes = plt.subplots(1, len(pick), figsize=(4.2 * len(pick), 3.6), squeeze=False)
    grid = np.linspace(0.0, 255.0, 103)
    cells = summary["cells"]
    for ax, i in zip(axes[0], pick):
        seg = segs[i].seg
        rows = [r for r in cells if r["segment"] == seg.index]
        x = [r["intensity_dn"] for r in rows]
        ax.errorbar(x, [r["measured_sigma_dn"] for r in rows], yerr=_sigma_errors(rows),
                    fmt="o", ms=4, color="k", label="measured (total)")
        if "temporal" in rows[0]["measured_var_dn2"]:
            ax.plot(x, np.sqrt(np.maximum([r["measured_var_dn2"]["temporal"] for r in rows], 0)), "s", ms=3,
                    mfc="none", color="tab:blue", label="measured (temporal)")
        ax.plot(grid, model_curve(comp.effects, seg.meta, grid), color="tab:red", label="model")
        if after is not None:
            ax.plot(grid, model_curve(after.effects, seg.meta, grid), "--", color="tab:green", label="model + added")
        ax.set_title(f"g={seg.meta.gain_db:.1f} dB, t={seg.meta.exposure_time_s * 1e3:.3g} ms, "
                     f"T={seg.meta.sensor_temperature_c:.0f} °C", fontsize=9)
        ax.set_xlabel("intensity [DN]")
        ax.set_ylabel("noise sigma [DN]")
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=8)
    fig.suptitle("Noise level function: measurement vs model")
    return _png(fig)


def _condition_plot(summary: dict[str, Any]) -> str:
    keys = [k for k in CONDITION_LABELS if k in summary["by_condition"]]
    cols = min(3, len(keys))
    nrows = -(-len(keys) // cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(4.2 * cols, 3.3 * nrows), squeeze=False, layout="constrained")
    after = summary.get("by_condition_after")
    for ax in axes.flat[len(keys):]:
        ax.set_visible(False)
    for ax, key in zip(axes.flat, keys):
        rows = summary["by_condition"][key]
        x = np.arange(len(rows))
        ax.errorbar(x, [r["measured_sigma_dn"] for r in rows], yerr=[r["measured_sigma_err_dn"] for r in rows],
                    fmt="o-", color="k", capsize=3, label="measured (1 sigma)")
        ax.plot(x, [r["model_sigma_dn"] for r in rows], "s--", color="tab:red", label="model")
        if after:
            ax.plot(x, [r["model_sigma_dn"] for r in after[key]], "^:", color="tab:green", label="model + added")
        ax.set_xticks(x, [f"{r[key]:.3g}" for r in rows], rotation=45, fontsize=8)
        ax.set_xlim(-0.5, len(rows) - 0.5)
        ax.set_xlabel(CONDITION_LABELS[key])
        ax.set_ylabel("rms noise sigma [DN]")
        ax.grid(alpha=0.3)
    axes.flat[0].legend(fontsize=8)
    fig.suptitle("Model vs measurement per condition")
    return _png(fig)


def _xi_plot(views: dict[str, Any]) -> str:
    fig, ax = plt.subplots(figsize=(7, 3.4))
    colors = {"before": "tab:red", "after": "tab:green"}
    for name, v in views.items():
        s = v["series"]
        label = f"{'model + added' if name == 'after' else 'model'}: mean {v['xi_dn']['mean']:+.3f} DN" \
            if v["xi_dn"]["mean"] is not None else name
        ax.plot(s["time_s"], s["xi"], ".-", ms=3, lw=0.8, color=colors.get(name), label=label)
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xlabel("time since first frame [s]")
    ax.set_ylabel("xi = sigma_model - sigma_image [DN]")
    ax.set_title("Estimator (Full-Meta) xi per frame")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _png(fig)


def _sigma_errors(rows: list[dict[str, Any]]) -> list[list[float]]:
    """Error bars (below, above) of the cells' measured sigma: they differ where the variance's error is as large as
    the variance (a view that shows the scene: down to 0 below)."""
    return [[r["measured_sigma_err_below_dn"] for r in rows], [r["measured_sigma_err_above_dn"] for r in rows]]


def _residual_plot(summary: dict[str, Any]) -> str:
    fig, ax = plt.subplots(figsize=(7, 3.6))
    cells = summary["cells"]
    ax.errorbar([r["intensity_dn"] for r in cells], [r["residual_dn"] for r in cells],
                yerr=_sigma_errors(cells), fmt="o", ms=3, alpha=0.7, color="tab:red",
                label=f"before: rms {summary['rms_error_raw_dn']:.3f} DN (net {summary['rms_error_dn']:.3f})")
    if "cells_after" in summary:
        after = summary["cells_after"]
        ax.plot([r["intensity_dn"] for r in after], [r["residual_dn"] for r in after], "^", ms=3,
                color="tab:green", label=f"after: rms {summary['rms_error_after_raw_dn']:.3f} DN (net {summary['rms_error_after_dn']:.3f})")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xlabel("intensity [DN]")
    ax.set_ylabel("measured - model sigma [DN]")
    ax.set_title("Residual per cell (segment x intensity bin)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _png(fig)


def _events_plot(summary: dict[str, Any]) -> str:
    """Each segment's mean residual over time, the compared ones and the set-apart ones, with the noise changes inside
    holds."""
    fig, ax = plt.subplots(figsize=(9, 3.6))
    for rows, color, fmt, label in ((summary["cells"], "k", "o", "compared with the model"),
                                    (summary["set_apart_cells"], "tab:red", "s", "set apart")):
        by_segment: dict[int, list[dict[str, Any]]] = {}
        for r in rows:
            by_segment.setdefault(r["segment"], []).append(r)
        if by_segment:
            t = [seg[0]["time_s"] for seg in by_segment.values()]
            ax.errorbar(t, [np.mean([r["residual_dn"] for r in seg]) for seg in by_segment.values()],
                        yerr=[np.sqrt(np.sum([r["measured_sigma_err_dn"] ** 2 for r in seg])) / len(seg)
                              for seg in by_segment.values()], fmt=fmt, color=color, ms=5, ls="none", label=label)
    for ev in summary["set_apart"]:
        ax.axvspan(ev["from_s"], ev["to_s"], color="tab:red", alpha=0.12)
    for i, c in enumerate(summary["measurement"]["noise_changes"]):
        ax.axvline(c["time_s"], color="tab:orange", ls="--", lw=1, label="noise change inside a hold" if i == 0 else None)
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xlabel(CONDITION_LABELS["time_s"])
    ax.set_ylabel("measured - model sigma [DN]\n(segment mean over its cells)")
    ax.set_title("Noise events: the segments compared with the model and those set apart")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _png(fig)


def _component_plot(summary: dict[str, Any]) -> str:
    """Measured (+- one standard error of its mean difference from the model, segments as clusters) vs model
    sigma per component: the temporal noise on its own axis, the small fixed-pattern and line components on
    theirs (invisible beside it on one)."""
    rows = summary["by_condition"]["component"]
    after = {r["component"]: r for r in (summary.get("by_condition_after") or {}).get("component", [])}
    groups = [[r for r in rows if r["component"] == "temporal"], [r for r in rows if r["component"] != "temporal"]]
    groups = [g for g in groups if g]
    fig, axes = plt.subplots(1, len(groups), figsize=(2.2 + 1.1 * len(rows), 3.6), squeeze=False,
                             width_ratios=[max(len(g), 1) + 0.6 for g in groups], layout="constrained")
    for ax, group in zip(axes[0], groups):
        x = np.arange(len(group))
        bars = [("measured", "0.3", [r["measured_sigma_dn"] for r in group]),
                ("model", "tab:red", [r["model_sigma_dn"] for r in group])]
        if after:
            bars.append(("model + added", "tab:green",
                         [after.get(r["component"], {}).get("model_sigma_dn", np.nan) for r in group]))
        width = 0.8 / len(bars)
        mv = np.array([r["measured_var_dn2"] for r in group])
        se = np.array([r["measured_var_err_dn2"] for r in group])
        measured = np.array(bars[0][2])
        yerr = [measured - signed_sigma(mv - se), signed_sigma(mv + se) - measured]
        for i, (label, color, values) in enumerate(bars):
            b = ax.bar(x + (i - (len(bars) - 1) / 2) * width, values, width, color=color, label=label,
                       yerr=yerr if i == 0 else None, capsize=3, ecolor="0.5")
            ax.bar_label(b, labels=["" if np.isnan(v) else "0" if abs(v) < 0.005 else f"{v:.2f}" for v in values], fontsize=7, padding=1)
        ax.set_xticks(x, [r["component"].replace("_", "\n") for r in group], fontsize=8)
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_ylabel("sigma [DN] (signed: sign(var) sqrt|var|)")
        ax.grid(alpha=0.3, axis="y")
        ax.margins(y=0.15)
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=len(labels), fontsize=8)
    fig.suptitle("Temporal vs fixed-pattern (white, column, row) noise: measured (± 1 standard error) vs model")
    return _png(fig)


def _excess_map_plot(comp: Comparison, component: str) -> str:
    """Measured - model variance of ``component`` per block position on the sensor (mean over segments)."""
    gy, gx = max(comp.meas.shape[0] // BLOCK, 1), max(comp.meas.shape[1] // BLOCK, 1)  # the block grid
    total, count = np.zeros((gy, gx)), np.zeros((gy, gx))
    for sb, comps in comp.predict_with():
        if component not in sb.seg.values:
            continue
        x = sb.seg.values[component][sb.rep] - as_measured(sb, comps, component)
        iy = np.minimum((sb.pos[:, 0] * gy).astype(int), gy - 1)
        ix = np.minimum((sb.pos[:, 1] * gx).astype(int), gx - 1)
        np.add.at(total, (iy, ix), x)
        np.add.at(count, (iy, ix), 1.0)
    mean = np.where(count > 0, total / np.maximum(count, 1.0), np.nan)
    lim = float(np.nanpercentile(np.abs(mean), 98)) if np.isfinite(mean).any() else 1.0
    fig, ax = plt.subplots(figsize=(5.6, 4.4))
    im = ax.imshow(mean, extent=(0, 1, 1, 0), cmap="RdBu_r", vmin=-lim, vmax=lim, interpolation="nearest")
    fig.colorbar(im, ax=ax, label=f"{component} variance: measured - model [DN²]")
    ax.set_xlabel("sensor x [fraction of the width]")
    ax.set_ylabel("sensor y [fraction of the height]")
    ax.set_title(f"Unexplained {component} noise on the sensor (blank: no flat block)")
    return _png(fig)


def _table(rows: Sequence[dict[str, Any]], cols: Sequence[str]) -> str:
    head = "".join(f"<th title=\"{html.escape(c)}\">{html.escape(_header(c))}</th>" for c in cols)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(_fmt(r.get(c)))}</td>" for c in cols) + "</tr>" for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _header(key: str) -> str:
    """A JSON key as a column header: words, and its unit in brackets (``measured_sigma_dn`` -> measured sigma
    [DN]); the key itself is the header's tooltip."""
    units = {"_dn2": " [DN^2]", "_dn": " [DN]", "_db": " [dB]", "_s": " [s]", "_c": " [degC]", "_pct": " [%]"}
    suffix = next((s for s in units if key.endswith(s)), "")
    return key[: len(key) - len(suffix)].replace("_", " ") + units.get(suffix, "")


def _fmt(v: Any) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, dict):
        return ", ".join(f"{k}={_fmt(x)}" for k, x in v.items())
    if isinstance(v, list):
        return ", ".join(_fmt(x) for x in v)
    return str(v)


def _unexplained_html(un: dict[str, Any] | None) -> str:
    """The residual's signature: what the model lacks, in physics terms, and the plug-in it suggests."""
    if not un:
        return ""
    head = "<h2>Unexplained residual</h2>"
    if not un["residual_significant"]:
        return head + "<p>The residual is within the measurement's uncertainty.</p>"
    intro = ("<p class='sig'>No candidate effect explains it: " if un["significant"]
             else "<p>Not established (an effect or the scene's texture): " if scene_or_effect(un)
             else f"<p>Explained by {html.escape(', '.join(un['explained_by']))}; before that: ")
    rows = [{"component": k, **{x: v for x, v in st.items()}} for k, st in un["components"].items()]
    parts = [head, intro + html.escape(un["reading"]) + "</p>",
             "<p>Per measured component (variance, DN²: measured − model):</p>",
             _table(rows, ["component", "excess_dn2", "excess_err_dn2", "model_dn2", "z", "significant"])]
    px = un["pixels"]
    parts.append(f"<p>Outlier pixels of the frame averages: {px['outlier_pixels']:.0f} (model "
                 f"{px['outlier_pixels_expected']:.1f}); pixels blinking between frames: {px['temporal_spikes']:.0f} "
                 f"(white noise gives {px['temporal_spikes_expected']:.1f}).</p>")
    if un.get("law"):
        law = un["law"]
        parts.append("<p>Law of the excess: " + html.escape(
            f"intensity^{law['intensity_power']} x exposure^{law['exposure_power']} x gain^{law['gain_power']}"
            + (" x dark-current(T)" if law["dark_current_law"] else "")
            + f", amplitude {law['amplitude_dn2']:.4g} DN² at the reference {law['reference']}") + "</p>")
    if un.get("spatial"):
        sp = un["spatial"]
        parts.append("<p>Position on the sensor: " + html.escape(
            f"{sp['pattern']} (explains {sp['explained_fraction']:.0%} of the block excess beyond segment means, "
            f"p = {sp['p_value']:.2g}; {'significant' if sp['significant'] else 'not significant'})") + "</p>")
    if un.get("suggested"):
        parts.append("<p>A plug-in for it (<code>--write-plugin-skeleton PATH</code>): "
                     + html.escape(_fmt(un["suggested"])) + "</p>")
    return "".join(parts)


def write_report(out_dir: str | Path, summary: dict[str, Any], comp: Comparison, candidates: list[Candidate],
                 after: NoiseModel | None = None) -> Path:
    """Write ``report.html`` (self-contained) and ``summary.json`` into ``out_dir``; returns the HTML path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    images = {
        "Noise level function": _nlf_plot(summary, comp, after),
        "Per condition": _condition_plot(summary),
        "Residuals": _residual_plot(summary),
        "Components": _component_plot(summary),
    }
    if summary["measurement"].get("noise_changes") or summary.get("set_apart"):
        images["Noise events"] = _events_plot(summary)
    if summary.get("estimator"):
        images["Estimator: xi per frame"] = _xi_plot(summary["estimator"])
    un = summary.get("unexplained") or {}
    if un.get("significant") and un.get("dominant_component") in ("temporal", "fixed", "single"):
        images["Unexplained residual on the sensor"] = _excess_map_plot(comp, un["dominant_component"])
    cand_rows = [{**c.as_dict(), "params": c.params} for c in candidates]  # params: the fit alone
    parts = [
        "<!DOCTYPE html><html><head><meta charset='utf-8'><title>noise_monitor analysis</title>",
        "<style>body{font-family:sans-serif;margin:2em;max-width:1400px}table{border-collapse:collapse;"
        "font-size:13px}td,th{border:1px solid #bbb;padding:3px 6px;text-align:left}img{max-width:100%}"
        ".sig{color:#b00;font-weight:bold}</style></head><body>",
        f"<h1>Model vs measurement: {html.escape(str(summary.get('source')))}</h1>",
        f"<p>Profile: <b>{html.escape(str(summary.get('profile')))}</b>; model effects: "
        f"{html.escape(', '.join(summary['model_effects']))}. Frames used {summary['measurement']['frames_used']} of "
        f"{summary['measurement']['frames_total']}, {summary['measurement']['segments']} segments, "
        f"{summary['measurement']['cells']} cells. <b>rms error {summary['rms_error_dn']:.4f} DN</b> "
        f"(model vs measured total sigma per cell, net of the measurement's own scatter; raw rms "
        f"{summary['rms_error_raw_dn']:.4f} DN, of which the cells' standard errors explain "
        f"{summary['measurement_scatter_dn']:.4f} DN).</p>",
    ]
    gaps = [f"{n} frame(s): {why}" for why, n in summary["measurement"].get("frames_skipped", {}).items()]
    gaps += [f"{what}: {why}" for what, why in summary["measurement"].get("not_measured", {}).items()]
    if summary["measurement"].get("scene_in_partner_views"):
        gaps.append(scene_in_views_text(summary["measurement"]["scene_in_partner_views"]))
    if line := scene_in_single_views_text(summary["measurement"]["scene_in_single_views"]):
        gaps.append(line)
    if gaps:
        parts.append("<p><b>Not measured</b><ul>" + "".join(f"<li>{html.escape(g)}</li>" for g in gaps) + "</ul></p>")
    if "fixed_pattern_shape" in summary["measurement"]:
        text = fixed_shape_text(summary["measurement"]["fixed_pattern_shape"])
        parts.append(f"<p>{html.escape(text[:1].upper() + text[1:])}.</p>")
    if "field_conditions" in summary["measurement"]:
        text = field_conditions_text(summary["measurement"]["field_conditions"])
        parts.append(f"<p>Field conditions: {html.escape(text)}.</p>")
    for line in events_text(summary["measurement"].get("noise_changes", []), summary.get("set_apart", [])):
        parts.append(f"<p><b>{html.escape(line[:1].upper() + line[1:])}.</b></p>")
    if "rms_error_after_dn" in summary:
        added = "; ".join(f"{a['effect']} ({_fmt(a['params'])}): {a['reading']}" for a in summary["added_effects"])
        parts.append(f"<p>Added: {html.escape(added)}<br><b>rms error before {summary['rms_error_before_dn']:.4f} DN, "
                     f"after {summary['rms_error_after_dn']:.4f} DN</b> (raw {summary['rms_error_before_raw_dn']:.4f} -> "
                     f"{summary['rms_error_after_raw_dn']:.4f} DN); by measured component (the error each one's "
                     f"mismatch makes in the total sigma): {html.escape(component_change_text(summary))}</p>")
    line = diagnosis_line(cand_rows)
    parts.append("<h2>Diagnosis</h2>")
    parts.append(
        "<p class='sig'>" + html.escape(line[:1].upper() + line[1:]) + "</p>"
        if any(c.significant for c in candidates) else
        "<p>No candidate effect explains a significant part of the model error.</p>"
    )
    groups: dict[tuple[int, str], list[str]] = {}
    for c in candidates:
        if c.equivalent_to:
            groups.setdefault((c.rank, c.indistinguishable), []).append(c.effect)
    if groups:  # the diagnosis' own group is not repeated
        parts.append("<p>Candidates these data cannot tell apart (one explanation, one rank):<ul>" + "".join(
            f"<li>rank {rank}, {html.escape(', '.join(names))}: "
            f"{'the diagnosis above' if text in line else html.escape(text)}</li>"
            for (rank, text), names in groups.items()) + "</ul></p>")
    beyond = dict.fromkeys((c.rank, c.beyond["reading"]) for c in candidates if c.beyond)
    if beyond:  # the claims' forward selection: each candidate significant alone, refitted beyond the claimed
        parts.append("<p>Candidates significant on their own, refitted on top of the explanations claimed before "
                     "them (claimed only if significant beyond them):<ul>" + "".join(
                         f"<li>rank {rank}, {html.escape(', '.join(c.effect for c in candidates if c.rank == rank))}: "
                         f"{html.escape(reading)}</li>" for rank, reading in beyond) + "</ul></p>")
    if left := summary.get("left_by_claims"):
        first, *refused = left_text(left, summary["rms_error_dn"])
        parts.append(f"<p{' class=sig' if left['significant'] else ''}>{html.escape(first[:1].upper() + first[1:])}"
                     + ("<ul>" + "".join(f"<li>{html.escape(r.strip())}</li>" for r in refused) + "</ul>" if refused
                        else "") + "</p>")
    contradicted = [c for c in candidates if c.contradicted]
    if contradicted:
        parts.append("<p>Fits a direct observation contradicts (never claimed):<ul>" + "".join(
            f"<li>{html.escape(c.effect)}: {html.escape(c.contradicted)}</li>" for c in contradicted) + "</ul></p>")
    parts.append(_table(cand_rows, ["rank", "effect", "equivalent_to", "significant", "significant_alone",
                                    "explained_by", "explained_fraction", "delta_bic",
                                    "p_value", "params", "claimed_params", "param_errors", "degenerate", "param_ranges",
                                    "rms_error_after_dn",
                                    "reading"]))
    parts.append(_unexplained_html(summary.get("unexplained")))
    for title, b64 in images.items():
        parts.append(f"<h2>{html.escape(title)}</h2><img alt='{html.escape(title)}' src='data:image/png;base64,{b64}'>")
    parts.append("<h2>Where the model fails (by condition)</h2>")
    added_rows: dict[str, list[dict[str, Any]]] = summary.get("by_condition_after") or {}
    for key, rows in summary["by_condition"].items():
        count = "blocks" if rows and "blocks" in rows[0] else "cells"
        cols = [key, count, "measured_sigma_dn", "model_sigma_dn", "mean_residual_dn", "rms_residual_dn"]
        if key in added_rows:  # the model with the added effects beside it, matched by the condition's value
            by_value = {r[key]: r for r in added_rows[key]}
            rows = [{**r, "model_added_sigma_dn": by_value.get(r[key], {}).get("model_sigma_dn"),
                     "rms_residual_added_dn": by_value.get(r[key], {}).get("rms_residual_dn")} for r in rows]
            cols += ["model_added_sigma_dn", "rms_residual_added_dn"]
        parts.append(f"<h3>{html.escape(CONDITION_LABELS.get(key, key))}</h3>" + _table(rows, cols))
    if summary.get("estimator"):
        rows = [{"model": name, "frames": v["frames"], "xi_mean_dn": v["xi_dn"]["mean"],
                 "xi_mean_err_dn": v["xi_dn"]["sem"], "xi_p5_dn": v["xi_dn"]["p5"],
                 "xi_p95_dn": v["xi_dn"]["p95"], "mean_abs_xi_dn": v["mean_abs_xi_dn"],
                 "sigma_image_dn": v["sigma_image_dn"]["mean"], "sigma_model_dn": v["sigma_model_dn"]["mean"],
                 "weights": v["weights"]} for name, v in summary["estimator"].items()]
        parts.append("<h2>Estimator on the same frames</h2><p>The monitor's xi = sigma_model - sigma_image per "
                     "frame (sigma_image: Full-Meta's measurement of the noise in the image); near 0 when the "
                     "model is complete. With an effect missing from the model, read |xi| as a lower bound of the "
                     "missing noise: the measurement leans on the model's per-pixel shape and under-reads noise "
                     "whose shape the model lacks, most on patches spanning a wide intensity range.</p>"
                     + _table(rows, list(rows[0])))
    parts.append("<h2>Measurement</h2><pre>" + html.escape(json.dumps(summary["measurement"], indent=1)) + "</pre>")
    parts.append("</body></html>")
    path = out / "report.html"
    write_text_atomic(path, "\n".join(parts))  # a link in the folder is replaced, never followed
    write_text_atomic(out / "summary.json", json.dumps(summary, indent=1, default=float))
    return path
