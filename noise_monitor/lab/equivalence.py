"""Candidates the data cannot tell apart: what they share and which observation would separate them.

:func:`.diagnose.diagnose` groups candidates whose fitted models predict the same observables (see
``EQUIVALENT_CHI2`` there); this module says, in plain words, what a group's members agree on and what
would separate them, worked out from the fitted models rather than from their names:

1. **The noise elsewhere.** Each member's parameters are refitted to the other's predicted noise (every
   measured component, intensities 4-250 DN, nine sensor positions) at gains, exposures and temperatures
   beyond the data's (:class:`Probe`). Where neither can follow the other within ``PROBE_TOLERANCE`` of the
   total variance, a sweep of that axis separates them.
2. **The camera's physical state.** Otherwise the conditions after the modifiers (dark signal, dark
   current, exposure time, temperature, conversion gain; ``QUANTITIES``): those the members change alike
   are what the data saw; one they change differently is what must be measured apart from the noise.
3. **Traits beyond the variance** (distribution, temporal or fixed, line structure, position), when the
   members do not differ in the physical state either.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.optimize import least_squares

from ..physics import CameraMetadata, Effect, EffectError, NoiseModel
from ..physics.metadata import VALID_RANGES
from ..physics.sensor import Conditions
from .compare import MEASURED, Comparison, Views

if TYPE_CHECKING:
    from .diagnose import Candidate

#: a sweep separates two members when, refitted to each other's noise there, neither follows the other
#: within this fraction of the total variance somewhere on it
PROBE_TOLERANCE = 0.05
#: operating points per swept axis; the sweeps reach beyond the data's range by these
PROBE_POINTS = 7
PROBE_EXPOSURE_FACTOR = 10.0
PROBE_TEMPERATURE_C = 20.0
PROBE_GAIN_DB = (6.0, 12.0)  # below, above
PROBE_LEVELS_DN = np.linspace(4.0, 250.0, 12)
PROBE_NFEV = 60
#: a member changes a quantity when its log ratio to the model's (temperature: its difference in K)
#: exceeds CHANGED; members change it differently when their values spread by more than DIFFERENT
CHANGED = {True: 0.01, False: 0.1}
DIFFERENT = {True: 0.05, False: 1.0}

AXES = {
    "gain_db": ("gain", "dB"),
    "exposure_time_s": ("exposure", "s"),
    "sensor_temperature_c": ("temperature", "degC"),
}


@dataclass(frozen=True)
class Quantity:
    """A quantity of the camera's physical state (:class:`Conditions` after the modifiers)."""

    label: str
    value: Callable[[Conditions], float]
    #: compared as a ratio (else as a difference in K)
    ratio: bool
    #: how to measure it apart from the noise ('' when the noise is what shows it)
    how: str


#: in the order a separating measurement is proposed (the first the members change differently)
QUANTITIES = (
    Quantity("the exposure time t", lambda c: c.exposure_time_s, True,
             "the exposure time itself, apart from the dark current: the photo-signal of a light of known, "
             "constant irradiance grows in proportion to the true exposure (the dark current leaves it "
             "unchanged), or an LED pulsed at a known rate shows how long the exposure lasts"),
    Quantity("the sensor temperature", lambda c: c.temperature_k, False,
             "the sensor temperature with a thermometer of its own on the sensor package"),
    Quantity("the conversion gain", lambda c: c.dn_per_e, True,
             "the conversion gain apart from the noise: the mean signal of a light of known photon flux at a "
             "known quantum efficiency"),
    Quantity("the dark current D", lambda c: c.dark_e / max(c.exposure_time_s, 1e-12), True,
             "the dark current alone: the growth of the mean dark level over an independently timed exposure"),
    Quantity("the dark signal D x t", lambda c: c.dark_e, True, ""),
)

#: traits of an effect beyond its variance, with what would show them
TRAITS = (
    ("distribution", "the shape of the pixel-value distribution beyond its variance (e.g. a histogram of a "
                     "dark frame average: a few strongly offset pixels against a Gaussian spread)"),
    ("temporal", "frame differences (temporal noise) against the average of many frames (fixed pattern)"),
    ("structure", "the noise's correlation along rows and columns (line means)"),
    ("spatial", "the noise's dependence on the position on the sensor (a map of flat-field noise)"),
)


