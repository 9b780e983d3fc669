"""Sensor physics of the paper's model (Konnik & Welsh): dark current, source follower, kTC, conditions."""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property, lru_cache

import numpy as np
from scipy.special import ndtr

from .metadata import CameraMetadata

K_B_EV = 8.617343e-5  # Boltzmann constant, eV/K
K_B_J = 1.3806504e-23  # Boltzmann constant, J/K
Q_E = 1.602176487e-19  # elementary charge, C
DARK_PREFACTOR = 2.55e15  # electrons / (s cm^2 nA/cm^2 K^1.5)
T_REF_K = 298.15  # reference temperature of temperature-law deviations (25 degC)

# Fixed metadata of the paper (Table "Fixed camera metadata"); f_c as in the authors' simulator.
CDS_SAMPLE_TIME_S = 1e-6
CDS_TIME_FACTOR = 0.5
SOURCE_FOLLOWER_GAIN = 1.0
FLICKER_CORNER_HZ = 1e6
RTS_CURRENT_A = 1e-8
SPECTRUM_STEP_HZ = 1e4


def band_gap_ev(temperature_k: float) -> float:
    """Silicon band gap (Varshni)."""
    return 1.1557 - 7.021e-4 * temperature_k**2 / (temperature_k + 1108.0)


def dark_electrons(meta: CameraMetadata, exposure_time_s: float, temperature_k: float) -> float:
    """Mean dark-current electrons per pixel for one exposure."""
    pixel_cm = meta.pixel_size_m * 100.0
    eg = band_gap_ev(temperature_k)
    return (
        DARK_PREFACTOR
        * exposure_time_s
        * pixel_cm**2
        * meta.dark_signal_fom_na_cm2
        * temperature_k**1.5
        * math.exp(-eg / (2.0 * K_B_EV * temperature_k))
    )


@lru_cache(maxsize=256)
def source_follower_sigma_e(
    sensor_type: str, sense_node_gain: float, pixel_clock_hz: float, white_noise: float
) -> float:
    """Source-follower noise in electrons: the noise spectrum through the CDS transfer function.

    Vectorised over the frequency grid 1, 1 + 10 kHz, ... <= f_clk and cached per camera.
    """
    tau = CDS_TIME_FACTOR * CDS_SAMPLE_TIME_S
    f = np.arange(1.0, pixel_clock_hz + 0.5, SPECTRUM_STEP_HZ)
    spectrum = white_noise**2 * (1.0 + FLICKER_CORNER_HZ / f)
    if sensor_type == "cmos":
        tau_rts = 0.1 * tau
        spectrum = spectrum + 2.0 * RTS_CURRENT_A**2 * tau_rts / (4.0 + (2.0 * np.pi * f * tau_rts) ** 2)
    transfer = (2.0 - 2.0 * np.cos(2.0 * np.pi * f * CDS_SAMPLE_TIME_S)) / (1.0 + (2.0 * np.pi * f * tau) ** 2)
    volts = math.sqrt(SPECTRUM_STEP_HZ * float(np.sum(spectrum * transfer)))
    return volts / (sense_node_gain * SOURCE_FOLLOWER_GAIN * (1.0 - math.exp(-CDS_SAMPLE_TIME_S / tau)))


def rounded_normal_variance(sigma: float) -> float:
    """Variance of round(N(0, sigma^2)) (the source-follower sample is rounded to whole electrons)."""
    if sigma > 20.0:
        return sigma**2 + 1.0 / 12.0
    if sigma <= 0.0:
        return 0.0
    k = np.arange(0, int(math.ceil(10 * sigma)) + 2, dtype=float)
    p = ndtr((k + 0.5) / sigma) - ndtr((k - 0.5) / sigma)
    p[0] = 0.0
    return float(2.0 * np.sum(k**2 * p))


def ktc_sigma_v(meta: CameraMetadata, temperature_k: float) -> float:
    """kTC (reset) noise voltage of the sense node."""
    capacitance = Q_E / meta.sense_node_gain_v_per_e
    return math.sqrt(K_B_J * temperature_k / capacitance)


#: positions (per axis) at which a position-dependent effect is averaged when no pixel position is given
AVERAGE_GRID_POINTS = 15


@dataclass(frozen=True)
class Pixels:
    """Where pixels sit on the sensor: normalised coordinates of their centres, 0 at the top (left)
    edge and 1 at the bottom (right) edge, as arrays broadcastable to the signal."""

    y: np.ndarray
    x: np.ndarray

    @classmethod
    def frame(cls, shape: tuple[int, ...]) -> Pixels:
        """Every pixel of a full frame (the last two axes of ``shape``): y (H, 1), x (1, W)."""
        h, w = shape[-2], shape[-1]
        return cls(((np.arange(h, dtype=np.float32) + 0.5) / h)[:, None],
                   ((np.arange(w, dtype=np.float32) + 0.5) / w)[None, :])

    @classmethod
    def average_grid(cls) -> Pixels:
        """An even grid over the sensor (column vectors of AVERAGE_GRID_POINTS**2 positions)."""
        g = (np.arange(AVERAGE_GRID_POINTS) + 0.5) / AVERAGE_GRID_POINTS
        yy, xx = np.meshgrid(g, g, indexing="ij")
        return cls(yy.reshape(-1, 1), xx.reshape(-1, 1))


@dataclass(frozen=True)
class Conditions:
    """The physical state that generates the noise: the stated metadata plus what modifiers change.

    Metadata-error effects (true gain/exposure/temperature differ from stated ones) and dark-current
    law deviations act by changing these fields; noise effects read them. ``where`` tells
    position-dependent (``spatial``) effects where the evaluated pixels are on the sensor.
    """

    meta: CameraMetadata
    gain: float
    exposure_time_s: float
    temperature_k: float
    dark_scale: float = 1.0
    dark_rate_per_k: float = 0.0
    #: pixel positions of the signal being evaluated (None: unknown; position-dependent effects are
    #: then averaged over the sensor)
    where: Pixels | None = field(default=None, compare=False, repr=False)

    @classmethod
    def from_meta(cls, meta: CameraMetadata) -> Conditions:
        return cls(meta=meta, gain=meta.gain, exposure_time_s=meta.exposure_time_s, temperature_k=meta.temperature_k)

    def replace(self, **changes) -> Conditions:
        return replace(self, **changes)

    @property
    def dn_per_e(self) -> float:
        """DN per electron after the camera gain (8-bit scale)."""
        return 255.0 * self.gain / self.meta.full_well_e

    @cached_property
    def dark_e(self) -> float:
        """Mean dark electrons (band-gap law, times any law deviation)."""
        base = dark_electrons(self.meta, self.exposure_time_s, self.temperature_k)
        return base * self.dark_scale * math.exp(self.dark_rate_per_k * (self.temperature_k - T_REF_K))

    @cached_property
    def source_follower_e(self) -> float:
        m = self.meta
        return source_follower_sigma_e(
            m.sensor_type, m.sense_node_gain_v_per_e, m.pixel_clock_hz, m.thermal_white_noise_v_per_sqrt_hz
        )

    @cached_property
    def ktc_variance_e2(self) -> float:
        """Variance in electrons^2 of r * (exp(N(0, sigma_V^2)) - 1) volts (CMOS only)."""
        if not self.meta.is_cmos or self.meta.sense_node_reset_factor == 0.0:
            return 0.0
        s2 = ktc_sigma_v(self.meta, self.temperature_k) ** 2
        var_v = self.meta.sense_node_reset_factor**2 * math.expm1(s2) * math.exp(s2)
        return var_v / self.meta.sense_node_gain_v_per_e**2
