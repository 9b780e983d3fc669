"""Built-in effects: the paper's PN, DCSN, RN and common effects of real cameras (EMVA 1288 terms)."""
from __future__ import annotations

import numpy as np

from ..sampling import standard_normal
from ..sensor import Conditions, ktc_sigma_v, rounded_normal_variance
from .base import Distribution, Effect, Param

#: Seed of a fixed pattern (not fittable): gives cameras distinct patterns.
SEED_PARAM = Param("seed", "1", 0, (0, 2**31 - 1), fittable=False, integer=True, description="pattern seed")


class PhotonShotNoise(Effect):
    name = "pn"
    distribution = Distribution.POISSON
    description = "Photon shot noise: Poisson statistics of the photo-electrons (the paper's PN)."
    signature = "variance grows linearly with the signal and with the gain"

    def electrons(self, signal_dn, cond: Conditions):
        s = np.asarray(signal_dn)
        return np.maximum(s, 0) * s.dtype.type(1.0 / cond.dn_per_e) if s.dtype.kind == "f" else np.maximum(s, 0) / cond.dn_per_e


class DarkCurrentShotNoise(Effect):
    name = "dcsn"
    distribution = Distribution.POISSON
    description = "Dark-current shot noise: Poisson statistics of thermal electrons, mean subtracted (DCSN)."
    signature = "signal-independent variance growing with exposure time and steeply with temperature"

    def electrons(self, signal_dn, cond: Conditions):
        return np.broadcast_to(cond.dark_e, np.shape(signal_dn))


class ReadoutNoise(Effect):
    name = "rn"
    distribution = Distribution.GAUSSIAN
    description = "Readout noise: source follower (white, flicker, RTS through CDS) and CMOS kTC reset noise."
    signature = "signal-independent variance proportional to the square of the gain"

    def sigma_dn(self, signal_dn, cond: Conditions):
        var_e = rounded_normal_variance(cond.source_follower_e) + cond.ktc_variance_e2
        return np.broadcast_to(cond.dn_per_e * np.sqrt(var_e), np.shape(signal_dn))

    @classmethod
    def mergeable(cls) -> bool:
        return True  # rounding and the log-normal kTC only change moments beyond the variance

    def sample(self, signal_dn, cond: Conditions, rng):
        shape = np.shape(signal_dn)
        sf = np.rint(np.float32(cond.source_follower_e) * standard_normal(rng, shape))
        if cond.ktc_variance_e2 > 0.0:
            m = cond.meta
            sv = np.float32(ktc_sigma_v(m, cond.temperature_k))
            volts = np.float32(m.sense_node_reset_factor) * np.expm1(sv * standard_normal(rng, shape))
            sf = sf + volts / np.float32(m.sense_node_gain_v_per_e)
        return (np.float32(cond.dn_per_e) * sf).astype(np.float32)


class PRNU(Effect):
    name = "prnu"
    temporal = False
    params = (
        Param("sigma_pct", "%", 1.0, (0.0, 20.0), description="pixel gain non-uniformity, std in % of the signal"),
        SEED_PARAM,
    )
    description = "Photo-response non-uniformity: each pixel has its own gain."
    signature = (
        "residual variance grows with the square of the signal and is absent from frame differences: "
        "pixel gain non-uniformity, PRNU = {sigma_pct:.2f} %"
    )

    def sigma_dn(self, signal_dn, cond: Conditions):
        return self.sigma_pct / 100.0 * np.maximum(np.asarray(signal_dn, dtype=float), 0.0)


class DSNU(Effect):
    name = "dsnu"
    temporal = False
    params = (
        Param("fraction", "1", 0.3, (0.0, 10.0), description="std of the pixels' dark signal / mean dark signal"),
        SEED_PARAM,
    )
    description = "Dark-signal non-uniformity: pixels differ in dark current (fixed pattern, grows with t and T)."
    signature = (
        "signal-independent residual variance that grows with exposure and temperature like the dark "
        "current and is absent from frame differences: dark-signal non-uniformity, DSNU = {fraction:.3g} x dark signal"
    )

    def sigma_dn(self, signal_dn, cond: Conditions):
        return np.broadcast_to(self.fraction * cond.dark_e * cond.dn_per_e, np.shape(signal_dn))


