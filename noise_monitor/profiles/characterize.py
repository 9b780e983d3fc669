"""EMVA 1288 (release 4.0) characterization of a camera from a photon-transfer recording (a bag).

The recording: flat fields (a uniform light source, constant irradiance) over a series of exposure
times, a dark set (lens cap on) at the exposures, optionally dark sets at more sensor temperatures.
Consecutive frames with equal gain, exposure, temperature and level form a *set* (at least a pair).
Per (gain, temperature), at exposures with a flat field and a dark set the lower is dark, and the sets within
``dark_tolerance`` of the line those darks draw over the exposure are dark (a warm sensor's dark signal grows by
tens of DN over a long exposure); temperatures without flat fields hold dark sets only (:func:`_classify`). Everything is computed on the node's 8-bit scale and reported in electrons, with K
also in the camera's native DN:

- temporal variance of a set: the variance of the difference image of each pair / 2 (pairs averaged);
  spatial variance: the variance of the set's average image minus temporal variance / L;
- K: slope of (sigma_y^2 - sigma_y.dark^2) vs (mu_y - mu_y.dark) through the origin, up to 70 % of
  saturation (flats without clipped pixels); standard error from the fit residuals;
- saturation: the dark-subtracted mean of the set with the maximum temporal variance, divided by K
  (its resolution is the spacing of the exposure levels near saturation);
- temporal dark noise: sqrt(sigma_y.dark^2 - LSB^2/12) / K at the shortest exposure, read noise from
  the intercept of sigma_y.dark^2 vs exposure (not determined below 0.24 DN^2: under the ADC step);
- dark current: slope of mu_y.dark vs exposure / K per temperature; doubling temperature: ln 2 / slope
  of ln(dark current) vs temperature (two temperatures or more);
- DSNU: sqrt(spatial variance of the dark set) / K; PRNU: sqrt(s_y^2 - s_y.dark^2) / (mu_y - mu_y.dark)
  on the flat set nearest 50 % of saturation (the largest sets are used); both also at the pixel scale (the mean
  image less its 5x5 box mean: a light source's or lens's smooth shading off), which the profile takes;
- linearity error: deviation of mu_y - mu_y.dark from a straight line in exposure between 5 % and 95 %
  of saturation, in % of the line;
- dark sets with pixels at code 0 (a black level too low for the dark signal's spread) are left out, said in a note.

Quantum efficiency (and so anything in photons) needs a calibrated irradiance: determined from an EMVA 1288 image
set's photon counts (:mod:`.emva_images`), not from a bag.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.ndimage import uniform_filter

from noise_monitor.bag.reader import open_bag
from noise_monitor.monitor.period import skip_category

from .datasheet import Datasheet, datasheet_from_mapping
from .emva import fit_dark_law

#: Sets whose mean is within this fraction of the range above the lowest set (same gain, T) are dark.
DARK_TOLERANCE = 0.02
#: A new set starts where the mean jumps by more than this fraction of the range.
SET_SPLIT = 0.005
K_FIT_MAX = 0.70
#: A set with this share of its pixels at the ADC's ends, and at least CLIPPED_MIN_PIXELS of them, is clipped: a flat at
#: 255 leaves the K fit, a dark at 0 every dark figure (a pixel or two of a small image, a noise tail or a defect, do not).
CLIPPED_MAX = 1e-4
CLIPPED_MIN_PIXELS = 10
#: Below this dark variance (native DN^2) the dark noise is under the ADC step: not determined.
QUANTIZATION_LIMIT_DN2 = 0.24
LINEARITY_RANGE = (0.05, 0.95)
#: The pixel-scale non-uniformity: a set's mean image less its HPF_SIZE x HPF_SIZE box mean (the smooth shading of a
#: light source, lens or amplifier glow taken off), its variance divided by what the filter leaves of white noise.
HPF_SIZE = 5
HPF_WHITE = (1.0 - 1.0 / HPF_SIZE**2) ** 2 + (HPF_SIZE**2 - 1) / HPF_SIZE**4


class CharacterizeError(ValueError):
    """The recording cannot be characterized (the reason says what is missing)."""


@dataclass
class FrameSet:
    """Consecutive frames of equal conditions and level."""

    gain_db: float
    exposure_time_s: float
    temperature_c: float | None
    first_index: int
    images: list[np.ndarray] = field(default_factory=list)
    first_mean: float = 0.0
    size: int = 0
    kind: str = ""
    mean: float = 0.0
    temporal_var: float = 0.0
    spatial_var: float = 0.0
    spatial_var_hpf: float = 0.0  # its pixel-scale part (HPF_SIZE)
    clipped_pixels: int = 0  # at the ADC's top
    underflow_pixels: int = 0  # at code 0: the black level too low for the dark signal's spread
    pixels: int = 0
    photons: float | None = None  # per pixel during the exposure, where the irradiance was calibrated
    temporal: bool = True  # False: a set for the spatial noise only (an EMVA image set's), kept out of the PTC

    def add(self, image: np.ndarray) -> None:
        if not self.images:
            self.first_mean = float(image.mean())
        self.images.append(image)
        self.size = len(self.images)

    def compute(self) -> None:
        """Mean, temporal and spatial variance, clipped fraction; frees the pixels."""
        stack = np.stack(self.images).astype(np.float64, copy=False)
        self.images = []  # the stack holds the pixels now
        self.mean = float(stack.mean())
        pairs = [np.var(stack[i] - stack[i + 1]) / 2.0 for i in range(0, len(stack) - 1, 2)]
        self.temporal_var = float(np.mean(pairs))
        mean_image = stack.mean(axis=0)
        self.spatial_var = float(np.var(mean_image) - self.temporal_var / len(stack))
        self.spatial_var_hpf = _highpass_var(mean_image) - self.temporal_var / len(stack)
        self.clipped_pixels = int(np.count_nonzero(stack >= 255.0 - 1e-3))
        self.underflow_pixels = int(np.count_nonzero(stack <= 1e-3))
        self.pixels = stack.size


@dataclass
class Recording:
    sets: list[FrameSet]
    bit_depth: int
    shape: tuple[int, int]
    frames: int
    skipped: dict[str, int]
    static: dict[str, Any]
    unusable: str = ""  # the frames skipped as unusable, said (empty: none)
    depth_note: str = ""  # how the bit depth was inferred (empty: stated)
    kinds_given: bool = False  # each set's kind (dark / flat) stated by the recording (an EMVA image set)

    @property
    def lsb(self) -> float:
        """One native code on the 8-bit scale."""
        return 255.0 / (2**self.bit_depth - 1)


def _bit_depth(path: str | Path, override: int | None, topics: dict[str, str | None]) -> tuple[int, str]:
    """Bits per pixel and, when inferred, how: the override, the metadata's bit_depth, else the image container's
    width; in 16-bit words the fewest ADC bits that hold the recording's largest code (a photon-transfer recording
    reaches the ADC's top; drivers of 10-16 bit cameras mostly state no bit depth), said in a note."""
    if override:
        return override, ""
    with open_bag(path, **topics) as reader:
        for frame in reader.frames():
            bd = frame.raw_metadata.get("bit_depth")
            if bd is not None:
                return int(bd), ""
            break
        encoding = next((str(getattr(msg, "encoding", "")) for _, _, msg in
                         reader.messages([reader.image_topic] if reader.image_topic else [])), "")
        if "16" not in encoding:
            return 8, ""
        tops = [float(f.image_dn.max()) for f in reader.frames(bit_depth=16) if f.image_dn is not None]
    if not tops:
        return 16, ""
    top = int(round(max(tops) * 65535.0 / 255.0))
    bits = next(b for b in (8, 10, 12, 14, 16) if top <= 2**b - 1)
    if bits == 16:
        return 16, ""
    return bits, (f"bit depth {bits} inferred from the images' largest code, {top}, in 16-bit words (the metadata "
                  f"states none): --bit-depth states it")


