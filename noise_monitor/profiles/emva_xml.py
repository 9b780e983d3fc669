"""The EMVA 1288 reference implementation's results XML (``emva1288``: ``Emva1288(descriptor).xml()``) as a datasheet.

The XML holds the figures in electrons, DN and percent, one element per figure with its section, unit and value
(``<results><sensitivity><K><unit>$DN/e^-$</unit><value>0.288</value>...``); tag names are matched without regard
to case, as emva1288's own reader does. It does not hold what the measurement's conditions were: the sensor type,
the ADC's bits, the pixel size and the sensor temperature are asked for, and the exposure of the dark spatial set
(DSNU1288's) when the DSNU is to enter the profile.

Mapping: K, ``sigma_d``, ``u_e_sat``, ``u_I_mean`` (the dark current from the dark signal's mean) and ``QE`` as the
datasheet's figures; the non-uniformities are the pixel components, ``PRNU1288_pixel`` and ``DSNU1288_pixel`` (the
row and column parts removed: what an image patch shows as noise, as ``characterize`` takes its pixel-scale figures;
the totals where emva1288 gives no pixel component, a pixel DSNU of 0 where its variance came out negative). emva1288
takes ``sigma_d`` at zero exposure (the dark variance's fit over an exposure series of more than two exposures; with
fewer, at the first, whose dark shot noise is then counted twice: a short exposure's is negligible) and converts the
descriptor's exposure times from ns, the format's unit; with the DSNU's exposure t given, the datasheet's temporal
dark noise at t is sqrt(sigma_d^2 + u_I_mean t), the dark signal's shot noise added, so that one measurement exposure
serves both.
"""
from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from .datasheet import Datasheet, DatasheetError, datasheet_from_mapping
from .emva_images import EXPOSURE_UNITS

#: Largest results file read (emva1288's, histograms included, is ~50 kB).
MAX_BYTES = 10 * 2**20
#: The figures read: datasheet key -> (the XML's tag, its unit as emva1288 writes it, LaTeX marks removed).
FIGURES = {"system_gain_dn_per_e": ("K", "DN/e-"), "temporal_dark_noise_e": ("sigma_d", "e-"),
           "saturation_capacity_e": ("u_e_sat", "e-"), "dark_current_e_per_s": ("u_I_mean", "e-/s"),
           "dsnu_e": ("DSNU1288", "e-"), "dsnu_pixel_e": ("DSNU1288_pixel", "e-"), "prnu_pct": ("PRNU1288", "%"),
           "prnu_pixel_pct": ("PRNU1288_pixel", "%"), "quantum_efficiency_pct": ("QE", "%")}
REQUIRED = ("system_gain_dn_per_e", "temporal_dark_noise_e", "saturation_capacity_e")


def _unit(text: str | None) -> str:
    """``$e^-/s$`` -> ``e-/s``, ``\\%`` -> ``%``."""
    return re.sub(r"[$\\^{}\s]", "", text or "")


