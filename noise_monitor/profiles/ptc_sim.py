"""The ``ptc`` scenario of ``simulate-bag``: an EMVA 1288 photon-transfer recording of a simulated camera.

The camera looks at a uniform light source of constant irradiance while the exposure time steps
through a series (signal proportional to exposure, up to beyond saturation; the series is denser
around saturation), with a lens-cap (dark) set at every exposure, then dark sets at three more
sensor temperatures. Each set is two frames (a pair for the difference image), eight for the spatial
(DSNU/PRNU) sets. Frames are the model's noise drawn effect by effect (the profile's effects
included) on the flat signal plus a black level, clipped to the ADC range and quantised to the
profile's bit depth (mono16 above 8 bit), as a real camera delivers them.

The sidecar ``<bag>.truth.json`` holds the EMVA figures the simulated camera has by construction.
"""
from __future__ import annotations

import json
import math
from collections.abc import Iterable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.special import roots_hermitenorm

from noise_monitor.physics import CameraProfile, NoiseModel, load_profile
from noise_monitor.physics.clipping import clipped_normal_moments

from .emva import to_native

#: Conditions of the recording.
GAIN_DB = 0.0
BASE_TEMPERATURE_C = 30.0
EXTRA_TEMPERATURES_C = (40.0, 50.0, 60.0)
MAX_EXPOSURE_S = 0.2
#: Highest flat signal relative to the range above the black level (beyond saturation: the variance
#: maximum is seen); DENSE_FRACTION of the levels lie between DENSE_FROM and TOP_LEVEL (saturation region).
TOP_LEVEL = 1.06
DENSE_FROM = 0.88
DENSE_FRACTION = 0.4
SPATIAL_FRAMES = 8
MIN_FRAMES = 60
#: Black level: at least this fraction of the range and 6 dark-noise sigmas (no clipping at 0).
BLACK_LEVEL_FRACTION = 1.0 / 64.0


@dataclass(frozen=True)
class PlannedFrame:
    kind: str  # "flat" or "dark"
    exposure_time_s: float
    sensor_temperature_c: float
    signal_dn: float  # clean flat signal on the 8-bit scale (0 for dark)


def plan(frames: int, signal_range_dn: float = 255.0) -> list[PlannedFrame]:
    """The recording for a budget of ``frames`` images (the levels fill what the fixed sets leave).

    Levels are fractions of ``signal_range_dn`` (the ADC range above the black level), as an operator
    sets the light so that the series spans the camera's range.
    """
    if frames < MIN_FRAMES:
        raise ValueError(f"the ptc scenario needs at least {MIN_FRAMES} frames, got {frames}")
    dark_exposures = (0.25 * MAX_EXPOSURE_S, 0.5 * MAX_EXPOSURE_S, MAX_EXPOSURE_S)
    fixed = 2 * len(dark_exposures) * len(EXTRA_TEMPERATURES_C) + 2 * (SPATIAL_FRAMES - 2)
    levels = (frames - fixed) // 4
    n_dense = int(round(levels * DENSE_FRACTION))
    rel = np.concatenate([np.linspace(0.05, DENSE_FROM, levels - n_dense, endpoint=False),
                          np.linspace(DENSE_FROM, TOP_LEVEL, n_dense)])
    t_of = MAX_EXPOSURE_S / TOP_LEVEL  # signal proportional to exposure: TOP_LEVEL at MAX_EXPOSURE_S
    spatial = int(np.argmin(np.abs(rel - 0.5)))
    out: list[PlannedFrame] = []
    for i, r in enumerate(rel):
        t = float(r * t_of)
        n = SPATIAL_FRAMES if i == spatial else 2
        out += [PlannedFrame("flat", t, BASE_TEMPERATURE_C, float(r * signal_range_dn))] * n
        out += [PlannedFrame("dark", t, BASE_TEMPERATURE_C, 0.0)] * n
    for temp in EXTRA_TEMPERATURES_C:
        for t in dark_exposures:
            out += [PlannedFrame("dark", t, temp, 0.0)] * 2
    return out


def _profile_model(prof: CameraProfile, effects: Iterable[str]) -> NoiseModel:
    specs = [*(f"{k}:" + ",".join(f"{p}={v}" for p, v in vals.items()) if vals else k
               for k, vals in prof.effects.items()), *effects]
    return NoiseModel(extra=specs)