def read_recording(path: str | Path, bit_depth: int | None = None, image_topic: str | None = None,
                   metadata_topic: str | None = None, temperature_topic: str | None = None) -> Recording:
    """Frames of a bag grouped into sets (see module doc)."""
    topics = {"image_topic": image_topic, "metadata_topic": metadata_topic, "temperature_topic": temperature_topic}
    depth, depth_note = _bit_depth(path, bit_depth, topics)
    sets: list[FrameSet] = []
    skipped: dict[str, int] = {}
    example: dict[str, str] = {}  # a full reason of each kind skipped
    shape = None
    static: dict[str, Any] = {}
    count = 0
    with open_bag(path, **topics) as reader:
        for frame in reader.frames(bit_depth=depth):
            count += 1
            if frame.image_dn is None:  # counted by kind (a pixel value per frame would make a kind each)
                reason = frame.skip_reason or "image unusable"
                kind = skip_category(reason)
                example.setdefault(kind, reason)
                skipped[kind] = skipped.get(kind, 0) + 1
                continue
            img = frame.image_dn
            if shape is None:
                shape = img.shape
            elif img.shape != shape:
                raise CharacterizeError(f"frame {frame.index} is {img.shape[1]}x{img.shape[0]} pixels, the first "
                                        f"{shape[1]}x{shape[0]}: a recording must keep its image size")
            meta = {**frame.raw_metadata, **(frame.metadata.as_dict() if frame.metadata else {})}
            if meta.get("exposure_time_s") is None:
                raise CharacterizeError(f"frame {frame.index} has no exposure_time_s in its metadata: the dark current "
                                        "and linearity need each frame's exposure")
            for k in ("sensor_type", "pixel_size_m"):
                if meta.get(k) is not None:
                    static.setdefault(k, meta[k])
            key = (float(meta.get("gain_db") or 0.0), float(meta["exposure_time_s"]),
                   None if meta.get("sensor_temperature_c") is None else float(meta["sensor_temperature_c"]))
            mean = float(img.mean())
            last = sets[-1] if sets else None
            if (last is None or (last.gain_db, last.exposure_time_s, last.temperature_c) != key
                    or abs(last.first_mean - mean) > SET_SPLIT * 255.0):
                last = FrameSet(*key, first_index=frame.index)
                sets.append(last)
            last.add(img)
    if shape is None:
        raise CharacterizeError(f"{path}: no usable image ({_skips(skipped, example, count)})")
    singles = sum(1 for s in sets if s.size < 2)
    if singles:
        skipped["single frame of its conditions (no pair for the difference image)"] = singles
    sets = [s for s in sets if s.size >= 2]
    if not sets:
        raise CharacterizeError(f"{path}: no two consecutive frames share gain, exposure and temperature: a "
                                "photon-transfer recording holds each set of conditions for at least two frames "
                                "(`simulate-bag --scenario ptc` shows one)")
    for s in sets:
        s.compute()
    return Recording(sets, depth, shape, count, skipped, static, _skips(skipped, example, count) if example else "",
                     depth_note=depth_note)


