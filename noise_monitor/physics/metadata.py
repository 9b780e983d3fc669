"""Camera metadata (SI units), validation, normalisation, profiles and random samplers."""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .. import safe_yaml
from ..text import clip

DYNAMIC_FIELDS = ("gain_db", "exposure_time_s", "sensor_temperature_c")
STATIC_FIELDS = (
    "full_well_e",
    "pixel_size_m",
    "dark_signal_fom_na_cm2",
    "pixel_clock_hz",
    "sense_node_gain_v_per_e",
    "sense_node_reset_factor",
    "thermal_white_noise_v_per_sqrt_hz",
    "sensor_type",
)
NUMERIC_FIELDS = DYNAMIC_FIELDS + STATIC_FIELDS[:-1]
SENSOR_TYPES = ("ccd", "cmos")

#: The paper's metadata ranges (Table "Camera metadata"); used for normalisation and sampling.
PAPER_RANGES: dict[str, tuple[float, float]] = {
    "gain_db": (0.0, 20.0 * math.log10(16.0)),
    "exposure_time_s": (0.001, 0.2),
    "sensor_temperature_c": (0.0, 80.0),
    "dark_signal_fom_na_cm2": (0.0, 1.0),
    "full_well_e": (2_000.0, 100_000.0),
    "pixel_clock_hz": (8e6, 150e6),
    "sense_node_gain_v_per_e": (1e-6, 5e-6),
    "sense_node_reset_factor": (0.0, 1.0),
    "pixel_size_m": (0.9e-6, 10e-6),
    "thermal_white_noise_v_per_sqrt_hz": (1e-9, 60e-9),
}

#: Physically meaningful limits: values outside are rejected (the model is not defined there).
VALID_RANGES: dict[str, tuple[float, float]] = {
    "gain_db": (0.0, 48.0),
    "exposure_time_s": (1e-7, 600.0),
    "sensor_temperature_c": (-80.0, 150.0),
    "dark_signal_fom_na_cm2": (0.0, 100.0),
    "full_well_e": (100.0, 1e7),
    "pixel_clock_hz": (1e5, 1e10),
    "sense_node_gain_v_per_e": (1e-8, 1e-3),
    "sense_node_reset_factor": (0.0, 1.0),
    "pixel_size_m": (1e-7, 1e-4),
    "thermal_white_noise_v_per_sqrt_hz": (1e-11, 1e-6),
}

UNITS = {
    "gain_db": "dB",
    "exposure_time_s": "s",
    "sensor_temperature_c": "degC",
    "dark_signal_fom_na_cm2": "nA/cm^2",
    "full_well_e": "e-",
    "pixel_clock_hz": "Hz",
    "sense_node_gain_v_per_e": "V/e-",
    "sense_node_reset_factor": "1",
    "pixel_size_m": "m",
    "thermal_white_noise_v_per_sqrt_hz": "V/sqrt(Hz)",
}

#: Longest camera profile name (it is echoed in statuses and reports).
MAX_NAME_CHARS = 200
#: a profile's black level stays below the 8-bit range's top
BLACK_LEVEL_MAX_DN = 255.0

#: Order of the normalised metadata vector fed to the networks (sensor_type: CCD = 1, CMOS = 0).
NORMALIZED_ORDER = NUMERIC_FIELDS + ("sensor_type",)


class MetadataError(ValueError):
    """Invalid, missing or out-of-range camera metadata."""


def db_to_factor(gain_db: float | np.ndarray) -> float | np.ndarray:
    """Amplitude gain factor from decibels (dB = 20 log10 g)."""
    return np.power(10.0, np.asarray(gain_db, dtype=float) / 20.0) if isinstance(gain_db, np.ndarray) else 10.0 ** (gain_db / 20.0)


def factor_to_db(gain: float | np.ndarray) -> float | np.ndarray:
    """Decibels from an amplitude gain factor."""
    return 20.0 * np.log10(gain) if isinstance(gain, np.ndarray) else 20.0 * math.log10(gain)


def celsius_to_kelvin(t_c: float | np.ndarray) -> float | np.ndarray:
    return t_c + 273.15


def kelvin_to_celsius(t_k: float | np.ndarray) -> float | np.ndarray:
    return t_k - 273.15


