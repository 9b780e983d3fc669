"""PNG plot of a replay: per-source sigma and xi over time, alarm spans shaded, skipped frames marked, which
measurement drove xi and where a still hold's measurement restarted."""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter  # noqa: E402

from noise_monitor.monitor.status import HOLD_EVENT_SEPARATOR, HOLD_EVENTS, XI_MEASUREMENTS  # noqa: E402

from .results import FrameTable  # noqa: E402

SERIES = (("sigma_pn", "PN (photon shot)", "tab:blue"), ("sigma_dcsn", "DCSN (dark current shot)", "tab:orange"),
          ("sigma_rn", "RN (readout)", "tab:green"), ("sigma_total", "total (estimated)", "black"),
          ("sigma_model", "model total (stated metadata)", "tab:gray"),
          ("sigma_image", "noise measured in the image", "tab:purple"))
#: A still hold's frame differences: the noise measured there and the model's temporal noise on the same blocks
#: (sigma_temporal + xi_temporal), drawn with gaps between holds.
TEMPORAL_LABELS = ("noise from frame differences (still view)", "model of the frame differences (same blocks)")
#: Per-frame xi by the measurement that drove it (``FrameResult.xi_measurement``): label, colour.
XI_MEASUREMENT_STYLES = dict(zip(XI_MEASUREMENTS, (("xi per frame: single image", "tab:purple"),
                                                   ("xi per frame: frame differences (still view)", "darkcyan"),
                                                   ("xi per frame: image bound (texture hides the noise)", "tab:olive")),
                                 strict=True))
#: Where a still hold's frame-difference measurement restarted (``FrameResult.hold_event``): line style.
HOLD_EVENT_STYLES = dict(zip(HOLD_EVENTS, (":", "--")))


def plot_replay(table: FrameTable, episodes: list[dict[str, Any]], path: Path, title: str,
                threshold_dn: float, frame_period_s: float = 0.0,
                truth_spans: Sequence[tuple[float, float, str]] = ()) -> Path:
    """Write :func:`replay_figure` as a PNG."""
    fig = replay_figure(table, episodes, title, threshold_dn, frame_period_s, truth_spans)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def replay_figure(table: FrameTable, episodes: list[dict[str, Any]], title: str, threshold_dn: float,
                  frame_period_s: float = 0.0, truth_spans: Sequence[tuple[float, float, str]] = ()) -> Figure:
    """Three stacked panels sharing the time axis (seconds since the first frame): sigma, xi, conditions.

    ``truth_spans`` (start s, end s, label): known corruptions of a simulated bag, hatched.
    """
    fig, (ax_s, ax_x, ax_c) = plt.subplots(3, 1, figsize=(13, 8.5), sharex=True,
                                           gridspec_kw={"height_ratios": [3, 2, 1.4]}, constrained_layout=True)
    for key, label, color in SERIES:
        t, v = table.series(key)
        if t.size:
            style = {"sigma_model": "--", "sigma_image": ":"}.get(key, "-")
            ax_s.plot(t, v, style, color=color, lw=1.3, label=label, marker="." if t.size < 60 else None)
    time_s, temporal = table.column("time_s"), table.numbers("sigma_temporal")
    if np.any(~np.isnan(temporal)):  # NaN between holds breaks the lines
        ax_s.plot(time_s, temporal, "-", color="darkcyan", lw=1.6, marker=".", ms=3, label=TEMPORAL_LABELS[0])
        ax_s.plot(time_s, table.temporal_model(), "--", color="darkcyan", lw=1.2, label=TEMPORAL_LABELS[1])
    xi, measurement = table.numbers("xi"), np.array(table.texts("xi_measurement"), dtype=object)
    for key, (label, color) in XI_MEASUREMENT_STYLES.items():
        drove = (measurement == key) & ~np.isnan(xi)
        if drove.any():
            ax_x.plot(time_s[drove], xi[drove], ".", color=color, ms=4, alpha=0.7, label=label)
    t, v = table.series("xi_filtered")
    if t.size:
        ax_x.plot(t, v, "-", color="tab:purple", lw=1.6, label="xi filtered")
    t, v = table.series("xi_bound")
    if np.any(v > 0):  # what the image alone proves on any content: xi >= xi_bound (drawn where that says xi > 0)
        ax_x.plot(t[v > 0], v[v > 0], "^", color="tab:olive", ms=4, label="xi lower bound > 0 (image alone)")
    ax_x.axhline(0.0, color="black", lw=0.6)
    for sgn in (1, -1):
        ax_x.axhline(sgn * threshold_dn, color="tab:red", ls=":", lw=1.0,
                     label=f"alarm threshold ±{threshold_dn:g} DN" if sgn > 0 else None)
    for i, ep in enumerate(episodes):
        for ax in (ax_s, ax_x):
            ax.axvspan(ep["start_s"] - frame_period_s / 2, ep["end_s"] + frame_period_s / 2, color="tab:red",
                       alpha=0.15, lw=0, label=("alarm (xi " + ("< 0" if ep["sign"] == "-" else "> 0") + ")")
                       if i == 0 and ax is ax_x else None)
    for i, (a, b, label) in enumerate(truth_spans):
        ax_x.axvspan(a - frame_period_s / 2, b + frame_period_s / 2, fill=False, hatch="//", ec="tab:gray", lw=0,
                     label=f"simulated: {label}" if i == 0 else None)
    _mark_hold_events(ax_s, ax_x, table)
    skipped = time_s[~table.column("processed")]
    if skipped.size:
        ax_x.plot(skipped, np.zeros(len(skipped)), "x", color="tab:gray", ms=5, label="skipped frame")
    _plot_conditions(ax_c, table)
    ax_s.set_ylabel("noise sigma [DN]")
    ax_s.set_ylim(bottom=0)
    ax_x.set_ylabel("xi [DN]\n(model - measured)")
    ax_c.set_xlabel("time since first frame [s]")
    ax_s.set_title(title)
    for ax in (ax_s, ax_x, ax_c):
        ax.grid(True, alpha=0.3)
    for ax in (ax_s, ax_x):
        ax.legend(loc="upper left", bbox_to_anchor=(1.06, 1.0), fontsize=8, borderaxespad=0)
    return fig