class Probe:
    """The model's noise at operating points beyond the data's: gain, exposure and temperature swept one
    at a time (the others at the data's medians), each over intensities 4-250 DN at nine sensor
    positions, without partner views (fixed patterns as single-view variances)."""

    def __init__(self, comp: Comparison) -> None:
        metas = [sb.seg.meta for sb in comp.segments]
        data = {a: np.array([getattr(m, a) for m in metas], dtype=float) for a in AXES}
        self.ranges = {a: (float(x.min()), float(x.max())) for a, x in data.items()}
        ref = metas[0].replace(gain_db=float(np.median(data["gain_db"])),
                               exposure_time_s=float(np.exp(np.median(np.log(data["exposure_time_s"])))),
                               sensor_temperature_c=float(np.median(data["sensor_temperature_c"])))
        (g0, g1), (t0, t1), (c0, c1) = (self.ranges[a] for a in AXES)
        sweeps = {
            "gain_db": np.linspace(g0 - PROBE_GAIN_DB[0], g1 + PROBE_GAIN_DB[1], PROBE_POINTS),
            "exposure_time_s": np.geomspace(t0 / PROBE_EXPOSURE_FACTOR, t1 * PROBE_EXPOSURE_FACTOR, PROBE_POINTS),
            "sensor_temperature_c": np.linspace(c0 - PROBE_TEMPERATURE_C, c1 + PROBE_TEMPERATURE_C, PROBE_POINTS),
        }
        self.points = [(a, float(np.clip(x, *VALID_RANGES[a]))) for a, xs in sweeps.items() for x in xs]
        self.swept = {a: (min(x for b, x in self.points if b == a), max(x for b, x in self.points if b == a))
                      for a in AXES}
        grid = (np.arange(3) + 0.5) / 3.0
        pos = np.tile(np.array([(y, x) for y in grid for x in grid]), (PROBE_LEVELS_DN.size, 1))
        self.levels = np.repeat(PROBE_LEVELS_DN, 9)
        probe_metas: list[CameraMetadata] = [ref.replace(**{a: x}) for a, x in self.points]
        # the blocks' noise (for which offsets stand out as outlier pixels) is the model's own
        first = Views([(m, self.levels, np.ones(self.levels.size), pos, []) for m in probe_metas])
        base = first.components(comp.effects)
        sigma = np.split(np.sqrt(np.maximum(base["temporal"] + base["fixed"], 1e-6)), len(probe_metas))
        self.views = Views([(m, self.levels, s, pos, []) for m, s in zip(probe_metas, sigma)])
        self.comp = comp

    def variances(self, effect: Effect) -> np.ndarray:
        """Variance (DN^2) per measured component (rows, ``MEASURED`` order) at every probe block with
        ``effect`` added to the model."""
        comps = self.views.components(self.comp.replaced([effect]))
        return np.stack([comps[c] for c in MEASURED])

    def follow(self, target: np.ndarray, effect: Effect, free: Sequence[str]) -> tuple[float, int]:
        """Refit ``effect``'s continuous ``free`` parameters to the ``target`` variances; (largest
        remaining difference as a fraction of the target's total variance, its flat index)."""
        cls = type(effect)
        params = [p for p in cls.params if p.name in free and not p.integer]
        total = np.maximum(target.sum(axis=0), 1e-9)

        def resid(x: np.ndarray) -> np.ndarray:
            values = {**effect.values, **{p.name: float(np.clip(v, *p.bounds)) for p, v in zip(params, x)}}
            try:
                pred = self.variances(cls(**values))
            except (EffectError, ValueError, FloatingPointError):
                return np.full(target.size, 1e3)
            return ((pred - target) / total).ravel()

        x0 = np.array([effect.values[p.name] for p in params], dtype=float)
        if params:
            lo, hi = np.array([p.bounds for p in params], dtype=float).T
            r = least_squares(resid, x0, bounds=(lo, hi), x_scale=np.maximum(np.abs(x0), 1e-3 * (hi - lo)),
                              max_nfev=PROBE_NFEV).fun
        else:
            r = resid(x0)
        i = int(np.argmax(np.abs(r)))
        return float(abs(r[i])), i

    def where(self, index: int) -> tuple[str, float, float, str]:
        """(axis, its value, intensity DN, component) of a flat index into :meth:`variances`' array."""
        comp, block = divmod(index, self.levels.size * len(self.points))
        axis, value = self.points[block // self.levels.size]
        return axis, value, float(self.levels[block % self.levels.size]), MEASURED[comp]


def _fmt(axis: str, x: float) -> str:
    if axis == "exposure_time_s":
        return f"{x * 1e3:.3g} ms" if x < 1.0 else f"{x:.3g} s"
    return f"{x:.0f} {AXES[axis][1]}"


def _span(axis: str, lo: float, hi: float) -> str:
    return _fmt(axis, lo) if lo == hi else f"{_fmt(axis, lo)} - {_fmt(axis, hi)}"


def _separating_sweep(probe: Probe, members: Sequence[Candidate]) -> str:
    """How a sweep beyond the data separates the leader from each member ('' when none does)."""
    lead = members[0]
    assert lead.fitted is not None
    found = []
    for m in members[1:]:
        assert m.fitted is not None
        a, b = probe.variances(lead.fitted), probe.variances(m.fitted)
        tries = [(*probe.follow(a, m.fitted, list(m.params)), m.effect, lead.effect),
                 (*probe.follow(b, lead.fitted, list(lead.params)), lead.effect, m.effect)]
        miss, index, follower, target = min(tries)
        if miss <= PROBE_TOLERANCE:
            continue
        axis, value, level, comp = probe.where(index)
        found.append(f"{'an' if AXES[axis][0][0] in 'aeiou' else 'a'} {AXES[axis][0]} sweep separates {lead.effect} and {m.effect}: at {_fmt(axis, value)} "
                     f"(the data: {_span(axis, *probe.ranges[axis])}) and {level:.0f} DN their {comp} noise "
                     f"differs by {100 * miss:.0f} % of the total even with {follower}'s parameters refitted to "
                     f"{target}'s noise")
    return "; ".join(found)


def _state(comp: Comparison, members: Sequence[Candidate]) -> dict[str, list[float]]:
    """Per quantity, each member's change of it against the model's (median over the segments' metadata:
    log ratio, or difference in K)."""
    metas = [sb.seg.meta for sb in comp.segments]
    base = NoiseModel(comp.effects)
    conds0 = [base.conditions(m) for m in metas]
    out: dict[str, list[float]] = {q.label: [] for q in QUANTITIES}
    for c in members:
        assert c.fitted is not None
        model = NoiseModel(comp.replaced([c.fitted]))
        conds = [model.conditions(m) for m in metas]
        for q in QUANTITIES:
            now = np.array([q.value(x) for x in conds])
            was = np.array([q.value(x) for x in conds0])
            d = np.log(np.maximum(now, 1e-300) / np.maximum(was, 1e-300)) if q.ratio else now - was
            out[q.label].append(float(np.median(d)))
    return out


def _change(q: Quantity, d: float) -> str:
    """A member's change of a quantity: 'the exposure time t (x 2.03)'."""
    return f"{q.label} (x {np.exp(d):.2f})" if q.ratio else f"{q.label} ({d:+.1f} degC)"


def _shared(q: Quantity, d: float) -> str:
    """A change the members share: 'the dark signal D x t is 2.03 x the model's'."""
    return f"{q.label} is {np.exp(d):.2f} x the model's" if q.ratio else f"{q.label} is {d:+.1f} degC off the model's"


def _params(c: Candidate) -> str:
    return ", ".join(f"{k}={v:.4g}" for k, v in c.params.items())


def explain(comp: Comparison, members: Sequence[Candidate], chi2: float, z: float) -> str:
    """One paragraph on a group of equivalent candidates (leader first): what they agree on, that these
    data cannot tell them apart (their fitted predictions' largest difference ``z`` in standard errors
    and its chi-square ``chi2``) and which observation would separate them."""
    state = _state(comp, members)
    changed = {q.label: any(abs(d) > CHANGED[q.ratio] for d in state[q.label]) for q in QUANTITIES}
    spread = {q.label: max(state[q.label]) - min(state[q.label]) for q in QUANTITIES}
    shared = [q for q in QUANTITIES if changed[q.label] and spread[q.label] <= DIFFERENT[q.ratio]]
    differing = [q for q in QUANTITIES if changed[q.label] and spread[q.label] > DIFFERENT[q.ratio]]

    def alternative(i: int, c: Candidate) -> str:
        own = [q for q in differing + shared if abs(state[q.label][i]) > CHANGED[q.ratio]]
        what = _change(own[0], state[own[0].label][i]) if own else c.reading
        return f"{what} ({c.effect}: {_params(c)})"

    if shared:
        head = " and ".join(_shared(q, float(np.mean(state[q.label]))) for q in shared)
    else:
        comps = sorted({k for c in members for k in (c.components or {})})
        head = f"the same change of the {', '.join(comps) or 'measured'} noise"
    text = (f"{head}: either " + " or ".join(alternative(i, c) for i, c in enumerate(members))
            + f"; these data cannot tell them apart (their fitted predictions differ by at most {z:.2f} standard "
            f"errors, chi-square {chi2:.1f} over {comp.residuals().size} observables)")
    if shared and differing:
        text += f": they see only {' and '.join(q.label for q in shared)}"
    probe: Probe | None
    try:
        probe = Probe(comp)
        sweep = _separating_sweep(probe, members)
    except (EffectError, ValueError, FloatingPointError):  # an effect fails beyond the data's conditions
        probe, sweep = None, ""
    if sweep:
        return f"{text}. To separate them: {sweep}."
    if probe is None:
        text += ". Their noise beyond the data's operating points could not be evaluated"
    else:
        text += (". No noise measurement separates them: at gains " + _span("gain_db", *probe.swept["gain_db"])
                 + ", exposures " + _span("exposure_time_s", *probe.swept["exposure_time_s"])
                 + " and temperatures " + _span("sensor_temperature_c", *probe.swept["sensor_temperature_c"])
                 + f" each follows the other's noise within {100 * PROBE_TOLERANCE:.0f} % once refitted")
    how = [q.how for q in differing if q.how]
    if how:
        return f"{text}. To separate them, measure {how[0]}."
    traits = [(name, what) for name, what in TRAITS
              if len({str(getattr(type(c.fitted), name)) for c in members}) > 1]
    if traits:
        name, what = traits[0]
        values = ", ".join(f"{c.effect}: {getattr(type(c.fitted), name)}" for c in members)
        return f"{text}. They differ in their {name} ({values}): to separate them, measure {what}."
    return f"{text}. Nothing in the camera model distinguishes them: the same physics under two names."