@dataclass(frozen=True)
class CameraMetadata:
    """All metadata the noise model needs, in SI units (dynamic per frame, static per camera)."""

    gain_db: float
    exposure_time_s: float
    sensor_temperature_c: float
    full_well_e: float
    pixel_size_m: float
    dark_signal_fom_na_cm2: float
    pixel_clock_hz: float
    sense_node_gain_v_per_e: float
    sense_node_reset_factor: float
    thermal_white_noise_v_per_sqrt_hz: float
    sensor_type: str
    bit_depth: int | None = None
    extras: Mapping[str, Any] = field(default_factory=dict, compare=False, hash=False)

    def __post_init__(self) -> None:
        for name in NUMERIC_FIELDS:
            value = getattr(self, name)
            if isinstance(value, str):
                try:
                    value = float(value.strip())
                except ValueError:
                    raise MetadataError(f"{name} must be a number in {UNITS[name]}, got {clip(repr(value), 80)}") from None
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
                raise MetadataError(f"{name} must be a number in {UNITS[name]}, got {clip(repr(value), 80)}")
            value = float(value)
            object.__setattr__(self, name, value)
            if not math.isfinite(value):
                raise MetadataError(f"{name} is not finite ({value}); expected {UNITS[name]}")
            lo, hi = VALID_RANGES[name]
            if not lo <= value <= hi:
                raise MetadataError(
                    f"{name} = {value:g} {UNITS[name]} is outside the allowed range [{lo:g}, {hi:g}] {UNITS[name]}"
                )
        st = str(self.sensor_type).strip().lower()
        if st not in SENSOR_TYPES:
            raise MetadataError(f"sensor_type must be one of {SENSOR_TYPES}, got {clip(repr(self.sensor_type), 80)}")
        object.__setattr__(self, "sensor_type", st)
        if self.bit_depth is not None:
            bd = self.bit_depth
            if isinstance(bd, str):
                try:
                    bd = float(bd.strip())
                except ValueError:
                    raise MetadataError(f"bit_depth must be an integer in [1, 16], got {clip(repr(bd), 80)}") from None
            if (isinstance(bd, bool) or not isinstance(bd, (int, float, np.integer, np.floating))
                    or not float(bd).is_integer() or not 1 <= int(bd) <= 16):
                raise MetadataError(f"bit_depth must be an integer in [1, 16], got {clip(repr(bd), 80)}")
            object.__setattr__(self, "bit_depth", int(bd))

    # --- derived quantities -------------------------------------------------------------
    @property
    def gain(self) -> float:
        """Gain as an amplitude factor."""
        return 10.0 ** (self.gain_db / 20.0)

    @property
    def temperature_k(self) -> float:
        return self.sensor_temperature_c + 273.15

    @property
    def is_cmos(self) -> bool:
        return self.sensor_type == "cmos"

    @property
    def dn_per_electron(self) -> float:
        """DN per electron before the camera gain (8-bit scale: 255 DN = full well)."""
        return 255.0 / self.full_well_e

    # --- conversions --------------------------------------------------------------------
    def replace(self, **changes: Any) -> CameraMetadata:
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    def as_dict(self) -> dict[str, Any]:
        out = {name: getattr(self, name) for name in NUMERIC_FIELDS + ("sensor_type",)}
        if self.bit_depth is not None:
            out["bit_depth"] = self.bit_depth
        return out

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> CameraMetadata:
        """Build from a mapping of field names; names every missing or unknown field in the error."""
        known = set(NUMERIC_FIELDS) | {"sensor_type", "bit_depth"}
        unknown = sorted(set(values) - known)
        if unknown:
            raise MetadataError(f"unknown metadata field(s): {', '.join(unknown)}")
        missing = [n for n in NUMERIC_FIELDS + ("sensor_type",) if n not in values or values[n] is None]
        if missing:
            raise MetadataError(f"missing metadata field(s): {', '.join(missing)}")
        kwargs = {k: values[k] for k in known if k in values and values[k] is not None}
        return cls(**kwargs)

    def normalized(self) -> np.ndarray:
        """Metadata mapped to [0, 1] with the paper's ranges (gain as factor, temperature in K).

        Order: ``NORMALIZED_ORDER``. Values outside the paper's ranges map outside [0, 1] (not clipped),
        see :meth:`outside_paper_ranges`.
        """
        out = np.empty(len(NORMALIZED_ORDER), dtype=np.float32)
        for i, name in enumerate(NUMERIC_FIELDS):
            lo, hi = PAPER_RANGES[name]
            value = getattr(self, name)
            if name == "gain_db":
                value, lo, hi = self.gain, 1.0, 16.0
            out[i] = (value - lo) / (hi - lo)
        out[-1] = 1.0 if self.sensor_type == "ccd" else 0.0
        return out

    def outside_paper_ranges(self) -> list[str]:
        """Fields whose value lies outside the paper's (training) ranges."""
        eps = 1e-9
        return [
            n
            for n in NUMERIC_FIELDS
            if not PAPER_RANGES[n][0] - eps * abs(PAPER_RANGES[n][1]) <= getattr(self, n) <= PAPER_RANGES[n][1] * (1 + eps)
        ]


