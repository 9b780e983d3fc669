"""Campaign summary (per bag and per camera: frames accounted, alarm episodes in wall-clock time, xi and
per-source sigma with trends, health ranking) and its self-contained HTML report."""
from __future__ import annotations

import base64
import html
import io
import math
from collections import Counter, defaultdict
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from .bags import Problem

#: Per-bag quantities whose trend over the campaign is fitted per camera.
TREND_KEYS = ("xi", "sigma_image", "sigma_model", "sigma_pn", "sigma_dcsn", "sigma_rn")
CONDITIONS = ("gain_db", "exposure_time_s", "sensor_temperature_c")
WEEK_NS = 7 * 86400 * 1e9
#: A trend counts when its slope is this many standard errors from zero (and >= 4 bags) ...
TREND_T = 3.0
#: ... and it changes the quantity by at least this much over the campaign (DN): the physics' own
#: per-source sigma is noiseless, so statistically certain trends of a thousandth of a DN are no finding.
TREND_MIN_CHANGE_DN = 0.05
#: Cameras drawn in the report's per-camera figure (the least healthy first).
PLOT_CAMERAS = 6


def utc(ns: int | None) -> str | None:
    """ISO 8601 UTC time of a stamp in ns (ms resolution)."""
    if ns is None:
        return None
    return datetime.fromtimestamp(ns / 1e9, tz=UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def trend(t_ns: np.ndarray, y: np.ndarray, conds: dict[str, np.ndarray]) -> dict[str, Any] | None:
    """Least-squares slope of y per week over the bags, at equal conditions: the conditions that vary
    between bags (gain, exposure, temperature) are regressors too, so a warmer week is not read as drift."""
    ok = np.isfinite(y) & np.isfinite(t_ns)
    for c in conds.values():
        ok &= np.isfinite(c)
    n = int(ok.sum())
    if n < 3:
        return None
    t = (t_ns[ok] - t_ns[ok].min()) / WEEK_NS
    span = float(t.max())
    if span <= 0:
        return None
    cols, names = [np.ones(n), t], []
    for name, c in conds.items():
        c = c[ok]
        if np.ptp(c) > 1e-6 * max(1.0, float(np.abs(c).max())) and n >= len(cols) + 3:
            cols.append(c - c.mean())
            names.append(name)
    x = np.stack(cols, axis=1)
    beta, *_ = np.linalg.lstsq(x, y[ok], rcond=None)
    dof = n - x.shape[1]
    resid = y[ok] - x @ beta
    s2 = float(resid @ resid) / dof if dof > 0 else 0.0
    se = math.sqrt(max(s2 * float(np.linalg.pinv(x.T @ x)[1, 1]), 0.0))
    slope = float(beta[1])
    significant = (n >= 4 and dof > 0 and abs(slope) > TREND_T * se and abs(slope * span) >= TREND_MIN_CHANGE_DN)
    return {"slope_dn_per_week": round(slope, 5), "stderr_dn_per_week": round(se, 5),
            "change_dn": round(slope * span, 4), "span_weeks": round(span, 3), "bags": n,
            "adjusted_for": names, "significant": bool(significant)}


def _bag_row(e: dict[str, Any]) -> dict[str, Any]:
    r = e["record"]
    row = {"path": e["path"], "sha256": e["sha256"], **{k: r[k] for k in (
        "hardware_id", "profile", "frames_total", "frames_processed", "frames_skipped", "frames_in_alarm",
        "alarm_episodes", "skip_reasons", "conditions", "xi_threshold_dn", "start_ns", "end_ns")}}
    row.update(start_utc=utc(r["start_ns"]), end_utc=utc(r["end_ns"]), stats=r["stats"],
               alarms=[{**a, "start_utc": utc(a["start_ns"]), "end_utc": utc(a["end_ns"])} for a in r["alarms"]],
               wall_s=e.get("wall_s"), peak_rss_mb=e.get("peak_rss_mb"),
               temporal_noise_changes=r.get("temporal_noise_changes", 0),  # absent from records of older versions
               temporal_light_steps=r.get("temporal_light_steps", 0),
               frames_lost=r.get("frames_lost", 0), metadata_overrides=r.get("metadata_overrides", {}))
    return row


def _reasons(rows: Sequence[dict[str, Any]]) -> dict[str, int]:
    """Skipped frames per reason over bags, commonest first."""
    counts: Counter[str] = Counter()
    for r in rows:
        counts.update(r["skip_reasons"])
    return dict(counts.most_common())


def _scaled(xi_dn: float, threshold_dn: float) -> float:
    """An |xi| symptom on 0..1: nothing below a quarter of the alarm threshold, 1 at the threshold."""
    return float(np.clip((xi_dn - threshold_dn / 4) / (0.75 * threshold_dn), 0.0, 1.0))


def _camera(hw: str, rows: list[dict[str, Any]]) -> dict[str, Any]:
    total = sum(r["frames_total"] for r in rows)
    processed = sum(r["frames_processed"] for r in rows)
    in_alarm = sum(r["frames_in_alarm"] for r in rows)
    thr = float(np.median([r["xi_threshold_dn"] for r in rows]))
    means = {}
    for k in TREND_KEYS:
        w = [(r["stats"][k]["mean"], r["stats"][k]["n"]) for r in rows if r["stats"][k]["mean"] is not None]
        n = sum(c for _, c in w)
        means[k] = round(sum(m * c for m, c in w) / n, 4) if n else None
    mid = np.array([(r["start_ns"] + r["end_ns"]) / 2 if r["start_ns"] is not None else np.nan for r in rows])
    conds = {c: np.array([r["conditions"][c] if r["conditions"][c] is not None else np.nan for r in rows])
             for c in CONDITIONS}
    trends = {}
    for k in TREND_KEYS:
        y = np.array([r["stats"][k]["mean"] if r["stats"][k]["mean"] is not None else np.nan for r in rows])
        trends[k] = trend(mid, y, conds)
    episodes = [a for r in rows for a in r["alarms"]]
    # health: 1 - the worst symptom (each scaled to 0..1)
    symptoms = {
        "alarm": in_alarm / processed if processed else 0.0,
        "skipped": (total - processed) / total if total else 1.0,
        "xi_bias": _scaled(abs(means["xi"]), thr) if means["xi"] is not None and thr > 0 else 0.0,
        "xi_drift": 0.0, "dcsn_growth": 0.0,
    }
    findings = []
    tx, td = trends["xi"], trends["sigma_dcsn"]
    if tx and tx["significant"]:
        symptoms["xi_drift"] = _scaled(abs(tx["change_dn"]), thr) if thr > 0 else 0.0
        findings.append(f"xi drifts {tx['slope_dn_per_week']:+.3f} DN/week ({tx['change_dn']:+.2f} DN over "
                        f"{tx['span_weeks']:.1f} weeks" + (f", at equal {', '.join(tx['adjusted_for'])})"
                                                           if tx["adjusted_for"] else ")"))
    if td and td["significant"] and td["slope_dn_per_week"] > 0 and means["sigma_dcsn"]:
        first = means["sigma_dcsn"] - td["change_dn"] / 2
        rel = td["change_dn"] / first if first > 0 else 1.0
        symptoms["dcsn_growth"] = min(1.0, rel)
        findings.append(f"dark-current shot noise grows {td['slope_dn_per_week']:+.3f} DN/week "
                        f"({100 * rel:+.0f} % over {td['span_weeks']:.1f} weeks"
                        + (f" at equal {', '.join(td['adjusted_for'])}" if td["adjusted_for"] else "")
                        + "): an ageing sensor?")
    xi_mean = means["xi"]
    if symptoms["xi_bias"] > 0 and xi_mean is not None:
        kind = "image noisier than the model predicts" if xi_mean < 0 else "model predicts more noise than the image"
        findings.append(f"mean xi {xi_mean:+.2f} DN (alarm threshold {thr:g} DN): {kind}")
    if symptoms["alarm"] > 0:
        findings.append(f"{len(episodes)} alarm episode(s), {100 * symptoms['alarm']:.1f} % of processed frames in alarm")
    if symptoms["skipped"] > 0:
        findings.append(f"{100 * symptoms['skipped']:.1f} % of frames not evaluated")
    changes = sum(r["temporal_noise_changes"] for r in rows)
    if changes:
        findings.append(f"the noise changed suddenly {changes} time(s) while the camera held still (each restarted its "
                        "frame-difference measurement)")
    light_steps = sum(r["temporal_light_steps"] for r in rows)
    if light_steps:
        findings.append(f"the light stepped {light_steps} time(s) while the camera held still (a lamp switched; each "
                        "restarted its frame-difference measurement)")
    overrides: dict[str, dict[str, Any]] = {}
    for r in rows:
        for key, pair in r["metadata_overrides"].items():
            overrides.setdefault(key, pair)
    if overrides:
        findings.append("the bags' metadata set camera constants over the profile's (the profile's are not used): "
                        + ", ".join(f"{k} {v['bag']} (profile {v['profile']})" for k, v in sorted(overrides.items())))
    worst = max(symptoms, key=lambda k: symptoms[k])
    return {
        "hardware_id": hw, "profiles": sorted({str(r["profile"]) for r in rows}), "bags": len(rows),
        "first_utc": utc(min((r["start_ns"] for r in rows if r["start_ns"] is not None), default=None)),
        "last_utc": utc(max((r["end_ns"] for r in rows if r["end_ns"] is not None), default=None)),
        "frames_total": total, "frames_processed": processed, "frames_skipped": total - processed,
        "skip_reasons": _reasons(rows), "frames_lost": sum(r["frames_lost"] for r in rows),
        "frames_in_alarm": in_alarm, "alarm_episodes": len(episodes), "temporal_noise_changes": changes,
        "temporal_light_steps": light_steps,
        "alarm_time_s": round(sum(a["duration_s"] for a in episodes), 3),
        "mean": means, "trends": trends, "xi_threshold_dn": thr,
        "health": round(1.0 - symptoms[worst], 4), "health_limited_by": worst if symptoms[worst] > 0 else None,
        "symptoms": {k: round(v, 4) for k, v in symptoms.items()}, "findings": findings,
        "metadata_overrides": overrides,
    }


def summarize(paths: Sequence[str], entries: Sequence[dict[str, Any]], problems: Sequence[Problem],
              run: dict[str, Any]) -> dict[str, Any]:
    """campaign.json: totals, cameras ranked by health, bags, alarm episodes and everything not evaluated."""
    order = {p: i for i, p in enumerate(paths)}
    bags, duplicates, failed = [], [], []
    ordered = sorted(entries, key=lambda e: order[e["path"]])
    primary: dict[str, str] = {}  # per content, the first bag replayed (a duplicate is not: ``duplicate_of``)
    for e in ordered:
        if e["status"] == "ok" and "record" in e:
            primary.setdefault(e["sha256"], e["path"])
    for e in ordered:
        if e["status"] != "ok":
            failed.append({"path": e["path"], "reason": e.get("reason", "unknown"),
                           **({"hardware_id": e["hardware_id"]} if e.get("hardware_id") else {})})
        elif primary.get(e["sha256"]) == e["path"]:
            bags.append(_bag_row(e))
        else:
            first = primary.get(e["sha256"], e.get("duplicate_of"))
            duplicates.append({"path": e["path"], "reason": f"duplicate of {first} (same content, "
                                                            f"sha256 {e['sha256'][:16]}...): counted once"})
    by_cam: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for b in bags:
        by_cam[b["hardware_id"]].append(b)
    cameras = sorted((_camera(hw, rows) for hw, rows in by_cam.items()), key=lambda c: (c["health"], c["hardware_id"]))
    for rank, c in enumerate(cameras, 1):
        c["rank"] = rank
    unevaluated: dict[str, list[dict[str, Any]]] = defaultdict(list)  # cameras whose every bag failed
    for f in failed:
        if f.get("hardware_id") and f["hardware_id"] not in by_cam:
            unevaluated[f["hardware_id"]].append(f)
    episodes = sorted(({"hardware_id": b["hardware_id"], "bag": b["path"], **a} for b in bags for a in b["alarms"]),
                      key=lambda a: a["start_ns"])
    recorded = {e["path"] for e in entries}
    pending = [p for p in paths if p not in recorded]
    return {
        "totals": {
            "bags_found": len(paths), "bags_evaluated": len(bags), "bags_failed": len(failed),
            "bags_duplicate": len(duplicates), "bags_not_run": len(pending), "inputs_rejected": len(problems),
            "cameras": len(cameras),
            "frames_total": sum(b["frames_total"] for b in bags),
            "frames_processed": sum(b["frames_processed"] for b in bags),
            "frames_skipped": sum(b["frames_skipped"] for b in bags),
            "skip_reasons": _reasons(bags),
            "frames_lost": sum(b["frames_lost"] for b in bags),
            "alarm_episodes": len(episodes),
            "temporal_noise_changes": sum(b["temporal_noise_changes"] for b in bags),
            "temporal_light_steps": sum(b["temporal_light_steps"] for b in bags),
        },
        "run": run,
        "cameras": cameras,
        "cameras_not_evaluated": [{"hardware_id": hw, "bags_failed": len(rows), "reason": rows[0]["reason"]}
                                  for hw, rows in sorted(unevaluated.items())],
        "bags": bags,
        "alarm_episodes": episodes,
        "failed": failed,
        "duplicates": duplicates,
        "problems": [{"path": p.path, "reason": p.reason} for p in problems],
        "not_run": pending,
    }


# --- HTML ---------------------------------------------------------------------------------------------
def _png(fig: Any) -> str:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _mean(row: dict[str, Any], key: str) -> float:
    """A bag's mean of ``key`` over its frames (NaN where it has none)."""
    mean = row["stats"].get(key, {}).get("mean")
    return np.nan if mean is None else float(mean)


def _times(rows: list[dict[str, Any]]) -> list[datetime]:
    return [datetime.fromtimestamp((r["start_ns"] + r["end_ns"]) / 2e9, tz=UTC) for r in rows]


def _camera_figure(campaign: dict[str, Any]) -> str | None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cams = [c for c in campaign["cameras"]][:PLOT_CAMERAS]
    if not cams:
        return None
    fig, axes = plt.subplots(len(cams), 3, figsize=(15, 3.0 * len(cams)), squeeze=False)
    for row, cam in zip(axes, cams):
        rows = sorted((b for b in campaign["bags"] if b["hardware_id"] == cam["hardware_id"]),
                      key=lambda b: b["start_ns"] or 0)
        rows = [r for r in rows if r["start_ns"] is not None]
        t = _times(rows)
        ax = row[0]
        xi = np.array([r["stats"]["xi"]["mean"] if r["stats"]["xi"]["mean"] is not None else np.nan for r in rows])
        lo = np.array([r["stats"]["xi"]["p5"] if r["stats"]["xi"]["p5"] is not None else np.nan for r in rows])
        hi = np.array([r["stats"]["xi"]["p95"] if r["stats"]["xi"]["p95"] is not None else np.nan for r in rows])
        ax.errorbar(t, xi, yerr=[xi - lo, hi - xi], fmt="o", ms=4, color="k", ecolor="0.6", label="xi per bag (mean, p5-p95)")
        alarm = [i for i, r in enumerate(rows) if r["alarm_episodes"]]
        if alarm:
            ax.plot([t[i] for i in alarm], xi[alarm], "o", mfc="none", mec="tab:red", ms=10, label="bag with alarm")
        thr = cam["xi_threshold_dn"]
        for s in (-thr, thr):
            ax.axhline(s, ls="--", color="tab:red", lw=1)
        ax.set_ylabel("xi [DN]")
        ax.set_title(f"#{cam['rank']} {cam['hardware_id']}: health {cam['health']:.2f}", fontsize=10)
        ax.legend(fontsize=7, loc="best")
        ax = row[1]
        for key, color, style, label in (
                ("sigma_pn", "tab:blue", "o-", "PN"), ("sigma_dcsn", "tab:orange", "o-", "DCSN"),
                ("sigma_rn", "tab:green", "o-", "RN"), ("sigma_model", "tab:red", "o-", "model total"),
                ("sigma_image", "k", "s--", "image (measured)"),
                ("sigma_temporal", "darkcyan", "D", "frame differences (still views)"),
                ("sigma_temporal_model", "darkcyan", "x", "their model (same blocks)")):
            y = np.array([_mean(r, key) for r in rows])
            if np.isfinite(y).any():  # a campaign without still views (or older records) has no frame differences
                ax.plot(t, y, style, ms=3 if style != "x" else 6, lw=1, color=color, label=label)
        td = cam["trends"]["sigma_dcsn"]
        if td and td["significant"]:
            ax.text(0.01, 0.02, f"DCSN trend {td['slope_dn_per_week']:+.3f} DN/week", transform=ax.transAxes,
                    va="bottom", fontsize=8, color="tab:orange")
        ax.set_ylabel("noise sigma per bag [DN]")
        ax.set_ylim(0, ax.get_ylim()[1] * 1.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7, loc="upper center", ncol=3)
        else:  # every frame of the camera's bags skipped: nothing to draw
            ax.text(0.5, 0.5, "no frame evaluated", transform=ax.transAxes, ha="center", va="center", fontsize=9)
        ax = row[2]
        temp = [r["conditions"]["sensor_temperature_c"] for r in rows]
        ax.plot(t, [np.nan if v is None else v for v in temp], "o-", ms=3, color="tab:purple", label="temperature")
        ax.set_ylabel("sensor temperature [°C]", color="tab:purple")
        ax2 = ax.twinx()
        gain = [r["conditions"]["gain_db"] for r in rows]
        ax2.plot(t, [np.nan if v is None else v for v in gain], "s--", ms=3, color="tab:gray", label="gain")
        ax2.set_ylabel("gain [dB]", color="tab:gray")
        for a in row:
            a.set_xlabel("bag time (UTC)")
            a.grid(alpha=0.3)
            a.tick_params(axis="x", labelsize=7, rotation=20)
    fig.suptitle("Cameras, least healthy first: xi, per-source sigma and conditions per bag over the campaign")
    fig.tight_layout(rect=(0, 0, 1, 0.98))
    return _png(fig)


def _health_figure(campaign: dict[str, Any]) -> str | None:
    import matplotlib.pyplot as plt

    cams = campaign["cameras"][:40]
    if not cams:
        return None
    fig, ax = plt.subplots(figsize=(9, 0.3 * len(cams) + 1.2))
    colors = {"alarm": "tab:red", "xi_bias": "tab:orange", "xi_drift": "tab:purple", "dcsn_growth": "tab:brown",
              "skipped": "tab:gray", None: "tab:green"}
    y = np.arange(len(cams))[::-1]
    ax.barh(y, [c["health"] for c in cams], color=[colors[c["health_limited_by"]] for c in cams])
    ax.set_yticks(y, [c["hardware_id"] for c in cams], fontsize=8)
    ax.set_xlim(0, 1)
    ax.set_xlabel("health index (1 = no symptom; 1 - worst symptom, each scaled to 0..1)")
    handles = [plt.Rectangle((0, 0), 1, 1, color=v) for v in colors.values()]
    ax.legend(handles, [k or "healthy" for k in colors], fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1),
              title="limited by")
    ax.grid(axis="x", alpha=0.3)
    return _png(fig)


