"""EMVA 1288 figures <-> noise-model profile: the mapping, and its round trip.

Mapping (the model works on an 8-bit DN scale with ``DN/e- = 255 g / FW``, g the gain factor):

- system gain K (native DN/e-, base gain 0 dB): ``full_well_e = (2^bits - 1) / K``. The model's K at
  gain G dB is ``K * 10^(G/20)``; K given at other gain settings is checked against that.
- saturation capacity: the model saturates at the ADC range (255 DN on its scale), less the black level (the
  dark offset) where one is given; its EMVA saturation (mean at the maximum of the temporal variance, clipping
  included) is predicted and compared. A datasheet whose saturation exceeds the ADC range above the dark offset at
  base gain is contradictory (error); one clearly below it (a full well that the model lacks) cannot be reproduced
  (stated).
- dark current mu_I at T and doubling temperature T_d: ``dark_signal_fom_na_cm2`` from the band-gap
  law at T; where T_d differs from the law's own, a ``dark_current_law`` effect adds the exponential
  rate r = (ln 2 - ln(b(T + T_d) / b(T))) / T_d (b: the law), so mu_I(T + T_d) = 2 mu_I(T) exactly.
- temporal dark noise sigma_d: minus the dark-current shot noise at the measurement's exposure, what
  remains is read noise, put in the source follower: ``thermal_white_noise_v_per_sqrt_hz`` is solved
  numerically (Brent) so the rounded source-follower variance equals it (kTC off: reset factor 0).
- PRNU (%) -> ``prnu`` effect; DSNU (e-) -> ``dsnu`` effect, whose fixed pattern is a fraction of the
  dark signal: fraction = DSNU / dark signal at the measurement's exposure and temperature.
- bit depths up to 10: a ``quantization`` effect (EMVA's sigma_d excludes the quantization noise).

Not identifiable from a datasheet: the quantum efficiency (it only scales photons, the model starts
at electrons; recorded as a comment), the split of read noise between source follower and kTC reset
noise, the pixel clock and sense-node gain (defaults unless given: only their product with the white
noise matters), and DSNU that is offset non-uniformity (it does not scale with the dark signal).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import brentq

from noise_monitor.physics import CameraMetadata, CameraProfile, NoiseModel, build_effects
from noise_monitor.physics.clipping import DN_MAX
from noise_monitor.physics.metadata import VALID_RANGES
from noise_monitor.physics.model import TABLE_STEP_DN
from noise_monitor.physics.sensor import T_REF_K, dark_electrons, rounded_normal_variance, source_follower_sigma_e

from .datasheet import Datasheet, DatasheetError

#: Round-trip acceptance: every reproduced figure within this relative error.
TOLERANCE = 0.02
#: Defaults for what a datasheet does not identify (the generic profile's clock, the paper's A_SN).
DEFAULT_PIXEL_CLOCK_HZ = 74.25e6
DEFAULT_SENSE_NODE_GAIN_V_PER_E = 5.0e-6
#: Bit depths with a quantization effect (above, LSB^2/12 < 0.005 DN^2 on the 8-bit scale).
QUANTIZATION_MAX_BITS = 10
#: Linear range of the photon transfer curve used for K (fraction of the 8-bit range).
PTC_LINEAR_RANGE = (0.05, 0.70)
#: Exposure standing in for "negligible" (the model needs a positive exposure).
MIN_EXPOSURE_S = 1e-7
_W_BOUNDS = VALID_RANGES["thermal_white_noise_v_per_sqrt_hz"]
_DSNU_MAX_FRACTION = 10.0


@dataclass
class ProfileResult:
    """A profile made from a datasheet, with what the mapping derived and what it could not represent."""

    profile: CameraProfile
    derived: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def to_yaml(self, datasheet: Datasheet, source: str = "") -> str:
        """The profile YAML, headed by comments: its source, the quantum efficiency and the notes."""
        source = source or f"the EMVA 1288 datasheet of {datasheet.name} (noise-monitor profile from-emva)"
        head = [f"# Camera profile from {source}."]
        if datasheet.quantum_efficiency_pct is not None:
            wl = f" at {datasheet.wavelength_nm:g} nm" if datasheet.wavelength_nm else ""
            head.append(f"# Quantum efficiency {datasheet.quantum_efficiency_pct:g} %{wl} (not a model field: "
                        "the model starts at electrons).")
        head += [f"# Note: {n}" for n in self.notes]
        return "\n".join(head) + "\n" + self.profile.to_yaml()


def to_8bit(k_native: float, bits: int) -> float:
    """DN/e- on the model's 8-bit scale from native DN/e- of a ``bits``-bit camera."""
    return k_native * 255.0 / (2**bits - 1)


