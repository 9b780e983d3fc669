"""EMVA-style plots and an HTML report of a characterization (measurement beside the profile's model)."""
from __future__ import annotations

import html
import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from noise_monitor.physics import CameraProfile  # noqa: E402

from .emva import model_ptc, temporal_model  # noqa: E402

_LABELS = {
    "system_gain_dn_per_e": "System gain K",
    "system_gain_dn8_per_e": "System gain K (node's 8-bit scale)",
    "temporal_dark_noise_e": "Temporal dark noise sigma_d (shortest exposure)",
    "read_noise_e": "Read noise (dark noise at zero exposure)",
    "saturation_capacity_e": "Saturation capacity",
    "doubling_temperature_k": "Dark current doubling temperature",
    "dsnu_e": "DSNU1288",
    "prnu_pct": "PRNU1288",
    "dsnu_hpf_e": "DSNU of the pixels (5x5 high-pass: smooth shading off; the profile's)",
    "prnu_hpf_pct": "PRNU of the pixels (5x5 high-pass: smooth shading off; the profile's)",
    "linearity_error_pct": "Linearity error (largest deviation)",
    "quantum_efficiency": "Quantum efficiency",
    "responsivity_dn_per_p": "Responsivity R",
    "saturation_capacity_p": "Saturation capacity (photons)",
    "sensitivity_threshold_p": "Absolute sensitivity threshold",
    "dynamic_range_db": "Dynamic range",
}


def _fmt(v: float | None, se: float | None = None) -> str:
    if v is None:
        return "not determined"
    s = f"{v:.4g}"
    return s + (f" &plusmn; {se:.2g}" if se is not None else "")


