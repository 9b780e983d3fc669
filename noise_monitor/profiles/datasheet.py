"""EMVA 1288 datasheet figures (YAML), validated: every figure named, in range and consistent.

Format (config/datasheets/example_cmos_emva.yaml is a worked example)::

    name: my-camera
    sensor_type: cmos              # or ccd
    bit_depth: 12                  # ADC bits of the figures' DN
    pixel_size_um: 3.45
    quantum_efficiency: {percent: 68.0, wavelength_nm: 525}   # optional (not identifiable, recorded)
    system_gain_dn_per_e: 0.39     # K at base gain (0 dB), native DN per electron
    gains:                         # optional: K at other gain settings
      - {gain_db: 12.0, system_gain_dn_per_e: 1.55}
    temporal_dark_noise_e: 2.4     # sigma_d (quantization noise excluded, as EMVA 1288 defines it)
    saturation_capacity_e: 10300
    dark_current: {e_per_s: 14.0, temperature_c: 25.0, doubling_temperature_k: 6.5}
    dsnu_e: 3.1                    # DSNU1288 (optional)
    prnu_pct: 0.6                  # PRNU1288 (optional)
    measurement: {exposure_time_s: 0.01, temperature_c: 25.0}  # conditions of sigma_d and DSNU
    dark_offset_dn: 48             # optional: mu_y.dark at zero exposure (the black level), native DN
    # optional model fields a datasheet rarely gives (not identifiable from the EMVA figures):
    pixel_clock_hz: 74.25e6
    sense_node_gain_v_per_e: 5.0e-6
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from noise_monitor.physics.metadata import SENSOR_TYPES, VALID_RANGES


class DatasheetError(ValueError):
    """A datasheet with missing, out-of-range or contradictory figures."""


#: Plausible ranges of the EMVA figures (outside: a typo or wrong units, rejected).
RANGES: dict[str, tuple[float, float]] = {
    "bit_depth": (8, 16),
    "pixel_size_um": (0.5, 100.0),
    "quantum_efficiency.percent": (0.1, 100.0),
    "quantum_efficiency.wavelength_nm": (200.0, 1200.0),
    "system_gain_dn_per_e": (1e-4, 100.0),
    "gains.gain_db": (0.0, 48.0),
    "gains.system_gain_dn_per_e": (1e-4, 1000.0),
    "temporal_dark_noise_e": (0.05, 1000.0),
    "saturation_capacity_e": (100.0, 1e7),
    "dark_current.e_per_s": (0.0, 1e7),
    "dark_current.temperature_c": (-80.0, 150.0),
    "dark_current.doubling_temperature_k": (1.0, 30.0),
    "dsnu_e": (0.0, 1e4),
    "prnu_pct": (0.0, 20.0),
    "measurement.exposure_time_s": (0.0, 600.0),
    "measurement.temperature_c": (-80.0, 150.0),
    "pixel_clock_hz": VALID_RANGES["pixel_clock_hz"],
    "sense_node_gain_v_per_e": VALID_RANGES["sense_node_gain_v_per_e"],
    "dark_offset_dn": (0.0, 65534.0),  # and below the ADC range's top (checked with the bit depth)
}
REQUIRED = ("sensor_type", "bit_depth", "pixel_size_um", "system_gain_dn_per_e", "temporal_dark_noise_e",
            "saturation_capacity_e", "dark_current")
_TOP = {"name", "sensor_type", "bit_depth", "pixel_size_um", "quantum_efficiency", "system_gain_dn_per_e", "gains",
        "temporal_dark_noise_e", "saturation_capacity_e", "dark_current", "dsnu_e", "prnu_pct", "measurement",
        "pixel_clock_hz", "sense_node_gain_v_per_e", "dark_offset_dn"}
_SUB = {"quantum_efficiency": {"percent", "wavelength_nm"},
        "dark_current": {"e_per_s", "temperature_c", "doubling_temperature_k"},
        "measurement": {"exposure_time_s", "temperature_c"}}


@dataclass(frozen=True)
class Datasheet:
    """The EMVA 1288 figures of one camera (native DN, electrons, SI time, degC)."""

    name: str
    sensor_type: str
    bit_depth: int
    pixel_size_um: float
    system_gain_dn_per_e: float
    temporal_dark_noise_e: float
    saturation_capacity_e: float
    dark_current_e_per_s: float
    dark_current_temperature_c: float
    doubling_temperature_k: float | None = None
    dsnu_e: float | None = None
    prnu_pct: float | None = None
    measurement_exposure_s: float | None = None
    measurement_temperature_c: float | None = None
    quantum_efficiency_pct: float | None = None
    wavelength_nm: float | None = None
    gains: tuple[tuple[float, float], ...] = ()  # (gain_db, K in native DN/e-)
    pixel_clock_hz: float | None = None
    sense_node_gain_v_per_e: float | None = None
    dark_offset_dn: float | None = None  # mu_y.dark at zero exposure: the black level (native DN)
    extras: Mapping[str, Any] = field(default_factory=dict)

    @property
    def adc_max_dn(self) -> int:
        return 2 ** self.bit_depth - 1

    def as_dict(self) -> dict[str, Any]:
        """The figures as a flat mapping (for JSON reports)."""
        out = {k: getattr(self, k) for k in self.__dataclass_fields__ if k not in ("extras", "gains")}
        out["gains"] = [{"gain_db": g, "system_gain_dn_per_e": k} for g, k in self.gains]
        return out


def _number(key: str, value: Any, source: str) -> float:
    if isinstance(value, bool) or value is None:
        raise DatasheetError(f"{source}: {key} must be a number, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise DatasheetError(f"{source}: {key} must be a number, got {value!r}") from None
    lo, hi = RANGES[key]
    if not (math.isfinite(v) and lo <= v <= hi):
        raise DatasheetError(f"{source}: {key} = {value!r} is outside the plausible range [{lo:g}, {hi:g}]")
    return v


def datasheet_from_mapping(doc: Mapping[str, Any], source: str = "datasheet") -> Datasheet:
    """Validate a datasheet mapping (names every missing or unknown key, every out-of-range value)."""
    unknown = sorted(set(doc) - _TOP)
    if unknown:
        raise DatasheetError(f"{source}: unknown key(s) {', '.join(unknown)}; allowed: {', '.join(sorted(_TOP))}")
    missing = [k for k in REQUIRED if doc.get(k) is None]
    if missing:
        raise DatasheetError(f"{source}: missing figure(s) {', '.join(missing)}")
    sub: dict[str, dict[str, Any]] = {}
    for key, allowed in _SUB.items():
        part = doc.get(key) or {}
        if not isinstance(part, Mapping):
            raise DatasheetError(f"{source}: {key} must be a mapping with keys {', '.join(sorted(allowed))}")
        bad = sorted(set(part) - allowed)
        if bad:
            raise DatasheetError(f"{source}: unknown key(s) {', '.join(f'{key}.{b}' for b in bad)}")
        sub[key] = {k: _number(f"{key}.{k}", v, source) for k, v in part.items() if v is not None}
    dc = sub["dark_current"]
    for k in ("e_per_s", "temperature_c"):
        if k not in dc:
            raise DatasheetError(f"{source}: missing figure dark_current.{k}")
    st = str(doc["sensor_type"]).strip().lower()
    if st not in SENSOR_TYPES:
        raise DatasheetError(f"{source}: sensor_type must be one of {', '.join(SENSOR_TYPES)}, got {doc['sensor_type']!r}")
    bits = _number("bit_depth", doc["bit_depth"], source)
    if not bits.is_integer():
        raise DatasheetError(f"{source}: bit_depth must be an integer, got {doc['bit_depth']!r}")
    gains = []
    for i, g in enumerate(doc.get("gains") or []):
        if not isinstance(g, Mapping) or set(g) != {"gain_db", "system_gain_dn_per_e"}:
            raise DatasheetError(f"{source}: gains[{i}] must be a mapping {{gain_db, system_gain_dn_per_e}}")
        gains.append((_number("gains.gain_db", g["gain_db"], source),
                      _number("gains.system_gain_dn_per_e", g["system_gain_dn_per_e"], source)))
    opt = {k: _number(k, doc[k], source)
           for k in ("dsnu_e", "prnu_pct", "pixel_clock_hz", "sense_node_gain_v_per_e", "dark_offset_dn")
           if doc.get(k) is not None}
    if opt.get("dark_offset_dn", 0.0) >= 2**bits - 1:
        raise DatasheetError(f"{source}: dark_offset_dn = {opt['dark_offset_dn']:g} is not below the top of the "
                             f"{int(bits)}-bit ADC range")
    qe, meas = sub["quantum_efficiency"], sub["measurement"]
    return Datasheet(
        name=str(doc.get("name") or Path(source).stem),
        sensor_type=st,
        bit_depth=int(bits),
        pixel_size_um=_number("pixel_size_um", doc["pixel_size_um"], source),
        system_gain_dn_per_e=_number("system_gain_dn_per_e", doc["system_gain_dn_per_e"], source),
        temporal_dark_noise_e=_number("temporal_dark_noise_e", doc["temporal_dark_noise_e"], source),
        saturation_capacity_e=_number("saturation_capacity_e", doc["saturation_capacity_e"], source),
        dark_current_e_per_s=dc["e_per_s"],
        dark_current_temperature_c=dc["temperature_c"],
        doubling_temperature_k=dc.get("doubling_temperature_k"),
        measurement_exposure_s=meas.get("exposure_time_s"),
        measurement_temperature_c=meas.get("temperature_c"),
        quantum_efficiency_pct=qe.get("percent"),
        wavelength_nm=qe.get("wavelength_nm"),
        gains=tuple(gains),
        dsnu_e=opt.get("dsnu_e"),
        prnu_pct=opt.get("prnu_pct"),
        pixel_clock_hz=opt.get("pixel_clock_hz"),
        sense_node_gain_v_per_e=opt.get("sense_node_gain_v_per_e"),
        dark_offset_dn=opt.get("dark_offset_dn"),
    )


def load_datasheet(path: str | Path) -> Datasheet:
    """Read and validate a datasheet YAML file."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"datasheet {p} does not exist")
    try:
        doc = yaml.safe_load(p.read_text())
    except yaml.YAMLError as exc:
        raise DatasheetError(f"{p}: not valid YAML ({str(exc).splitlines()[0]})") from None
    if not isinstance(doc, Mapping):
        raise DatasheetError(f"{p}: a datasheet must be a YAML mapping")
    return datasheet_from_mapping(doc, source=str(p))