def _mark_hold_events(ax_s: plt.Axes, ax_x: plt.Axes, table: FrameTable) -> None:
    """A vertical line at each frame where a still hold's frame-difference measurement restarted."""
    time_s, events = table.column("time_s"), table.texts("hold_event")
    for event, style in HOLD_EVENT_STYLES.items():
        at = [t for t, e in zip(time_s, events) if e is not None and event in e.split(HOLD_EVENT_SEPARATOR)]
        for i, t in enumerate(at):
            for ax in (ax_s, ax_x):
                ax.axvline(t, color="darkcyan", ls=style, lw=1.0,
                           label=f"{event} in a still view: measurement restarts" if i == 0 and ax is ax_x
                           else None)


def _plot_conditions(ax: plt.Axes, table: FrameTable) -> None:
    """Stated gain and temperature (left axis) and exposure (right axis, log) per frame."""
    t, gain = table.series("gain_db")
    if not t.size:
        ax.text(0.5, 0.5, "no usable metadata", transform=ax.transAxes, ha="center", va="center")
        return
    ax.step(t, gain, where="post", color="tab:brown", label="gain [dB]")
    ax.step(*table.series("sensor_temperature_c"), where="post", color="tab:red", label="temperature [degC]")
    ax.set_ylabel("gain [dB]\ntemperature [degC]")
    ax_e = ax.twinx()
    t, exposure = table.series("exposure_time_s")
    ax_e.step(t, 1e3 * exposure, where="post", color="tab:cyan", ls="--", label="exposure [ms]")
    ax_e.set_yscale("log")
    ax_e.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    ax_e.yaxis.set_major_formatter(FormatStrFormatter("%g"))
    ax_e.yaxis.set_minor_formatter(NullFormatter())
    ax_e.set_ylabel("exposure [ms]")
    lines = ax.get_lines() + ax_e.get_lines()
    ax.legend(lines, [str(ln.get_label()) for ln in lines], loc="upper left", fontsize=8, framealpha=0.8)