class _LineOffsets(Effect):
    temporal = False
    axis = 0
    params = (
        Param("sigma_dn", "DN", 0.5, (0.0, 20.0), description="std of the per-line offsets"),
        SEED_PARAM,
    )

    def sigma_dn(self, signal_dn, cond: Conditions):
        return np.broadcast_to(self.values["sigma_dn"], np.shape(signal_dn))

    def sample(self, signal_dn, cond: Conditions, rng):
        shape = np.shape(signal_dn)
        if len(shape) < 2:
            return super().sample(signal_dn, cond, rng)
        n = shape[-2] if self.axis == 0 else shape[-1]
        line = self.pattern((n,), "lines")
        line = line[:, None] if self.axis == 0 else line[None, :]
        return np.broadcast_to(np.float32(self.values["sigma_dn"]) * line, shape).astype(np.float32)


class RowOffsets(_LineOffsets):
    name = "row_offsets"
    axis = 0
    structure = "row"
    description = "Row offsets: each image row carries its own offset (fixed pattern)."
    signature = (
        "constant residual variance concentrated in the row means, absent from frame differences: "
        "row offsets, std {sigma_dn:.2f} DN"
    )


class ColumnOffsets(_LineOffsets):
    name = "column_offsets"
    axis = 1
    structure = "column"
    description = "Column offsets: each image column carries its own offset (column amplifiers, fixed pattern)."
    signature = (
        "constant residual variance concentrated in the column means, absent from frame differences: "
        "column offsets, std {sigma_dn:.2f} DN"
    )


class Quantization(Effect):
    name = "quantization"
    distribution = Distribution.QUANTIZATION
    params = (Param("bits", "bit", 8, (1, 16), integer=True, description="ADC bit depth"),)
    description = "Quantization of the output to the ADC's bit depth (LSB^2/12 on the 8-bit scale)."
    signature = (
        "constant residual variance LSB^2/12 with pixel values on a coarse grid: "
        "quantization to {bits:.0f} bit"
    )

    def lsb_dn(self, cond: Conditions) -> float:
        return 255.0 / (2 ** int(self.bits) - 1)


class HotPixels(Effect):
    name = "hot_pixels"
    distribution = Distribution.MIXTURE
    temporal = False
    params = (
        Param("fraction", "1", 1e-3, (0.0, 0.2), description="fraction of hot pixels"),
        Param("dark_multiplier", "1", 1000.0, (0.0, 1e7), description="hot pixels' dark current / mean dark current"),
        SEED_PARAM,
    )
    description = "Hot pixels: a few pixels with a dark current many times the mean (heavy tail, grows with t and T)."
    signature = (
        "a heavy positive tail of isolated bright pixels that repeat in every frame and grow with exposure "
        "and temperature: hot pixels, {fraction_pct:.3g} % of pixels at {dark_multiplier:.5g} x the dark current"
    )

    def mixture(self, signal_dn, cond: Conditions):
        return self.fraction, np.broadcast_to(self.dark_multiplier * cond.dark_e * cond.dn_per_e, np.shape(signal_dn))


class ExtraReadNoise(Effect):
    name = "extra_read_noise"
    params = (Param("sigma_e", "e-", 10.0, (0.0, 1e4), description="extra temporal read noise in electrons"),)
    description = "Extra read noise, constant in electrons (an amplifier fault or a noisier ADC)."
    signature = (
        "signal-independent residual variance present in frame differences and proportional to the square "
        "of the gain: extra read noise {sigma_e:.1f} e-"
    )

    def sigma_dn(self, signal_dn, cond: Conditions):
        return np.broadcast_to(self.sigma_e * cond.dn_per_e, np.shape(signal_dn))