# --- profiles ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class CameraProfile:
    """A camera's datasheet metadata (static fields, optional dynamic defaults) and its effect set."""

    name: str
    values: Mapping[str, Any]
    effects: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    #: the camera's gain range in dB, for drivers that report a relative gain (Basler: 0..1)
    gain_range_db: tuple[float, float] | None = None
    #: the range of such a driver's relative gain number (default 0..1), mapped linearly onto gain_range_db
    driver_gain_range: tuple[float, float] | None = None
    #: the camera's black level (pedestal) on the 8-bit DN scale: what it outputs without light or dark signal,
    #: taken off every image before the model reads it (a 10-bit sensor's 64 codes: 64 x 255 / 1023 = 15.95)
    black_level_dn: float = 0.0
    #: 8-bit DN per unit of a driver's reported black level (Basler CurrentParams.black_level: BlackLevelRaw on ace
    #: GigE, 1/16 at Mono8 on most models; BlackLevel in the pixel format's DN on USB / ace 2); None: not converted
    driver_black_level_dn: float | None = None

    def metadata(self, **dynamic: Any) -> CameraMetadata:
        """CameraMetadata from the profile, with dynamic (or any) fields overridden by ``dynamic``."""
        merged = {**self.values, **{k: v for k, v in dynamic.items() if v is not None}}
        return CameraMetadata.from_mapping(merged)

    @property
    def bit_depth(self) -> int | None:
        return self.values.get("bit_depth")

    def to_yaml(self) -> str:
        doc: dict[str, Any] = {"name": self.name, **dict(self.values)}
        if self.effects:
            doc["effects"] = {k: dict(v) for k, v in self.effects.items()}
        for key in ("gain_range_db", "driver_gain_range"):
            if getattr(self, key) is not None:
                doc[key] = list(getattr(self, key))
        if self.black_level_dn:
            doc["black_level_dn"] = self.black_level_dn
        if self.driver_black_level_dn is not None:
            doc["driver_black_level_dn"] = self.driver_black_level_dn
        return yaml.safe_dump(doc, sort_keys=False)


def load_profile(path: str | Path) -> CameraProfile:
    """Load a camera profile YAML (bundled name like 'icx285' or a path)."""
    from ..paths import camera_profile_path

    p = camera_profile_path(path)
    try:
        doc = safe_yaml.load(p)
    except safe_yaml.YamlError as exc:
        raise MetadataError(str(exc)) from None
    if not isinstance(doc, dict):
        raise MetadataError(f"{p}: a camera profile must be a YAML mapping")
    return profile_from_mapping(doc, source=str(p))


def profile_from_mapping(doc: Mapping[str, Any], source: str = "profile") -> CameraProfile:
    """Validate a profile mapping: known field names only, values in range (partial is fine)."""
    doc = dict(doc)
    name = doc.pop("name", Path(source).stem)
    if not isinstance(name, str) or not 0 < len(name) <= MAX_NAME_CHARS:
        raise MetadataError(f"{source}: 'name' must be a text of 1 to {MAX_NAME_CHARS} characters, got "
                            f"{clip(repr(name), 80)}")
    effects_spec = doc.pop("effects", None) or {}
    ranges = {key: _range(source, key, doc.pop(key)) for key in ("gain_range_db", "driver_gain_range") if key in doc}
    black = _black_level(source, doc.pop("black_level_dn", 0.0))
    per_unit = _positive(source, "driver_black_level_dn", doc.pop("driver_black_level_dn", None))
    known = set(NUMERIC_FIELDS) | {"sensor_type", "bit_depth"}
    unknown = sorted(set(doc) - known)
    if unknown:
        raise MetadataError(f"{source}: unknown key(s) {', '.join(unknown)}; allowed: name, effects, gain_range_db, "
                            f"driver_gain_range, black_level_dn, driver_black_level_dn, {', '.join(sorted(known))}")
    # validate present values by building a metadata object with placeholder values for missing fields
    placeholder: dict[str, Any] = {n: PAPER_RANGES[n][0] if n != "pixel_clock_hz" else 1e7 for n in NUMERIC_FIELDS}
    placeholder["sensor_type"] = "ccd"
    try:
        checked = CameraMetadata.from_mapping({**placeholder, **doc})
    except MetadataError as exc:
        raise MetadataError(f"{source}: {exc}") from exc
    doc = {k: getattr(checked, k) for k in doc}  # typed values (YAML may give '90.0e6' as a string)
    return CameraProfile(name=name, values=doc, effects=_effects_spec(effects_spec, source), black_level_dn=black,
                         driver_black_level_dn=per_unit, **ranges)