def to_native(k_8bit: float, bits: int) -> float:
    return k_8bit * (2**bits - 1) / 255.0


# --- model side: the EMVA figures a profile predicts ---------------------------------------------
def temporal_model(profile: CameraProfile) -> NoiseModel:
    """The paper's sources plus the profile's temporal effects and modifiers (what frame differences see)."""
    extra = [e for e in build_effects(profile.effects) if e.temporal]
    return NoiseModel(extra=extra)


def _meta(profile: CameraProfile, gain_db: float = 0.0, exposure_s: float | None = None,
          temperature_c: float = 25.0) -> CameraMetadata:
    return profile.metadata(gain_db=gain_db, exposure_time_s=max(exposure_s or 0.0, MIN_EXPOSURE_S),
                            sensor_temperature_c=temperature_c)


def model_ptc(model: NoiseModel, meta: CameraMetadata, black_level_dn: float = 0.0
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(clean signal, mean, temporal variance) of the model's output on its 8-bit scale, the black level taken off,
    clipping included (a camera with a black level saturates that much sooner)."""
    if not black_level_dn:
        m1, m2 = model.tables(meta)["total"]
        v = np.arange(0.0, DN_MAX + 1e-9, TABLE_STEP_DN)  # the model's table grid
        return v, v + m1, m2 - m1**2
    return model.output_moments(meta, black_level_dn)


def ptc_gain(mean: np.ndarray, var: np.ndarray, black_level_dn: float = 0.0) -> float:
    """Slope of variance vs mean over the linear range of the ADC's span above the black level (DN/e- on the
    data's scale)."""
    lo, hi = (f * (255.0 - black_level_dn) for f in PTC_LINEAR_RANGE)
    sel = (mean >= lo) & (mean <= hi)
    return float(np.polyfit(mean[sel], var[sel], 1)[0])


def ptc_saturation(mean: np.ndarray, var: np.ndarray) -> float:
    """Mean at the maximum of the variance (parabolic refinement between grid nodes)."""
    i = int(np.argmax(var))
    if 0 < i < len(var) - 1:
        y0, y1, y2 = var[i - 1:i + 2]
        den = y0 - 2 * y1 + y2
        off = 0.5 * (y0 - y2) / den if den < 0 else 0.0
        return float(mean[i] + off * (mean[i + 1] - mean[i - 1]) / 2.0)
    return float(mean[i])


def dark_current_e_per_s(profile: CameraProfile, temperature_c: float) -> float:
    """The model's mean dark current (e-/s) at a temperature, law deviations included."""
    model = temporal_model(profile)
    cond = model.conditions(_meta(profile, exposure_s=1.0, temperature_c=temperature_c))
    return float(cond.dark_e)


def predict_datasheet(profile: CameraProfile, ds: Datasheet) -> dict[str, Any]:
    """The EMVA 1288 figures the profile's model predicts, under the datasheet's conditions."""
    bits = ds.bit_depth
    model = temporal_model(profile)
    t_meas = ds.measurement_exposure_s
    temp_meas = ds.measurement_temperature_c if ds.measurement_temperature_c is not None else ds.dark_current_temperature_c
    out: dict[str, Any] = {}
    meta0 = _meta(profile, 0.0, t_meas, temp_meas)
    black = profile.black_level_dn
    _, mean, var = model_ptc(model, meta0, black)
    k8 = ptc_gain(mean, var, black)
    out["system_gain_dn_per_e"] = to_native(k8, bits)
    out["saturation_capacity_e"] = ptc_saturation(mean, var) / k8
    out["gains"] = []
    for g_db, _ in ds.gains:
        _, mg, vg = model_ptc(model, _meta(profile, g_db, t_meas, temp_meas), black)
        out["gains"].append(to_native(ptc_gain(mg, vg, black), bits))
    cond = model.conditions(meta0)
    dark_var = sum(float(e.variance_dn2(0.0, cond)) for e in model.noise_effects
                   if e.distribution in ("poisson", "gaussian") and e.name != "pn")
    out["temporal_dark_noise_e"] = math.sqrt(dark_var) / cond.dn_per_e
    t1 = ds.dark_current_temperature_c
    out["dark_current_e_per_s"] = dark_current_e_per_s(profile, t1)
    if ds.doubling_temperature_k is not None:
        t2 = t1 + ds.doubling_temperature_k
        mu2 = dark_current_e_per_s(profile, t2)
        out["dark_current_e_per_s_at_t_plus_td"] = mu2
        out["doubling_temperature_k"] = (t2 - t1) * math.log(2.0) / math.log(mu2 / out["dark_current_e_per_s"]) \
            if mu2 > out["dark_current_e_per_s"] > 0 else None
    effects = {e.name: e for e in build_effects(profile.effects)}
    out["dsnu_e"] = math.sqrt(float(effects["dsnu"].variance_dn2(0.0, cond))) / cond.dn_per_e if "dsnu" in effects else 0.0
    s50 = 0.5 * 255.0
    out["prnu_pct"] = 100.0 * math.sqrt(float(effects["prnu"].variance_dn2(s50, cond))) / s50 if "prnu" in effects else 0.0
    return out


def round_trip(ds: Datasheet, profile: CameraProfile) -> list[dict[str, Any]]:
    """Per figure: datasheet value, the profile's prediction, relative error and whether it is within 2 %."""
    pred = predict_datasheet(profile, ds)
    rows: list[tuple[str, float, float | None]] = [
        ("system_gain_dn_per_e", ds.system_gain_dn_per_e, pred["system_gain_dn_per_e"]),
        *((f"system_gain_dn_per_e@{g:g}dB", k, p) for (g, k), p in zip(ds.gains, pred["gains"])),
        ("saturation_capacity_e", ds.saturation_capacity_e, pred["saturation_capacity_e"]),
        ("temporal_dark_noise_e", ds.temporal_dark_noise_e, pred["temporal_dark_noise_e"]),
        (f"dark_current_e_per_s@{ds.dark_current_temperature_c:g}C", ds.dark_current_e_per_s,
         pred["dark_current_e_per_s"]),
    ]
    if ds.doubling_temperature_k is not None and ds.dark_current_e_per_s > 0:  # of no dark current: no doubling
        t2 = ds.dark_current_temperature_c + ds.doubling_temperature_k
        rows.append((f"dark_current_e_per_s@{t2:g}C", 2.0 * ds.dark_current_e_per_s,
                     pred["dark_current_e_per_s_at_t_plus_td"]))
        rows.append(("doubling_temperature_k", ds.doubling_temperature_k, pred["doubling_temperature_k"]))
    if ds.dsnu_e is not None:
        rows.append(("dsnu_e", ds.dsnu_e, pred["dsnu_e"]))
    if ds.prnu_pct is not None:
        rows.append(("prnu_pct", ds.prnu_pct, pred["prnu_pct"]))
    out = []
    for name, want, got in rows:
        if got is None:
            err = None
        elif want == 0:
            err = abs(got)  # absolute for a zero figure
        else:
            err = (got - want) / want
        out.append({"field": name, "datasheet": want, "predicted": None if got is None else float(got),
                    "rel_error": None if err is None else float(err),
                    "ok": bool(err is not None and abs(err) <= TOLERANCE)})
    return out


# --- datasheet -> profile --------------------------------------------------------------------------
def _law_rate(meta_unit: CameraMetadata, t1_c: float, td_k: float) -> float:
    """Extra exponential rate (1/K) that makes the band-gap law double over td_k above t1_c."""
    b1 = dark_electrons(meta_unit, 1.0, t1_c + 273.15)
    b2 = dark_electrons(meta_unit, 1.0, t1_c + td_k + 273.15)
    return (math.log(2.0) - math.log(b2 / b1)) / td_k


def fit_dark_law(pixel_size_m: float, temperatures_c: list[float], rates_e_per_s: list[float],
                 rel_errors: list[float] | None = None) -> tuple[float, float]:
    """(mu_I at the first temperature, doubling temperature there) of the model's law fitted to measurements.

    The model's dark current is D b(T) exp(r (T - 25 degC)) (b: band-gap law): ln(mu_I / b) is linear in T,
    so (ln D, r) is a weighted straight-line fit; the doubling temperature is the model's at the first T.
    """
    unit = CameraMetadata.from_mapping({"sensor_type": "ccd", "full_well_e": 1e4, "pixel_size_m": pixel_size_m,
                                        "dark_signal_fom_na_cm2": 1.0, "pixel_clock_hz": 1e7,
                                        "sense_node_gain_v_per_e": 5e-6, "sense_node_reset_factor": 0.0,
                                        "thermal_white_noise_v_per_sqrt_hz": 1e-8, "gain_db": 0.0,
                                        "exposure_time_s": 1.0, "sensor_temperature_c": 25.0})
    tk = np.asarray(temperatures_c, dtype=float) + 273.15
    lnb = np.log([dark_electrons(unit, 1.0, t) for t in tk])
    y = np.log(np.asarray(rates_e_per_s, dtype=float)) - lnb
    w = None if rel_errors is None else 1.0 / np.maximum(np.asarray(rel_errors, dtype=float), 1e-6)
    rate, ln_d = np.polyfit(tk - T_REF_K, y, 1, w=w)

    def ln_mu(t_k: float) -> float:
        return ln_d + math.log(dark_electrons(unit, 1.0, t_k)) + rate * (t_k - T_REF_K)

    t0 = float(tk[0])
    td = brentq(lambda d: ln_mu(t0 + d) - ln_mu(t0) - math.log(2.0), 0.1, 200.0)
    return math.exp(ln_mu(t0)), float(td)


def _solve_white_noise(sensor_type: str, a_sn: float, f_clk: float, read_var_e2: float) -> tuple[float, float]:
    """(white noise V/sqrt(Hz), sense-node gain V/e-) whose rounded source-follower variance is read_var_e2."""
    def resid(w: float, a: float) -> float:
        return rounded_normal_variance(source_follower_sigma_e(sensor_type, a, f_clk, w)) - read_var_e2

    lo, hi = _W_BOUNDS
    if resid(hi, a_sn) < 0 or resid(lo, a_sn) > 0:
        # outside the white-noise range at this sense-node gain: move A_SN (sigma ~ w / A_SN) to mid-range
        mid = math.sqrt(lo * hi)
        sigma_mid = source_follower_sigma_e(sensor_type, a_sn, f_clk, mid)
        a_sn = a_sn * sigma_mid / math.sqrt(read_var_e2 + 1.0 / 12.0)
        a_lo, a_hi = VALID_RANGES["sense_node_gain_v_per_e"]
        if not a_lo <= a_sn <= a_hi:
            raise DatasheetError(f"read noise {math.sqrt(read_var_e2):.3g} e- is outside what the source-follower "
                                 "model reaches")
    w = brentq(resid, lo, hi, args=(a_sn,), xtol=1e-20, rtol=1e-12, maxiter=200)
    return float(w), float(a_sn)


def profile_from_datasheet(ds: Datasheet) -> ProfileResult:
    """A profile whose model reproduces the datasheet's figures (see the module docstring)."""
    notes: list[str] = []
    adc = ds.adc_max_dn
    k = ds.system_gain_dn_per_e
    fw = adc / k
    lo, hi = VALID_RANGES["full_well_e"]
    if not lo <= fw <= hi:
        raise DatasheetError(f"system gain {k:g} DN/e- at {ds.bit_depth} bit means {fw:.4g} e- over the ADC range, "
                             f"outside the model's full-well range [{lo:g}, {hi:g}] e-")
    sat_dn = ds.saturation_capacity_e * k
    offset = ds.dark_offset_dn or 0.0
    if sat_dn + offset > adc * (1.0 + TOLERANCE):
        above = f" above the dark offset {offset:g} DN ({adc - offset:.0f} DN)" if offset else f" ({adc} DN)"
        raise DatasheetError(f"contradictory: saturation capacity {ds.saturation_capacity_e:g} e- x K {k:g} DN/e- = "
                             f"{sat_dn:.0f} DN exceeds the {ds.bit_depth}-bit ADC range{above} at base gain")
    if sat_dn + offset < adc / 8.0:  # three bits above saturation unused: the figures' DN are another bit depth's
        fits = next(b for b in range(1, 17) if sat_dn + offset <= 2**b - 1)
        raise DatasheetError(f"saturation capacity {ds.saturation_capacity_e:g} e- x K {k:g} DN/e- = {sat_dn:.0f} DN "
                             f"is {(sat_dn + offset) / adc:.1%} of the {ds.bit_depth}-bit ADC range: a camera saturates "
                             f"near its ADC's top; the figures fit a bit_depth of {fits} ({(sat_dn + offset) / (2**fits - 1):.0%} "
                             "of its range): state the ADC's bits, not those of the 16-bit words the images come in")
    if ds.prnu_pct and ds.prnu_pct < 0.05:  # cameras: 0.1-5 %
        notes.append(f"PRNU {ds.prnu_pct:g} % is below any camera's (0.1-5 %): a fraction where percent is asked "
                     f"({100 * ds.prnu_pct:g} %)? used as given")
    if ds.quantum_efficiency_pct is not None and ds.quantum_efficiency_pct < 1.0:
        notes.append(f"quantum efficiency {ds.quantum_efficiency_pct:g} %: a fraction where percent is asked "
                     f"({100 * ds.quantum_efficiency_pct:g} %)? (recorded only)")
    t_meas = ds.measurement_exposure_s
    temp_meas = ds.measurement_temperature_c if ds.measurement_temperature_c is not None else ds.dark_current_temperature_c
    a_sn = ds.sense_node_gain_v_per_e or DEFAULT_SENSE_NODE_GAIN_V_PER_E
    f_clk = ds.pixel_clock_hz or DEFAULT_PIXEL_CLOCK_HZ
    values: dict[str, Any] = {
        "sensor_type": ds.sensor_type, "full_well_e": fw, "pixel_size_m": ds.pixel_size_um * 1e-6,
        "dark_signal_fom_na_cm2": 1.0, "pixel_clock_hz": f_clk, "sense_node_gain_v_per_e": a_sn,
        "sense_node_reset_factor": 0.0, "thermal_white_noise_v_per_sqrt_hz": 1e-8, "bit_depth": ds.bit_depth,
    }
    unit = CameraMetadata.from_mapping({**values, "gain_db": 0.0, "exposure_time_s": 1.0,
                                        "sensor_temperature_c": ds.dark_current_temperature_c})
    effects: dict[str, dict[str, float]] = {}
    # dark current: level at T, and its doubling temperature through the law deviation
    rate = 0.0
    if ds.doubling_temperature_k is None:
        notes.append("no doubling temperature given: the band-gap law's own temperature dependence is used")
    elif ds.dark_current_e_per_s > 0:
        rate = _law_rate(unit, ds.dark_current_temperature_c, ds.doubling_temperature_k)
        if abs(rate) > 0.5:
            raise DatasheetError(f"doubling temperature {ds.doubling_temperature_k:g} K is too far from the band-gap "
                                 f"law's (extra rate {rate:+.3f}/K exceeds the dark_current_law range +-0.5/K)")
    t1_k = ds.dark_current_temperature_c + 273.15
    b1 = dark_electrons(unit, 1.0, t1_k) * math.exp(rate * (t1_k - T_REF_K))
    fom = ds.dark_current_e_per_s / b1
    scale = 1.0
    fom_max = VALID_RANGES["dark_signal_fom_na_cm2"][1]
    if fom > fom_max:
        fom, scale = fom_max, fom / fom_max
    values["dark_signal_fom_na_cm2"] = fom
    if abs(rate) * (ds.doubling_temperature_k or 0.0) > 1e-4 or scale != 1.0:
        effects["dark_current_law"] = {"scale": scale, "rate_per_k": rate}
    mu_meas = _dark_e(values, effects, t_meas, temp_meas) if t_meas else 0.0
    if t_meas is None:
        notes.append("measurement.exposure_time_s not given: the dark-current shot noise in sigma_d is taken as "
                     "negligible (all of sigma_d is read noise)")
    read_var = ds.temporal_dark_noise_e**2 - mu_meas
    if read_var <= 0:
        raise DatasheetError(f"contradictory: temporal dark noise {ds.temporal_dark_noise_e:g} e- is not above the "
                             f"dark-current shot noise {math.sqrt(mu_meas):.3g} e- at {t_meas:g} s, {temp_meas:g} degC")
    w, a_sn = _solve_white_noise(ds.sensor_type, a_sn, f_clk, read_var)
    values.update(thermal_white_noise_v_per_sqrt_hz=w, sense_node_gain_v_per_e=a_sn)
    if ds.prnu_pct:
        effects["prnu"] = {"sigma_pct": ds.prnu_pct}
    if ds.dsnu_e is not None:
        if not t_meas:
            notes.append("DSNU not represented: its exposure time (measurement.exposure_time_s) is "
                         f"{'not given' if t_meas is None else '0 s: no dark signal'}, and the model's DSNU is a "
                         "fraction of the dark signal")
        else:
            fraction = ds.dsnu_e / mu_meas if mu_meas > 0 else math.inf
            if fraction > _DSNU_MAX_FRACTION:
                notes.append(f"DSNU not represented: {ds.dsnu_e:g} e- is {fraction:.3g} x the dark signal "
                             f"({mu_meas:.3g} e- at {t_meas:g} s, {temp_meas:g} degC); the model's DSNU scales with "
                             f"the dark signal (at most {_DSNU_MAX_FRACTION:g} x): this is offset non-uniformity")
            elif ds.dsnu_e > 0:
                effects["dsnu"] = {"fraction": fraction}
    if ds.bit_depth <= QUANTIZATION_MAX_BITS:
        effects["quantization"] = {"bits": ds.bit_depth}
    profile = CameraProfile(name=ds.name, values=values, effects=effects,
                            black_level_dn=(ds.dark_offset_dn or 0.0) * 255.0 / ds.adc_max_dn)
    if profile.black_level_dn:
        notes.append(f"black level {profile.black_level_dn:.4g} DN on the 8-bit scale (the dark offset "
                     f"{ds.dark_offset_dn:g} DN): the node takes it off every image")
    profile.metadata(gain_db=0.0, exposure_time_s=1.0, sensor_temperature_c=25.0)  # validates every field
    result = ProfileResult(profile, notes=notes, derived={
        "full_well_e": fw, "read_noise_e": math.sqrt(read_var), "dark_shot_noise_at_measurement_e": math.sqrt(mu_meas),
        "law_rate_per_k": rate, "law_scale": scale})
    predicted = predict_datasheet(profile, ds)
    for g_db, k_g in ds.gains:  # the model's K at G dB is K x 10^(G/20): a gain in true dB
        if abs(k_g / (k * 10.0 ** (g_db / 20.0)) - 1.0) > TOLERANCE:
            notes.append(f"K at {g_db:g} dB not reproduced: the figures give {k_g:g} DN/e-, K x 10^({g_db:g}/20) = "
                         f"{k * 10.0 ** (g_db / 20.0):.4g}: that setting amplifies by {20.0 * math.log10(k_g / k):.2f} "
                         f"dB, not {g_db:g}; the node needs the camera's true gain in dB (its metadata or a gain table)")
    k0 = predicted["system_gain_dn_per_e"]
    if abs(k0 / k - 1.0) > TOLERANCE and not offset:
        notes.append(f"K not reproduced ({k0:.4g} for {k:g} DN/e-): without a dark offset the model's dark level is 0, "
                     f"where it clips half of its dark noise ({ds.temporal_dark_noise_e:g} e-); give dark_offset_dn")
    sat = predicted["saturation_capacity_e"]
    if abs(sat / ds.saturation_capacity_e - 1.0) > TOLERANCE:
        notes.append(f"saturation not reproduced: the model saturates at the ADC range ({sat:.0f} e- by the EMVA "
                     f"variance maximum), the figures give {ds.saturation_capacity_e:.0f} e- "
                     f"({sat_dn / (adc - offset):.1%} of the ADC range{' above the dark offset' if offset else ''}): "
                     "a full well below the ADC range is not in the model")
    return result


def _dark_e(values: dict[str, Any], effects: dict[str, dict[str, float]], exposure_s: float,
            temperature_c: float) -> float:
    prof = CameraProfile(name="tmp", values=values, effects=effects)
    model = temporal_model(prof)
    return float(model.conditions(_meta(prof, 0.0, exposure_s, temperature_c)).dark_e)