def plots(result: dict[str, Any], out: Path, profile: CameraProfile | None) -> dict[str, str]:
    """Write the PNGs; returns {name: file name}."""
    pts, cond, fig_ = result["points"], result["conditions"], result["figures"]
    bits = cond["bit_depth"]
    to_nat = (2**bits - 1) / 255.0
    k8 = fig_["system_gain_dn8_per_e"]["value"]
    files: dict[str, str] = {}
    ptc = pts["ptc"]
    x, y, used = np.array(ptc["signal_dn"]), np.array(ptc["variance_dn2"]), np.array(ptc["k_fit"], bool)
    model = None
    if profile is not None:
        meta = profile.metadata(gain_db=cond["gain_db"], exposure_time_s=cond["temporal_dark_noise_exposure_s"],
                                sensor_temperature_c=cond["temperature_c"] if cond["temperature_c"] is not None else 25.0)
        tm = temporal_model(profile)
        _, mm, mv = model_ptc(tm, meta, profile.black_level_dn)  # the black level off: its dark mean is 0
        c = tm.conditions(meta)
        dark_var = sum(float(e.variance_dn2(0.0, c)) for e in tm.noise_effects if e.name != "pn")
        model = (mm, mv - dark_var)
    # photon transfer curve
    f, ax = plt.subplots(figsize=(6.4, 4.4))
    ax.plot(x * to_nat, y * to_nat**2, "o", ms=4, color="0.55", label="measured")
    ax.plot(x[used] * to_nat, y[used] * to_nat**2, "o", ms=4, color="C0", label="measured, used for K")
    xx = np.linspace(0, x[used].max(), 50)
    ax.plot(xx * to_nat, k8 * xx * to_nat**2, "-", color="C0",
            label=f"fit: K = {fig_['system_gain_dn_per_e']['value']:.4g} DN/e-")
    if model is not None:
        ax.plot(model[0] * to_nat, model[1] * to_nat**2, "--", color="C3", label="profile's model")
    if ptc["saturation_dn"]:
        ax.axvline(ptc["saturation_dn"] * to_nat, color="C2", lw=1, label="saturation (variance maximum)")
    ax.set_xlabel(f"mean signal mu_y - mu_y.dark [DN, {bits} bit]")
    ax.set_ylabel(f"sigma_y^2 - sigma_y.dark^2 [DN^2, {bits} bit]")
    ax.set_title("Photon transfer curve")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    files["ptc"] = _save(f, out / "ptc.png")
    # SNR vs signal in electrons
    sd = fig_["temporal_dark_noise_e"]["value"]
    q_e2 = (255.0 / (2**bits - 1)) ** 2 / 12.0 / k8**2
    ok = (x > 0) & np.array(ptc["unclipped"], bool)
    mu_e = x[ok] / k8
    snr = x[ok] / np.sqrt(np.maximum(np.array(ptc["total_variance_dn2"])[ok], 1e-12))
    f, ax = plt.subplots(figsize=(6.4, 4.4))
    ax.loglog(mu_e, snr, "o", ms=4, label="measured (flats without clipped pixels)")
    ee = np.logspace(0, math.log10(max(mu_e.max(), 10.0)), 100)
    if sd is not None:
        ax.loglog(ee, ee / np.sqrt(sd**2 + ee + q_e2), "-", label="EMVA linear model from the fitted figures")
    ax.loglog(ee, np.sqrt(ee), ":", color="0.5", label="ideal (shot noise only)")
    ax.set_xlabel("signal mu_e [e-]")
    ax.set_ylabel("SNR [1]")
    ax.set_title("Signal-to-noise ratio")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    files["snr"] = _save(f, out / "snr.png")
    # dark signal vs exposure per temperature (none from a recording at one exposure)
    if pts["dark"]:
        f, ax = plt.subplots(figsize=(6.4, 4.4))
        for i, s in enumerate(pts["dark"]):
            t = np.array(s["exposure_s"])
            lbl = "unknown T" if s["temperature_c"] is None else f"{s['temperature_c']:g} degC"
            ax.plot(t * 1e3, np.array(s["mean_dn"]) * to_nat, "o", ms=4, color=f"C{i}",
                    label=f"{lbl} measured" if s["fit"] else f"{lbl} measured (within ADC steps: not determined)")
            if s["fit"]:
                tt = np.linspace(0, t.max(), 20)
                ax.plot(tt * 1e3, np.polyval(s["fit"], tt) * to_nat, "-", color=f"C{i}",
                        label=f"{lbl} fit: {s['rate_e_per_s']:.3g} e-/s")
        ax.set_xlabel("exposure time [ms]")
        ax.set_ylabel(f"dark signal mu_y.dark [DN, {bits} bit]")
        ax.set_title("Dark signal vs exposure time")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        files["dark_exposure"] = _save(f, out / "dark_vs_exposure.png")
    # dark current vs temperature
    temps = [(s["temperature_c"], s["rate_e_per_s"]) for s in pts["dark"] if s["temperature_c"] is not None
             and (s["rate_e_per_s"] or 0.0) > 0]
    if temps:
        f, ax = plt.subplots(figsize=(6.4, 4.4))
        tt, rr = np.array(temps).T
        ax.semilogy(tt, rr, "o", label="measured")
        td = fig_["doubling_temperature_k"]["value"]
        if td:
            grid = np.linspace(tt.min(), tt.max(), 50)
            p = np.polyfit(tt, np.log(rr), 1)
            ax.semilogy(grid, np.exp(np.polyval(p, grid)), "-", label=f"fit: doubling every {td:.3g} K")
        if profile is not None:
            from .emva import dark_current_e_per_s

            grid = np.linspace(tt.min(), tt.max(), 50)
            ax.semilogy(grid, [dark_current_e_per_s(profile, g) for g in grid], "--", color="C3",
                        label="profile's model")
        ax.set_xlabel("sensor temperature [degC]")
        ax.set_ylabel("dark current [e-/s]")
        ax.set_title("Dark current vs temperature")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
        files["dark_temperature"] = _save(f, out / "dark_vs_temperature.png")
    # linearity
    lin = pts["linearity"]
    if "fit" in lin:  # against the photons where the set states them (EMVA's abscissa), else the exposure
        t, scale, axis = ((np.array(lin["photons"]), 1.0, "photons per pixel mu_p [p]") if "photons" in lin
                          else (np.array(lin["exposure_s"]), 1e3, "exposure time [ms]"))
        s = np.array(lin["signal_dn"])
        m = np.array(lin["range_mask"], bool)
        f, (a1, a2) = plt.subplots(2, 1, figsize=(6.4, 6.0), sharex=True)
        a1.plot(t * scale, s * to_nat, "o", ms=4, color="0.55", label="measured")
        a1.plot(t[m] * scale, s[m] * to_nat, "o", ms=4, color="C0", label="measured, 5-95 % of saturation")
        a1.plot(t * scale, np.polyval(lin["fit"], t) * to_nat, "-", color="C0", label="straight-line fit")
        a1.set_ylabel(f"mu_y - mu_y.dark [DN, {bits} bit]")
        a1.set_title("Linearity")
        a1.grid(alpha=0.3)
        a1.legend(fontsize=8)
        a2.plot(t[m] * scale, lin["deviation_pct"], "o-", ms=4)
        a2.axhline(0, color="0.5", lw=1)
        a2.set_xlabel(axis)
        a2.set_ylabel("deviation from the line [%]")
        a2.grid(alpha=0.3)
        files["linearity"] = _save(f, out / "linearity.png")
    return files