def read_results(path: str | Path) -> dict[str, float]:
    """The figures of :data:`FIGURES` found in the XML (NaN where emva1288 could not compute one)."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"results XML {p} does not exist")
    if p.stat().st_size > MAX_BYTES:
        raise DatasheetError(f"{p}: {p.stat().st_size} bytes is no EMVA 1288 results XML (at most {MAX_BYTES})")
    data = p.read_bytes()
    if b"<!DOCTYPE" in data or b"<!ENTITY" in data:
        raise DatasheetError(f"{p}: declares a DOCTYPE or entities, which emva1288's results never do: not read")
    try:
        root = ET.fromstring(data)
    except ET.ParseError as exc:
        raise DatasheetError(f"{p}: not well-formed XML ({exc})") from None
    elements = {e.tag.lower(): e for section in root for e in section if e.find("value") is not None}
    found: dict[str, float] = {}
    for key, (tag, unit) in FIGURES.items():
        e = elements.get(tag.lower())
        if e is None:
            continue
        got = _unit(e.findtext("unit"))
        if got != unit:
            raise DatasheetError(f"{p}: {tag} is in {got or 'no unit'}, expected {unit}: not emva1288's results format")
        text = (e.findtext("value") or "").strip()
        try:
            found[key] = float(text)
        except ValueError:
            raise DatasheetError(f"{p}: {tag} = {text!r} is not a number") from None
    missing = [FIGURES[k][0] for k in REQUIRED if not math.isfinite(found.get(k, math.nan))]
    if missing:
        raise DatasheetError(f"{p}: no {', '.join(missing)} (an EMVA 1288 results XML written by emva1288 has "
                             f"<results><sensitivity><K>... with a <value>)")
    return found


def datasheet_from_results(path: str | Path, sensor_type: str, bit_depth: int, pixel_size_um: float,
                           temperature_c: float, dsnu_exposure_s: float | None = None,
                           doubling_temperature_k: float | None = None, dark_offset_dn: float | None = None,
                           exposure_unit: str = "ns", name: str | None = None,
                           dark_current_e_per_s: float | None = None) -> tuple[Datasheet, list[str]]:
    """The results XML and the conditions it does not hold as a validated :class:`Datasheet`, with notes.

    ``exposure_unit``: the unit the measurement's descriptor gave its exposure times in (emva1288 takes ns: its dark
    current is rescaled from per ns to per ``exposure_unit``). ``dark_current_e_per_s``: instead of the XML's, where
    that is not usable (negative or missing: a dark signal the measurement did not resolve)."""
    if exposure_unit not in EXPOSURE_UNITS:
        raise DatasheetError(f"exposure unit {exposure_unit!r}: one of {', '.join(EXPOSURE_UNITS)}")
    if dsnu_exposure_s is not None and not 0.0 < dsnu_exposure_s <= 600.0:
        raise DatasheetError(f"the DSNU's exposure must be in (0, 600] s, got {dsnu_exposure_s!r}")
    f = read_results(path)
    notes = []
    rate = f.get("dark_current_e_per_s", math.nan) * 1e-9 / EXPOSURE_UNITS[exposure_unit]
    if dark_current_e_per_s is not None:
        notes.append(f"dark current {dark_current_e_per_s:g} e-/s as given, not the XML's u_I_mean ({rate:.4g} e-/s)")
        rate = dark_current_e_per_s
    elif not rate >= 0:
        raise DatasheetError(f"{path}: the dark current u_I_mean is {'negative' if rate < 0 else 'missing'} "
                             f"({rate:.3g} e-/s): the dark signal was not resolved; check the dark frames, or give the "
                             "dark current (--dark-current-e-per-s, 0 where it is immeasurably small)")
    sigma_d = f["temporal_dark_noise_e"]
    doc: dict[str, Any] = {
        "name": name or Path(path).stem, "sensor_type": sensor_type, "bit_depth": bit_depth,
        "pixel_size_um": pixel_size_um, "system_gain_dn_per_e": f["system_gain_dn_per_e"],
        "saturation_capacity_e": f["saturation_capacity_e"],
        "dark_current": {"e_per_s": rate, "temperature_c": temperature_c,
                         "doubling_temperature_k": doubling_temperature_k},
        "measurement": {"temperature_c": temperature_c},
        "dark_offset_dn": dark_offset_dn,
    }
    for key, pixel, label, unit in (("prnu_pct", "prnu_pixel_pct", "PRNU", "%"), ("dsnu_e", "dsnu_pixel_e", "DSNU", "e-")):
        total = f.get(key, math.nan)
        if math.isfinite(f.get(pixel, math.nan)):
            doc[key] = f[pixel]
            notes.append(f"{label} {f[pixel]:.4g} {unit}, the pixel component (total {total:.4g}): row, column and "
                         "smooth shading are no noise of an image patch")
        elif math.isfinite(total) and pixel in f:  # emva1288 writes NaN where the pixel variance came out negative
            doc[key] = 0.0
            notes.append(f"{label} 0 {unit}: no pixel component above the temporal noise (total {total:.4g}, in the "
                         "row and column parts)")
        elif math.isfinite(total):
            doc[key] = total
    if math.isfinite(f.get("quantum_efficiency_pct", math.nan)):
        doc["quantum_efficiency"] = {"percent": f["quantum_efficiency_pct"]}
    if dsnu_exposure_s:
        doc["temporal_dark_noise_e"] = math.sqrt(sigma_d**2 + rate * dsnu_exposure_s)
        doc["measurement"]["exposure_time_s"] = dsnu_exposure_s
        notes.append(f"sigma_d {sigma_d:.4g} e- at zero exposure taken to the DSNU's {dsnu_exposure_s:g} s with the "
                     f"dark signal's shot noise: {doc['temporal_dark_noise_e']:.4g} e-")
    else:
        doc["temporal_dark_noise_e"] = sigma_d
        doc["measurement"]["exposure_time_s"] = 0.0
    return datasheet_from_mapping(doc, source=str(path)), notes