def _black_level(source: str, value: Any) -> float:
    """A black level in DN on the 8-bit scale: a number in [0, BLACK_LEVEL_MAX_DN)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value < BLACK_LEVEL_MAX_DN:
        raise MetadataError(f"{source}: black_level_dn must be a number of DN (8-bit scale) in [0, "
                            f"{BLACK_LEVEL_MAX_DN:g}), got {clip(repr(value), 80)}")
    return float(value)


def _positive(source: str, key: str, value: Any) -> float | None:
    """An optional finite number > 0."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
        raise MetadataError(f"{source}: {key} must be a number > 0, got {clip(repr(value), 80)}")
    return float(value)


def _range(source: str, key: str, value: Any) -> tuple[float, float]:
    """A [low, high] pair of finite numbers with low < high."""
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise MetadataError(f"{source}: {key} must be a list [low, high] of two numbers, got {value!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise MetadataError(f"{source}: {key} must be [low, high] with finite low < high, got {value!r}")
    return lo, hi


def _effects_spec(spec: Any, source: str) -> dict[str, dict[str, float]]:
    """A profile's ``effects``: a list of names or a mapping name -> {parameter: number}."""
    usage = f"{source}: 'effects' must be a list of names or a mapping name -> {{parameter: number}}"
    if isinstance(spec, (list, tuple)):
        spec = {e: None for e in spec}
    if not isinstance(spec, dict):
        raise MetadataError(usage)
    effects: dict[str, dict[str, float]] = {}
    for name, params in spec.items():
        if not isinstance(name, str):
            raise MetadataError(f"{usage}; got the name {clip(repr(name), 80)}")
        params = params or {}
        if not isinstance(params, dict):
            raise MetadataError(f"{usage}; effect {clip(name, 80)!r} has {clip(repr(params), 80)}")
        for key, value in params.items():
            if (not isinstance(key, str) or isinstance(value, bool) or not isinstance(value, (int, float))
                    or not math.isfinite(value)):
                raise MetadataError(f"{source}: effect {clip(name, 80)!r}: parameter {clip(repr(key), 80)} must "
                                    f"be a finite number, got {clip(repr(value), 80)}")
        effects[name] = {k: float(v) for k, v in params.items()}
    return effects


# --- samplers -----------------------------------------------------------------------------------
def sample_static(rng: np.random.Generator, sensor_type: str | None = None) -> dict[str, Any]:
    """Random sensor (static fields) uniformly over the paper's ranges."""
    out: dict[str, Any] = {}
    for name in STATIC_FIELDS[:-1]:
        lo, hi = PAPER_RANGES[name]
        out[name] = float(rng.uniform(lo, hi))
    out["sensor_type"] = sensor_type or str(rng.choice(SENSOR_TYPES))
    return out


def sample_dynamic(rng: np.random.Generator) -> dict[str, float]:
    """Random operating conditions: gain uniform as a factor 1..16 (as in the paper), t and T uniform."""
    return {
        "gain_db": float(factor_to_db(rng.uniform(1.0, 16.0))),
        "exposure_time_s": float(rng.uniform(*PAPER_RANGES["exposure_time_s"])),
        "sensor_temperature_c": float(rng.uniform(*PAPER_RANGES["sensor_temperature_c"])),
    }


def sample_metadata(rng: np.random.Generator, sensor_type: str | None = None) -> CameraMetadata:
    """A random sensor under random conditions over the paper's ranges."""
    return CameraMetadata.from_mapping({**sample_static(rng, sensor_type), **sample_dynamic(rng)})