def _save(fig, path: Path) -> str:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path.name


def write_html(result: dict[str, Any], out: Path, files: dict[str, str], source: str,
               round_trip: list[dict[str, Any]] | None, profile_file: str | None) -> Path:
    """The report page: figures with uncertainties, conditions, notes, round trip and plots."""
    rows = []
    for key, label in _LABELS.items():
        v = result["figures"][key]
        rows.append(f"<tr><td>{label}</td><td>{_fmt(v['value'], v['stderr'])}</td><td>{html.escape(v['unit'])}</td></tr>")
    for temp, v in result["figures"]["dark_current_e_per_s"].items():
        rows.append(f"<tr><td>Dark current at {html.escape(temp)} degC</td><td>{_fmt(v['value'], v['stderr'])}</td>"
                    f"<td>e-/s</td></tr>")
    cond = result["conditions"]
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>EMVA 1288 characterization</title>",
        "<style>body{font-family:sans-serif;max-width:60em;margin:2em auto}td,th{padding:2px 10px;"
        "border-bottom:1px solid #ddd}img{max-width:48%;margin:4px}</style></head><body>",
        f"<h1>EMVA 1288 characterization of {html.escape(source)}</h1>",
        f"<p>{cond['frames']} frames ({cond['width']}x{cond['height']} px, {cond['bit_depth']} bit), "
        f"{cond['sets']} sets: {cond['flat_sets']} flat, {cond['dark_sets']} dark at the analysed gain "
        f"{cond['gain_db']:g} dB and temperature {cond['temperature_c']} degC. Uncertainties are standard errors "
        "of the fits.</p>",
        "<table><tr><th>figure</th><th>value</th><th>unit</th></tr>", *rows, "</table>",
    ]
    if result["notes"]:
        parts += ["<h2>Not determined / notes</h2><ul>", *(f"<li>{html.escape(n)}</li>" for n in result["notes"]),
                  "</ul>"]
    if round_trip:
        parts += ["<h2>Profile for the node</h2>",
                  f"<p>{html.escape(profile_file or '')}: the figures it was made from (the temporal dark noise at "
                  "the DSNU's exposure, the dark-current law fitted over the temperatures) and the measured dark "
                  "currents, predicted back from the profile's model.</p>",
                  "<table><tr><th>figure</th><th>made from</th><th>profile's model</th><th>error</th></tr>"]
        for r in round_trip:
            err = "n/a" if r["rel_error"] is None else f"{100 * r['rel_error']:+.2f} %"
            parts.append(f"<tr><td>{html.escape(r['field'])}</td><td>{_fmt(r['datasheet'])}</td>"
                         f"<td>{_fmt(r['predicted'])}</td><td>{err}</td></tr>")
        parts.append("</table>")
    parts.append("<h2>Plots</h2>")
    parts += [f"<img src='{html.escape(f)}' alt='{html.escape(k)}'>" for k, f in files.items()]
    parts.append("</body></html>")
    path = out / "report.html"
    path.write_text("\n".join(parts))
    return path