def _fmt(v: Any) -> str:
    if v is None:
        return "–"
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, (list, tuple)):
        return ", ".join(_fmt(x) for x in v)
    return str(v)


def _table(rows: Sequence[Sequence[Any]], head: Sequence[str], limit: int = 500) -> str:
    body = "".join("<tr>" + "".join(f"<td>{html.escape(_fmt(v))}</td>" for v in r) + "</tr>" for r in rows[:limit])
    more = f"<p>{len(rows) - limit} more rows in campaign.json.</p>" if len(rows) > limit else ""
    return ("<table><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in head) + "</tr>" + body + "</table>"
            + more)


def write_html(campaign: dict[str, Any], path: Path) -> None:
    """One self-contained HTML file (plots embedded as PNG)."""
    t, run = campaign["totals"], campaign["run"]
    figs = [f for f in (_health_figure(campaign), _camera_figure(campaign)) if f]
    trend_cell = lambda tr: (f"{tr['slope_dn_per_week']:+.3f} ± {tr['stderr_dn_per_week']:.3f}"  # noqa: E731
                             + (" *" if tr["significant"] else "")) if tr else None
    cams = [[c["rank"], c["hardware_id"], c["health"], c["health_limited_by"], c["bags"], c["frames_total"],
             c["frames_processed"], c["frames_in_alarm"], c["alarm_episodes"], c["mean"]["xi"],
             c["mean"]["sigma_dcsn"], trend_cell(c["trends"]["xi"]), trend_cell(c["trends"]["sigma_dcsn"]),
             "; ".join(c["findings"])] for c in campaign["cameras"]]
    bags = [[b["hardware_id"], Path(b["path"]).name, b["start_utc"], b["frames_total"], b["frames_processed"],
             b["frames_skipped"], b["frames_lost"], b["alarm_episodes"], b["stats"]["xi"]["mean"], b["stats"]["sigma_pn"]["mean"],
             b["stats"]["sigma_dcsn"]["mean"], b["stats"]["sigma_rn"]["mean"], b["conditions"]["sensor_temperature_c"],
             b["conditions"]["gain_db"]] for b in campaign["bags"]]
    eps = [[a["hardware_id"], Path(a["bag"]).name, a["start_utc"], a["end_utc"], a["duration_s"], a["frames"],
            a["sign"], a["peak_xi_dn"], a["cause"]] for a in campaign["alarm_episodes"]]
    bad = [[p["path"], p["reason"]] for p in (*campaign["failed"], *campaign["duplicates"], *campaign["problems"])]
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>noise_monitor campaign</title><style>"
        "body{font-family:sans-serif;margin:1.5em}table{border-collapse:collapse;font-size:12px}"
        "td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}th{background:#eee}"
        "td:nth-child(2){text-align:left}</style></head><body>",
        "<h1>noise_monitor field campaign</h1>",
        f"<p>{t['bags_found']} bags found: {t['bags_evaluated']} evaluated, {t['bags_failed']} failed, "
        f"{t['bags_duplicate']} duplicates, {t['bags_not_run']} not run; {t['inputs_rejected']} inputs rejected. "
        f"{t['cameras']} cameras, {t['frames_total']} frames ({t['frames_processed']} processed, "
        f"{t['frames_skipped']} skipped; {t['frames_lost']} missing from the recordings by their stamps), "
        f"{t['alarm_episodes']} alarm episodes. Backend {html.escape(str(run['backend']))}, "
        f"{run['bags_run']} bags run in {run['wall_time_s']} s ({run['bags_resumed']} finished before)"
        + (f"; {html.escape(run['backend_note'])}" if run.get("backend_note") else "") + ".</p>",
        "<h2>Cameras ranked by health</h2><p>Health = 1 - the worst symptom: fraction of frames in alarm, "
        "fraction not evaluated, |mean xi| and a significant xi drift over the campaign (0 below a quarter of the "
        "alarm threshold, 1 at the threshold), "
        "relative growth of the dark-current shot noise. Trends are least-squares slopes per week over the bags, "
        "with the conditions that vary between bags as regressors (equal conditions); * = beyond 3 standard errors.</p>",
        _table(cams, ["rank", "camera", "health", "limited by", "bags", "frames", "processed", "in alarm", "episodes",
                      "mean xi [DN]", "mean DCSN [DN]", "xi trend [DN/week]", "DCSN trend [DN/week]", "findings"]),
        *(f"<p><img src='data:image/png;base64,{f}'></p>" for f in figs),
        *(["<h2>Cameras not evaluated</h2><p>Every bag of these cameras failed (the first reason):</p>",
           _table([[c["hardware_id"], c["bags_failed"], c["reason"]] for c in campaign["cameras_not_evaluated"]],
                  ["camera", "bags failed", "reason"])] if campaign.get("cameras_not_evaluated") else []),
        "<h2>Alarm episodes (UTC)</h2>",
        _table(eps, ["camera", "bag", "start", "end", "duration [s]", "frames", "xi sign", "peak xi [DN]", "cause"]),
        "<h2>Not evaluated</h2>", _table(bad, ["input", "reason"]) if bad else "<p>none</p>",
        "<h2>Frames skipped, by reason</h2>",
        _table([[n, reason] for reason, n in t["skip_reasons"].items()], ["frames", "reason"]) if t["skip_reasons"]
        else "<p>none</p>",
        "<h2>Bags</h2>",
        _table(bags, ["camera", "bag", "start (UTC)", "frames", "processed", "skipped", "lost", "episodes", "xi [DN]",
                      "PN [DN]", "DCSN [DN]", "RN [DN]", "temperature [°C]", "gain [dB]"], limit=2000),
        "</body></html>",
    ]
    path.write_text("".join(parts), encoding="utf-8")