def _skips(skipped: dict[str, int], example: dict[str, str], count: int) -> str:
    """The frames skipped as unusable: how many of all, and the commonest reason in full."""
    if not example:
        return "every frame unusable"
    kind = max(example, key=lambda k: skipped[k])
    return f"{sum(skipped[k] for k in example)} of {count} frames skipped, e.g. {example[kind]}"


def _highpass_var(image: np.ndarray) -> float:
    """The variance of an image's pixel-scale part (see HPF_SIZE), edges left out; an image too small for the filter
    gives its whole variance."""
    if min(image.shape) <= 2 * HPF_SIZE:
        return float(np.var(image))
    edge = HPF_SIZE // 2
    high = image - uniform_filter(image, HPF_SIZE, mode="reflect")
    return float(np.var(high[edge:-edge, edge:-edge])) / HPF_WHITE


def _clipped(count: int, s: FrameSet) -> bool:
    """Whether ``count`` pixels at one end of the ADC make the set clipped (see CLIPPED_MAX)."""
    return count >= max(CLIPPED_MAX * s.pixels, CLIPPED_MIN_PIXELS)


def _fit_line(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares line (slope, intercept) and their standard errors."""
    if len(x) < 3:
        p = np.polyfit(x, y, 1)
        return p, np.full(2, np.nan)
    p, cov = np.polyfit(x, y, 1, cov="unscaled")
    resid = y - np.polyval(p, x)
    s2 = float(resid @ resid) / (len(x) - 2)
    return p, np.sqrt(np.diag(cov) * s2)


def _level(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A constant as a line of slope 0 (sets at one exposure): (0, mean) and (nan, its standard error)."""
    se = float(np.std(y, ddof=1) / math.sqrt(len(y))) if len(y) > 1 else float("nan")
    return np.array([0.0, float(np.mean(y))]), np.array([float("nan"), se])


def _doubling_fit(t: np.ndarray, log_rate: np.ndarray, rel_se: list[float | None]
                  ) -> tuple[np.ndarray, np.ndarray | None]:
    """ln(dark current) vs temperature: line and covariance (None with two points). Weighted by the rates' own
    errors when all are known, the covariance then widened by the scatter beyond them (Birge ratio: a law that is
    not exactly exponential, errors from fits of few exposures); unweighted with the scatter's covariance else."""
    if len(t) < 3:
        return np.polyfit(t, log_rate, 1), None
    if all(rel_se):
        w = 1.0 / np.array(rel_se, dtype=float)
        p, cov = np.polyfit(t, log_rate, 1, w=w, cov="unscaled")
        chi2 = float(np.sum((w * (log_rate - np.polyval(p, t))) ** 2))
        return p, cov * max(1.0, chi2 / (len(t) - 2))
    p, cov = np.polyfit(t, log_rate, 1, cov="unscaled")
    resid = log_rate - np.polyval(p, t)
    return p, cov * float(resid @ resid) / (len(t) - 2)


def _dithered(s: FrameSet, native2: float) -> bool:
    """Whether a set's temporal noise dithers the ADC's rounding (variance of at least ``QUANTIZATION_LIMIT_DN2``
    native DN^2, sigma ~ half a step): below it each pixel rounds alike from frame to frame, and the set's mean
    keeps an error of up to half a step that no pixel average removes (a fixed pattern rounded this way spreads over
    two levels whatever its size, so its measured spread is no sign of dithering)."""
    return s.temporal_var * native2 >= QUANTIZATION_LIMIT_DN2


def _value(v: float | None, se: float | None, unit: str) -> dict[str, Any]:
    return {"value": v, "stderr": None if se is None or not math.isfinite(se) else se, "unit": unit}


def _classify(groups: dict[tuple[float, float | None], list[FrameSet]], tolerance_dn: float) -> None:
    """Mark each set dark or flat. Where a (gain, temperature) has two sets or more at one exposure (a flat field
    and its dark set), the lowest there is dark and the darks' mean is a line in the exposure (the dark signal grows
    with it: by tens of DN over a long exposure of a warm sensor): a set is dark within ``tolerance_dn`` of that line.
    A (gain, temperature) without such pairs holds dark sets only when another one has them (the recording's
    further temperatures, lens cap on); otherwise its sets within ``tolerance_dn`` of its lowest are dark."""
    lines: dict[tuple[float, float | None], tuple[float, float]] = {}
    for key, members in groups.items():
        by_exposure: dict[float, list[FrameSet]] = {}
        for s in members:
            by_exposure.setdefault(s.exposure_time_s, []).append(s)
        lows = [min(sets, key=lambda s: s.mean) for sets in by_exposure.values() if len(sets) >= 2]
        if len(lows) >= 2:  # one per exposure
            slope, intercept = np.polyfit([s.exposure_time_s for s in lows], [s.mean for s in lows], 1)
            lines[key] = (float(slope), float(intercept))
        elif lows:
            lines[key] = (0.0, lows[0].mean)
    for key, members in groups.items():
        if key in lines:
            slope, intercept = lines[key]
            for s in members:
                s.kind = "dark" if s.mean <= intercept + slope * s.exposure_time_s + tolerance_dn else "flat"
        elif lines:
            for s in members:
                s.kind = "dark"
        else:
            floor = min(s.mean for s in members)
            for s in members:
                s.kind = "dark" if s.mean <= floor + tolerance_dn else "flat"


def characterize(rec: Recording, dark_tolerance: float = DARK_TOLERANCE) -> dict[str, Any]:
    """The EMVA figures of a recording (each with its standard error) and the points behind the plots; a recording
    that cannot be characterized names the frames it skipped as unusable too (a wrong --bit-depth, say)."""
    try:
        result = _characterize(rec, dark_tolerance)
    except CharacterizeError as exc:
        raise CharacterizeError(f"{exc} ({rec.unusable})" if rec.unusable else str(exc)) from None
    for note in (rec.unusable, rec.depth_note):
        if note:
            result["notes"].insert(0, note)
    return result


def _characterize(rec: Recording, dark_tolerance: float) -> dict[str, Any]:
    notes: list[str] = []
    groups: dict[tuple[float, float | None], list[FrameSet]] = {}
    for s in rec.sets:
        groups.setdefault((s.gain_db, s.temperature_c), []).append(s)
    if not rec.kinds_given:
        _classify(groups, dark_tolerance * 255.0)
    underflow = [s for s in rec.sets if s.kind == "dark" and _clipped(s.underflow_pixels, s)]
    for s in underflow:  # their mean and variance are the clipped signal's: every dark figure would be biased
        s.kind = "dark at code 0"
    if underflow:
        worst = max(underflow, key=lambda s: s.underflow_pixels / s.pixels)
        notes.append(f"{len(underflow)} dark set(s) left out: up to {worst.underflow_pixels / worst.pixels:.2%} of their pixels at "
                     f"code 0 ({worst.exposure_time_s:g} s"
                     f"{'' if worst.temperature_c is None else f', {worst.temperature_c:g} degC'}): the black level is "
                     "too low for the dark signal's spread there; raise it (e.g. BlackLevel) to characterize those "
                     "conditions")
    flats_by_group = {g: [s for s in m if s.kind == "flat"] for g, m in groups.items()}
    base = max(groups, key=lambda g: (len(flats_by_group[g]), -g[0]))
    gain0, temp0 = base
    if len({g for g, _ in groups}) > 1:
        notes.append(f"several gains recorded: the analysis uses {gain0:g} dB (the one with most flat fields)")
    flats = sorted((s for s in flats_by_group[base] if s.temporal), key=lambda s: s.exposure_time_s)
    spatial = [s for s in flats_by_group[base] if not s.temporal]  # for the PRNU only
    darks = sorted((s for s in groups[base] if s.kind == "dark"), key=lambda s: s.exposure_time_s)
    dark_t = np.array([s.exposure_time_s for s in darks])
    # an irradiance series at one exposure time (EMVA's other method): its dark set subtracts, no dark current
    one_exposure = len(np.unique(dark_t)) == 1 and all(
        math.isclose(s.exposure_time_s, dark_t[0], rel_tol=1e-9) for s in flats)
    if len(np.unique(dark_t)) < 2 and not one_exposure:
        raise CharacterizeError("no dark frames (lens cap on) at two or more exposure times"
                                f"{'' if temp0 is None else f' at {temp0:g} degC'} (nor flat fields all at the "
                                "exposure of the dark frames): dark subtraction and dark current cannot be determined")
    unclipped = [s for s in flats if not _clipped(s.clipped_pixels, s)]
    if len(unclipped) < 3:
        raise CharacterizeError(f"only {len(unclipped)} flat-field set(s) without saturated pixels (of {len(flats)}): "
                                "the photon transfer curve (K) cannot be determined")
    line = _level if one_exposure else _fit_line
    dark_mean_fit, dark_mean_se = line(dark_t, np.array([s.mean for s in darks]))
    dark_var_fit, dark_var_se = line(dark_t, np.array([s.temporal_var for s in darks]))
    if one_exposure:
        notes.append(f"one exposure time ({dark_t[0]:g} s; the irradiance varied): the dark current, the read noise "
                     "(dark noise at zero exposure) and the black level (dark offset at zero exposure) are not "
                     "determined; the temporal dark noise is that of this exposure")

    def dark_at(s: FrameSet) -> tuple[float, float, float, float]:
        """The dark set at a set's exposure: mean, temporal variance, spatial variance (whole, pixel-scale)."""
        same = [d for d in darks if math.isclose(d.exposure_time_s, s.exposure_time_s, rel_tol=1e-9)]
        if same:
            d = max(same, key=lambda d: d.size)
            return d.mean, d.temporal_var, d.spatial_var, d.spatial_var_hpf
        t = s.exposure_time_s
        return float(np.polyval(dark_mean_fit, t)), float(np.polyval(dark_var_fit, t)), float("nan"), float("nan")

    ref = np.array([dark_at(s)[:2] for s in flats])
    x = np.array([s.mean for s in flats]) - ref[:, 0]  # mu_y - mu_y.dark (8-bit DN)
    y = np.array([s.temporal_var for s in flats]) - ref[:, 1]
    t_flat = np.array([s.exposure_time_s for s in flats])
    # saturation: variance maximum (needs a drop after it)
    i = int(np.argmax(y))
    sat_dn = None
    sat_se_dn = 0.0
    if 0 < i < len(y) - 1:
        sat_dn = float(x[i])  # EMVA: the measured point of maximum variance (resolution: the level spacing)
        sat_se_dn = float(x[i + 1] - x[i - 1]) / 2.0 / math.sqrt(12.0)  # the maximum anywhere between its neighbours
    else:
        notes.append("saturation not determined: the variance has no maximum inside the exposure series "
                     "(record flat fields beyond saturation)")
    whole = np.array([not _clipped(s.clipped_pixels, s) for s in flats])  # flats without saturated pixels
    limit = K_FIT_MAX * (sat_dn if sat_dn else x[whole].max())
    sel = (x <= limit) & whole & (x > 0)
    if sel.sum() < 3:
        raise CharacterizeError(f"only {int(sel.sum())} flat-field set(s) in the linear range below 70 % of "
                                "saturation: K cannot be determined")
    k8 = float((x[sel] @ y[sel]) / (x[sel] @ x[sel]))
    resid = y[sel] - k8 * x[sel]
    k8_se = math.sqrt(float(resid @ resid) / max(int(sel.sum()) - 1, 1) / float(x[sel] @ x[sel]))
    rel_k = k8_se / k8
    adc = 2**rec.bit_depth - 1
    q = rec.lsb**2 / 12.0
    npix = rec.shape[0] * rec.shape[1]
    # dark noise at the shortest exposure, read noise from the intercept
    d0 = darks[0]  # sigma_d at the shortest exposure from the line through all dark variances (less noisy)
    dark_var0 = float(np.polyval(dark_var_fit, d0.exposure_time_s))
    sd2 = max(dark_var0 - q, 0.0)
    sd_value = math.sqrt(sd2) / k8
    sd: float | None = sd_value
    sd_se: float | None = sd_value * math.hypot(rel_k, 0.5 * math.hypot(dark_var_se[1], np.nan_to_num(dark_var_se[0]) * d0.exposure_time_s) / max(sd2, 1e-30))
    rn2 = dark_var_fit[1] - q
    read: float | None = math.sqrt(rn2) / k8 if rn2 > 0 and not one_exposure else None
    read_se: float | None = read * math.hypot(rel_k, 0.5 * dark_var_se[1] / rn2) if read else None
    native2 = ((2**rec.bit_depth - 1) / 255.0) ** 2
    if dark_var0 * native2 < QUANTIZATION_LIMIT_DN2:
        bound = math.sqrt(QUANTIZATION_LIMIT_DN2 - 1.0 / 12.0) / (k8 * adc / 255.0)
        notes.append(f"temporal dark noise not determined: sigma_y.dark^2 = {dark_var0 * native2:.3g} DN^2 is below the "
                     f"quantization limit {QUANTIZATION_LIMIT_DN2} DN^2 (dark noise below the ADC step: the LSB^2/12 "
                     "subtraction fails, and K is biased too); record with more bits or a higher gain. EMVA 1288 takes "
                     f"sigma_y.dark = 0.49 DN here, an upper bound: sigma_d <= {bound:.3g} e-")
        sd = sd_se = read = read_se = None
    # dark current per temperature and its doubling temperature
    currents: dict[str, dict[str, Any]] = {}
    series = []
    quantized: list[str] = []  # temperatures whose dark signal moved less than the ADC's steps resolve
    for (g, temp), members in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1] or 0.0)):
        if g != gain0:
            continue
        ds = [s for s in members if s.kind == "dark"]
        ts = np.array([s.exposure_time_s for s in ds])
        if len(np.unique(ts)) < 2:
            continue
        label = "unknown" if temp is None else f"{temp:g}"
        means = np.array([s.mean for s in ds])
        undithered = not all(_dithered(s, native2) for s in ds)
        if undithered and np.ptp(means) < 2.0 * rec.lsb:
            quantized.append(label)
            series.append({"temperature_c": temp, "exposure_s": ts.tolist(), "mean_dn": means.tolist(), "fit": None,
                           "rate_e_per_s": None})
            continue
        p, se = _fit_line(ts, means)
        if undithered:  # each mean is off by up to half an ADC step that no pixel average removes
            se[0] = math.hypot(se[0] if math.isfinite(se[0]) else 0.0,
                               rec.lsb / math.sqrt(12.0) / math.sqrt(float(np.sum((ts - ts.mean()) ** 2))))
        rate = p[0] / k8
        rate_se = abs(rate) * math.hypot(rel_k, se[0] / p[0]) if p[0] and math.isfinite(se[0]) else None
        currents[label] = _value(rate, rate_se, "e-/s")
        series.append({"temperature_c": temp, "exposure_s": ts.tolist(), "mean_dn": [s.mean for s in ds],
                       "fit": p.tolist(), "rate_e_per_s": rate})
    temps = [(s["temperature_c"], s["rate_e_per_s"], currents[f"{s['temperature_c']:g}"]["stderr"])
             for s in series if s["temperature_c"] is not None and (s["rate_e_per_s"] or 0.0) > 0]
    doubling = _value(None, None, "K")
    if len(temps) >= 2:
        tt = np.array([v[0] for v in temps])
        ly = np.log([v[1] for v in temps])
        p, cov = _doubling_fit(tt, ly, [v[2] / v[1] if v[2] else None for v in temps])
        td = math.log(2.0) / p[0] if p[0] > 0 else None
        td_se = td * math.sqrt(cov[0, 0]) / p[0] if (td and cov is not None) else None
        doubling = _value(td, td_se, "K")
    else:
        recorded = len({x["temperature_c"] for x in series if x["temperature_c"] is not None})
        notes.append("doubling temperature not determined: " + ("dark frames at one temperature only" if recorded < 2
                                                                  else "dark current determined at fewer than two "
                                                                       "temperatures"))
    if quantized:
        notes.append(f"dark current not determined at {', '.join(q + ' degC' for q in quantized)}: the dark signal "
                     "moves less than two ADC steps over the exposures and the dark noise does not dither the ADC "
                     "(below half a step); record longer or warmer darks, more bits or a higher gain")
    # DSNU: the largest dark set at the longest exposure; PRNU: the largest flat set nearest 50 % saturation
    dsnu_set = max(darks, key=lambda s: (s.size, s.exposure_time_s))

    def nonuniformity(s2: float, s: FrameSet) -> tuple[float, float]:
        """sqrt of a spatial variance and its relative standard error (the set's pixels and frames)."""
        return math.sqrt(max(s2, 0.0)), 0.5 * math.sqrt(2.0 / npix) * (s.spatial_var + s.temporal_var / s.size) / max(
            s2, 1e-30)

    dsnu_dn, dsnu_rel = nonuniformity(dsnu_set.spatial_var, dsnu_set)
    dsnu: float | None = dsnu_dn / k8
    dsnu_se: float | None = dsnu_dn / k8 * math.hypot(rel_k, dsnu_rel)
    dsnu_hpf_dn, dsnu_hpf_rel = nonuniformity(dsnu_set.spatial_var_hpf, dsnu_set)
    dsnu_hpf = _value(dsnu_hpf_dn / k8, dsnu_hpf_dn / k8 * math.hypot(rel_k, dsnu_hpf_rel), "e-")
    if not _dithered(dsnu_set, native2) and dsnu_set.spatial_var * native2 < 1.0:
        notes.append(f"DSNU not determined: its dark set's pattern spreads by {dsnu_set.spatial_var * native2:.3g} "
                     "DN^2 and its temporal noise is below one ADC step: the ADC rounds such a pattern to one or two "
                     "levels; record with more bits or a higher gain")
        dsnu = dsnu_se = None
        dsnu_hpf = _value(None, None, "e-")
    prnu = prnu_hpf = _value(None, None, "%")
    if sat_dn:
        signal = {id(s): s.mean - dark_at(s)[0] for s in flats + spatial}
        cands = [s for s in flats + spatial if 0.0 < signal[id(s)] <= 0.7 * sat_dn]
        best = min(cands, key=lambda s: (-s.size, abs(signal[id(s)] - 0.5 * sat_dn)))
        _, _, s2_dark, s2_dark_hpf = dark_at(best)
        if math.isfinite(s2_dark):
            def prnu_of(s2: float) -> dict[str, Any]:
                val, rel = nonuniformity(s2, best)
                return _value(100.0 * val / signal[id(best)], 100.0 * val / signal[id(best)] * rel, "%")

            prnu, prnu_hpf = prnu_of(best.spatial_var - s2_dark), prnu_of(best.spatial_var_hpf - s2_dark_hpf)
        else:
            notes.append("PRNU not determined: no dark set at the exposure of the 50 % flat field")
    # linearity: in the photons where the irradiance was calibrated (EMVA's own abscissa), else in the exposure
    # (constant irradiance)
    photons = np.array([np.nan if s.photons is None else s.photons for s in flats])
    calibrated = bool(np.isfinite(photons).all())
    lin = {"exposure_s": t_flat.tolist(), "signal_dn": x.tolist(), **({"photons": photons.tolist()} if calibrated else {})}
    abscissa = photons if calibrated else t_flat
    le = _value(None, None, "%")
    if sat_dn:
        m = (x >= LINEARITY_RANGE[0] * sat_dn) & (x <= LINEARITY_RANGE[1] * sat_dn)
        if m.sum() >= 3 and np.ptp(abscissa[m]) > 0:
            p = np.polyfit(abscissa[m], x[m], 1, w=1.0 / x[m])  # EMVA: the line minimising the relative deviations
            dev = 100.0 * (x[m] - np.polyval(p, abscissa[m])) / np.polyval(p, abscissa[m])
            j = int(np.argmax(np.abs(dev)))
            # the worst point's own error: its flat and dark means' temporal noise over the pixels and frames (the
            # dark set taken as long as its flat), relative to the line there (largest at the lowest signal)
            sets = [s for s, keep in zip(flats, m) if keep]
            se_dn = math.sqrt((sets[j].temporal_var + ref[m][j, 1]) / (sets[j].size * npix))
            le = _value(float(dev[j]), 100.0 * se_dn / float(np.polyval(p, abscissa[m][j])), "%")
            lin.update(fit=p.tolist(), range_mask=m.tolist(), deviation_pct=dev.tolist())
    # the sensitivity threshold from sigma_y.dark, at least the 0.49 DN EMVA 1288 takes below the quantization limit
    sigma_dark8 = math.sqrt(max(dark_var0, QUANTIZATION_LIMIT_DN2 / native2))
    photon_figures = _photon_figures(photons[sel], x[sel], k8, rel_k, adc, photons[i] if sat_dn else None,
                                     sigma_dark8) if calibrated else {
        "quantum_efficiency": _value(None, None, "%"), "responsivity_dn_per_p": _value(None, None, "DN/p"),
        "saturation_capacity_p": _value(None, None, "p"), "sensitivity_threshold_p": _value(None, None, "p"),
        "dynamic_range_db": _value(None, None, "dB")}
    if not calibrated:
        notes.append("quantum efficiency not determined: it needs a calibrated irradiance (photons per pixel)")
    saturation_e = _value(sat_dn / k8 if sat_dn else None,
                          math.hypot(sat_dn * rel_k, sat_se_dn) / k8 if sat_dn else None, "e-")
    if calibrated and sat_dn:  # EMVA: eta mu_p.sat, the photons of the variance maximum converted by the QE
        qe = photon_figures["quantum_efficiency"]
        sat_p = float(photons[i])
        saturation_e = _value(qe["value"] / 100.0 * sat_p, qe["stderr"] / 100.0 * sat_p, "e-")
    figures = {
        "system_gain_dn_per_e": _value(k8 * adc / 255.0, k8_se * adc / 255.0, f"DN/e- ({rec.bit_depth} bit)"),
        "system_gain_dn8_per_e": _value(k8, k8_se, "DN/e- (8-bit scale)"),
        "temporal_dark_noise_e": _value(sd, sd_se, "e-"),
        "read_noise_e": _value(read, read_se, "e-"),
        "saturation_capacity_e": saturation_e,
        "dark_current_e_per_s": currents,
        "doubling_temperature_k": doubling,
        "dsnu_e": _value(dsnu, dsnu_se, "e-"),
        "prnu_pct": prnu,
        "dsnu_hpf_e": dsnu_hpf,
        "prnu_hpf_pct": prnu_hpf,
        # the dark mean at zero exposure: the camera's black level (offset), which the node takes off every image
        "black_level_dn": _value(None if one_exposure else float(dark_mean_fit[1]) * adc / 255.0,
                                 None if one_exposure else float(dark_mean_se[1]) * adc / 255.0,
                                 f"DN ({rec.bit_depth} bit)"),
        "linearity_error_pct": le,
        **photon_figures,
    }
    return {
        "figures": figures,
        "conditions": {"gain_db": gain0, "temperature_c": temp0, "bit_depth": rec.bit_depth,
                       "width": rec.shape[1], "height": rec.shape[0], "frames": rec.frames,
                       "sets": len(rec.sets), "flat_sets": len(flats) + len(spatial), "dark_sets": len(darks),
                       "temporal_dark_noise_exposure_s": d0.exposure_time_s,
                       "dsnu_exposure_s": dsnu_set.exposure_time_s,
                       "dark_noise_at_dsnu_exposure_e": None if sd is None else math.sqrt(max(float(
                           np.polyval(dark_var_fit, dsnu_set.exposure_time_s)) - q, 0.0)) / k8,
                       "skipped": rec.skipped},
        "notes": notes,
        "points": {"ptc": {"signal_dn": x.tolist(), "variance_dn2": y.tolist(), "k_fit": sel.tolist(),
                           "unclipped": whole.tolist(),
                           "total_variance_dn2": [s.temporal_var for s in flats],
                           "saturation_dn": sat_dn},
                   "dark": series, "linearity": lin,
                   "dark_variance": {"exposure_s": dark_t.tolist(), "variance_dn2": [s.temporal_var for s in darks]}},
        "static": rec.static,
    }