def black_level_dn(model: NoiseModel, prof: CameraProfile, bits: int) -> float:
    """Black level on the 8-bit scale, a whole native code: the profile's when it states one, else one at which no
    dark frame clips at 0."""
    lsb = 255.0 / (2**bits - 1)
    if prof.black_level_dn:
        return round(prof.black_level_dn / lsb) * lsb
    worst = prof.metadata(gain_db=GAIN_DB, exposure_time_s=MAX_EXPOSURE_S,
                          sensor_temperature_c=max(EXTRA_TEMPERATURES_C))
    cond = model.conditions(worst)
    var = sum(float(e.variance_dn2(0.0, cond)) for e in model.noise_effects if e.distribution != "quantization")
    level = max(BLACK_LEVEL_FRACTION * 255.0, 6.0 * math.sqrt(var) + cond.dark_e * cond.dn_per_e)
    return math.ceil(level / lsb) * lsb


def simulate_ptc(out: str | Path, profile: str | Path | CameraProfile, effects: Iterable[str] = (),
                 frames: int = 120, width: int = 160, height: int = 128, seed: int = 0, storage: str = "mcap",
                 fps: float = 5.0, namespace: str = "/camera", hardware_id: str | None = None,
                 start_ns: int | None = None) -> Path:
    """Write the photon-transfer recording (see module doc) and its truth sidecar; returns the bag path.
    ``hardware_id``: the camera's id in the metadata (default the profile's name); ``start_ns``: the first stamp."""
    from noise_monitor.bag.messages import camera_info_msg, image_msg, metadata_msg
    from noise_monitor.bag.simulate import START_NS, TOPICS, truth_path
    from noise_monitor.bag.writer import BagWriter

    out = Path(out)
    prof = profile if isinstance(profile, CameraProfile) else load_profile(profile)
    bits = int(prof.bit_depth or 8)
    effects = list(effects)
    model = _profile_model(prof, effects)
    offset = black_level_dn(model, prof, bits)
    steps = plan(frames, 255.0 - offset)
    rng = np.random.default_rng(seed)
    adc = 2**bits - 1
    ns = namespace.rstrip("/")
    topic = {k: f"{ns}/{v}" for k, v in TOPICS.items()}
    adders = [e for e in model.noise_effects if e.distribution != "quantization"]  # the ADC quantises below
    with BagWriter(out, storage=storage) as writer:
        for i, step in enumerate(steps):
            stamp = (START_NS if start_ns is None else start_ns) + int(round(i * 1e9 / fps))
            meta = prof.metadata(gain_db=GAIN_DB, exposure_time_s=step.exposure_time_s,
                                 sensor_temperature_c=step.sensor_temperature_c)
            cond = model.conditions(meta)
            clean = np.full((height, width), step.signal_dn, np.float32)
            noisy = clean + np.float32(offset + cond.dark_e * cond.dn_per_e)  # black level + mean dark signal
            for e in adders:
                noisy += np.broadcast_to(np.asarray(e.sample(clean, cond, rng), dtype=np.float32), clean.shape)
            codes = np.rint(np.clip(noisy, 0.0, 255.0) * np.float32(adc / 255.0))
            img = codes.astype(np.uint8 if bits <= 8 else np.uint16)
            writer.write(topic["camera_info"], camera_info_msg(height, width, stamp), stamp)
            writer.write(topic["metadata"], metadata_msg(meta, stamp, hardware_id or prof.name), stamp)
            writer.write(topic["image"], image_msg(img, stamp), stamp)
    truth = {
        "bag": out.name, "profile": prof.name, "scenario": "ptc", "effects": [str(e) for e in model.effects],
        "seed": seed, "fps": fps, "width": width, "height": height, "bit_depth": bits, "storage": storage,
        "topics": topic, "black_level_dn8": offset, "gain_db": GAIN_DB,
        "emva": emva_truth(model, prof, bits, offset, steps), "episodes": [],
        "frames": [asdict(s) for s in steps],
    }
    truth_path(out).write_text(json.dumps(truth, indent=1))
    return out