class DarkCurrentLaw(Effect):
    name = "dark_current_law"
    distribution = Distribution.MODIFIER
    params = (
        Param("scale", "1", 1.0, (0.0, 1e4), description="dark current / band-gap law at 25 degC"),
        # from -0.06/K: a thermal dark current always rises with T, and the band-gap law's own rate is ~0.06-0.08/K at
        # 20-60 degC (doubling temperatures up to ~45 K stay reachable); below, a fit could make the dark current fall
        # with T and pass an episode of image noise off as dark current (a 30-frame field bag: scale 1769, -0.28/K)
        Param("rate_per_k", "1/K", 0.0, (-0.06, 0.5), description="extra exponential rate of the dark current with T"),
    )
    description = "Dark current deviating from the band-gap law (a different level or doubling temperature)."
    signature = (
        "residual variance that follows the dark current (exposure time, temperature) but not the band-gap "
        "law's size: dark current x {scale:.2f} at 25 degC, extra rate {rate_per_k:.3f}/K"
    )

    def modify(self, cond: Conditions) -> Conditions:
        return cond.replace(dark_scale=cond.dark_scale * self.scale, dark_rate_per_k=cond.dark_rate_per_k + self.rate_per_k)


class GainError(Effect):
    name = "gain_error"
    distribution = Distribution.MODIFIER
    params = (Param("factor", "1", 1.0, (0.05, 20.0), description="true gain / stated gain"),)
    description = "The camera's gain differs from the gain its metadata states."
    signature = (
        "the whole noise level function off by a gain-shaped factor (shot noise x sqrt(f), "
        "dark and read noise x f): true gain = {factor:.2f} x stated"
    )

    def modify(self, cond: Conditions) -> Conditions:
        return cond.replace(gain=cond.gain * self.factor)


class ExposureError(Effect):
    name = "exposure_error"
    distribution = Distribution.MODIFIER
    params = (Param("factor", "1", 1.0, (0.01, 100.0), description="true exposure / stated exposure"),)
    description = "The exposure time differs from the one the metadata states (affects the dark current)."
    signature = "dark-current noise off by a constant factor: true exposure = {factor:.2f} x stated"

    def modify(self, cond: Conditions) -> Conditions:
        return cond.replace(exposure_time_s=cond.exposure_time_s * self.factor)


class TemperatureError(Effect):
    name = "temperature_error"
    distribution = Distribution.MODIFIER
    params = (Param("offset_c", "degC", 0.0, (-60.0, 60.0), description="true - stated sensor temperature"),)
    description = "The sensor temperature differs from the one the metadata states."
    signature = (
        "dark-current noise off by a factor that grows steeply with the offset: "
        "true temperature = stated {offset_c:+.1f} degC"
    )

    def modify(self, cond: Conditions) -> Conditions:
        return cond.replace(temperature_k=cond.temperature_k + self.offset_c)


class BlackLevel(Effect):
    name = "black_level"
    distribution = Distribution.RESPONSE
    params = (Param("offset_dn", "DN", 16.0, (0.0, 64.0), description="the camera's black level (pedestal), 8-bit DN"),)
    description = ("A black level (pedestal) the profile does not state: output levels sit this far above the signal, "
                   "which the model otherwise reads as signal with shot noise that is not there.")
    signature = (
        "residual variance independent of the intensity and proportional to the gain, below the model: an unstated "
        "black level of {offset_dn:.1f} DN (state it as the profile's black_level_dn)"
    )

    def linear(self, signal_dn, cond: Conditions):
        return np.maximum(np.asarray(signal_dn, dtype=float) - self.offset_dn, 0.0)

    def slope(self, signal_dn, cond: Conditions):
        return np.ones(np.shape(signal_dn))


BUILTIN_EFFECTS: tuple[type[Effect], ...] = (
    PhotonShotNoise,
    DarkCurrentShotNoise,
    ReadoutNoise,
    PRNU,
    DSNU,
    RowOffsets,
    ColumnOffsets,
    Quantization,
    HotPixels,
    ExtraReadNoise,
    DarkCurrentLaw,
    GainError,
    ExposureError,
    TemperatureError,
    BlackLevel,
)