def _photon_figures(photons: np.ndarray, signal: np.ndarray, k8: float, rel_k: float, adc: int,
                    sat_photons: float | None, sigma_dark8: float) -> dict[str, dict[str, Any]]:
    """The figures in photons (an EMVA image set's calibrated irradiance): responsivity R (slope of the dark-subtracted
    signal vs the photons through the origin over K's range), quantum efficiency R / K, saturation in photons (the
    photons of the variance maximum), absolute sensitivity threshold (sigma_y.dark / K + 1/2) / eta and the dynamic
    range between the two, as the EMVA's reference implementation computes them."""
    r8 = float(photons @ signal / (photons @ photons))
    resid = signal - r8 * photons
    r8_se = math.sqrt(float(resid @ resid) / max(len(photons) - 1, 1) / float(photons @ photons))
    eta = r8 / k8
    eta_se = eta * math.hypot(rel_k, r8_se / r8)
    threshold = (sigma_dark8 / k8 + 0.5) / eta
    return {
        "quantum_efficiency": _value(100.0 * eta, 100.0 * eta_se, "%"),
        "responsivity_dn_per_p": _value(r8 * adc / 255.0, r8_se * adc / 255.0, "DN/p (native)"),
        "saturation_capacity_p": _value(sat_photons, None, "p"),
        "sensitivity_threshold_p": _value(threshold, threshold * eta_se / eta, "p"),
        "dynamic_range_db": _value(20.0 * math.log10(sat_photons / threshold) if sat_photons else None, None, "dB"),
    }