def emva_truth(model: NoiseModel, prof: CameraProfile, bits: int, offset: float,
               steps: list[PlannedFrame]) -> dict[str, Any]:
    """The EMVA 1288 figures of the simulated camera, from its model (what characterize should find)."""
    meta = prof.metadata(gain_db=GAIN_DB, exposure_time_s=min(s.exposure_time_s for s in steps),
                         sensor_temperature_c=BASE_TEMPERATURE_C)
    cond = model.conditions(meta)
    k8 = cond.dn_per_e
    lsb = 255.0 / (2**bits - 1)
    temporal = [e for e in model.noise_effects if e.temporal and e.distribution in ("poisson", "gaussian")]
    read_var = sum(float(e.variance_dn2(0.0, cond)) for e in temporal if e.name not in ("pn", "dcsn"))  # DN^2
    dark_var = read_var + float(cond.dark_e) * k8**2
    fx = {e.name: e for e in model.effects}

    def dark_rate(temp_c: float) -> float:
        m = prof.metadata(gain_db=GAIN_DB, exposure_time_s=1.0, sensor_temperature_c=temp_c)
        return float(model.conditions(m).dark_e)

    temps = sorted({s.sensor_temperature_c for s in steps if s.kind == "dark"})
    rates = [dark_rate(t) for t in temps]
    slope = np.polyfit(temps, np.log(rates), 1)[0] if len(temps) > 1 and min(rates) > 0 else None
    darks = [s.exposure_time_s for s in steps if s.kind == "dark" and s.sensor_temperature_c == BASE_TEMPERATURE_C]
    t_long = max(darks, key=lambda t: (darks.count(t), t))  # the largest dark set (as characterize picks it)
    cond_long = model.conditions(meta.replace(exposure_time_s=t_long))
    dsnu = math.sqrt(float(fx["dsnu"].variance_dn2(0.0, cond_long))) / k8 if "dsnu" in fx else 0.0
    prnu = float(fx["prnu"].sigma_pct) if "prnu" in fx else 0.0
    flat = next(s for s in steps if s.kind == "flat" and s.sensor_temperature_c == BASE_TEMPERATURE_C)
    dark_per_signal = dark_rate(BASE_TEMPERATURE_C) * k8 / (flat.signal_dn / flat.exposure_time_s)
    return {
        "system_gain_dn8_per_e": k8,
        "system_gain_dn_per_e": to_native(k8, bits),
        "read_noise_e": math.sqrt(read_var) / k8,
        "temporal_dark_noise_e": math.sqrt(dark_var) / k8,
        "temporal_dark_noise_exposure_s": meta.exposure_time_s,
        "saturation_capacity_e": _saturation_truth(k8, read_var, prnu, offset, lsb, dark_per_signal) / k8,
        "dark_current_e_per_s": dict(zip((f"{t:g}" for t in temps), rates)),
        "doubling_temperature_k": math.log(2.0) / slope if slope else None,
        "dsnu_e": dsnu, "dsnu_exposure_s": t_long,
        "prnu_pct": prnu,
        "linearity_error_pct": 0.0,
    }


def _saturation_truth(k8: float, read_var: float, prnu_pct: float, offset: float, lsb: float,
                      dark_per_signal: float) -> float:
    """Dark-subtracted mean (8-bit DN) at the maximum of the pixel-averaged temporal variance.

    Per pixel the output is clip(offset + d + v (1 + p z) + noise, 0, 255) with z ~ N(0, 1) the PRNU pattern,
    d = ``dark_per_signal`` x v the mean dark signal of the same exposure (the flat fields' signal and the dark
    signal both grow with it) and Gaussian temporal noise of variance k8 (signal + d) + read + LSB^2/12 (Poisson is
    Gaussian there); the EMVA saturation is the mean there less the dark set's, offset + d.
    """
    z, wz = roots_hermitenorm(41)
    wz = wz / wz.sum()
    v = np.linspace(0.3 * 255.0, 1.1 * 255.0, 8001)[:, None]
    dark = dark_per_signal * v
    sig = v * (1.0 + prnu_pct / 100.0 * z[None, :])
    s = np.sqrt(k8 * (sig + dark) + read_var + lsb**2 / 12.0)
    m1, m2, _ = clipped_normal_moments(offset + dark + sig, s, 0.0, 255.0)
    var = ((m2 - m1**2) * wz).sum(axis=1)
    mean = (m1 * wz).sum(axis=1)
    i = int(np.argmax(var))
    return float(mean[i] - offset - dark[i, 0])