def datasheet_from_result(result: dict[str, Any], name: str, sensor_type: str | None = None,
                          pixel_size_um: float | None = None, bounds: bool = False) -> tuple[Datasheet | None, list[str]]:
    """The measured figures as a datasheet for :func:`profile_from_datasheet`, or None and the reasons. ``bounds``:
    what the recording cannot determine taken as EMVA 1288 takes it, said in the notes: a temporal dark noise below
    the ADC step at the standard's 0.49 DN (an upper bound), an unmeasured dark current as 0."""
    f, cond, static = result["figures"], result["conditions"], result["static"]
    notes = []
    temp = cond["temperature_c"]
    if bounds and cond["dark_noise_at_dsnu_exposure_e"] is None and f["system_gain_dn_per_e"]["value"]:
        bound = math.sqrt(QUANTIZATION_LIMIT_DN2 - 1.0 / 12.0) / f["system_gain_dn_per_e"]["value"]
        cond = {**cond, "dark_noise_at_dsnu_exposure_e": bound}
        notes.append(f"profile: temporal dark noise {bound:.3g} e-, EMVA 1288's 0.49 DN bound for a dark noise below the "
                     "ADC step (--dark-bounds): the model's dark noise is an upper bound")
    key = "unknown" if temp is None else f"{temp:g}"
    if bounds and temp is not None and key not in f["dark_current_e_per_s"]:
        f = {**f, "dark_current_e_per_s": {**f["dark_current_e_per_s"], key: _value(0.0, None, "e-/s")}}
        notes.append(f"profile: dark current 0 at {temp:g} degC, not measured (--dark-bounds): the dark signal moved "
                     "less than the recording resolves, or darks at one exposure only")
    sensor_type = sensor_type or static.get("sensor_type")
    if pixel_size_um is None and static.get("pixel_size_m") is not None:
        pixel_size_um = float(static["pixel_size_m"]) * 1e6
    missing = []
    if sensor_type is None:
        missing.append("the sensor type (not in the metadata: give --sensor-type)")
    if pixel_size_um is None:
        missing.append("the pixel size (not in the metadata: give --pixel-size-um)")
    if cond["dark_noise_at_dsnu_exposure_e"] is None:
        missing.append("the temporal dark noise (quantization-limited)")
    if f["saturation_capacity_e"]["value"] is None:
        missing.append("the saturation capacity")
    if temp is None:
        missing.append("the sensor temperature of the dark frames")
    rate = f["dark_current_e_per_s"].get(key)
    if rate is None:
        missing.append("the dark current")
    if missing or pixel_size_um is None:
        hint = "" if bounds or not {"the temporal dark noise (quantization-limited)", "the dark current"} & set(missing) else (
            " (--dark-bounds takes EMVA 1288's bounds for the dark noise and current)")
        return None, ["profile not written: the recording does not determine " + "; ".join(missing) + hint]
    mu = rate["value"]
    if mu < 0:
        if rate["stderr"] is None or mu < -2.0 * rate["stderr"]:
            return None, [f"profile not written: the dark current is negative ({mu:.3g} e-/s): check the dark frames"]
        notes.append(f"dark current {mu:.3g} +- {rate['stderr']:.2g} e-/s is zero within its uncertainty: 0 used")
        mu = 0.0
    td = f["doubling_temperature_k"]["value"]
    measured = [(float(t), v["value"], (v["stderr"] or 0.0) / v["value"]) for t, v in f["dark_current_e_per_s"].items()
                if t != "unknown" and v["value"] and v["value"] > 0]
    measured.sort(key=lambda m: (m[0] != temp, m[0]))  # the analysed temperature first
    if len(measured) >= 2 and measured[0][0] == temp:
        mu, td = fit_dark_law(pixel_size_um * 1e-6, *map(list, zip(*measured)))
        notes.append(f"profile: the model's dark-current law fitted to {len(measured)} temperatures "
                     f"({mu:.4g} e-/s at {temp:g} degC, doubling {td:.3g} K there)")
    # the model's DSNU and PRNU are the pixels' (pixel-scale): the smooth shading of a light source, lens or amplifier
    # glow in the total is no noise of an image patch
    dsnu, prnu = (f[hpf]["value"] if f[hpf]["value"] is not None else f[whole]["value"]
                  for hpf, whole in (("dsnu_hpf_e", "dsnu_e"), ("prnu_hpf_pct", "prnu_pct")))
    said = [f"{label} {f[hpf]['value']:.3g} {unit} (total {f[whole]['value']:.3g})"
            for label, hpf, whole, unit in (("PRNU", "prnu_hpf_pct", "prnu_pct", "%"), ("DSNU", "dsnu_hpf_e", "dsnu_e", "e-"))
            if f[hpf]["value"] is not None and f[whole]["value"] is not None]
    if said:
        notes.append(f"profile: the pixel-scale non-uniformities (5x5 high-pass), {' and '.join(said)}: a light "
                     "source's, lens's or amplifier's smooth shading in the totals is no noise of an image patch")
    doc = {
        "name": name, "sensor_type": sensor_type, "bit_depth": cond["bit_depth"], "pixel_size_um": pixel_size_um,
        "system_gain_dn_per_e": f["system_gain_dn_per_e"]["value"],
        "temporal_dark_noise_e": cond["dark_noise_at_dsnu_exposure_e"],
        "saturation_capacity_e": f["saturation_capacity_e"]["value"],
        "dark_current": {"e_per_s": mu, "temperature_c": temp,
                         "doubling_temperature_k": td},
        "dsnu_e": dsnu, "prnu_pct": prnu,
        "measurement": {"exposure_time_s": cond["dsnu_exposure_s"], "temperature_c": temp},
        "dark_offset_dn": max(f["black_level_dn"]["value"] or 0.0, 0.0),
    }
    return datasheet_from_mapping(doc, source=name), notes
