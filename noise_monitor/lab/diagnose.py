"""Diagnosis: fit every candidate effect to the measurements, rank, test significance.

Each candidate's fittable parameters are fitted by bounded least squares on the normalised residuals
of all observables (cell variances per component, outlier-pixel counts, quantization step); integer
parameters are scanned on their grid. Ranking: the BIC gain ``chi2_0 - chi2_1 - k ln N``; explained
fraction: ``1 - chi2_1 / chi2_0``; significance: F-test of the chi-square drop against the remaining
chi-square per degree of freedom (robust to mis-scaled errors), plus a minimum explained fraction and
a minimum relative drop of the model error (DN, net of the measurement's scatter) where the effect acts:
in the measured components the effect changes (temporal, fixed, rows, columns, ...); where one cell far
noisier than the rest puts a component's pooled error within the scatter, its cells' chi-square judges, and where a
few imprecise cells make that error (not significantly above 0 against its own noise) its cells' chi-square may pass
an effect the error's cut does not (:func:`cuts_error`). A floor of scene texture in other components then cannot
hide a correct fit, and an effect that only bends the model towards a residual it cannot shape (a uniform
dark-current change for a glowing corner) is not claimed; nor is one that leaves where on the sensor the residual
sits: a significant position pattern of the excess (towards a corner, along a gradient, beyond an intensity law per
segment: :func:`.signature.position_pattern`) in a component it changes must lose MIN_OWN_REDUCTION of its
amplitude. Nor is a fit that a direct observation contradicts (``contradicted``): a quantization step the
output histogram does not show, or a Gaussian fixed pattern (PRNU, DSNU, line offsets, or an effect that
rescales them) standing for a measured fixed pattern that is sparse (a few pixels far off, kurtosis well
above a Gaussian's 3: :class:`.shape.FixedShape`), such as random telegraph pixels below the outlier
threshold.

Parameter errors come from the Jacobian at the optimum; along directions the data do not constrain
(only a product of parameters is identifiable: fraction x amplitude^2; hot pixels saturated in every
hold: only a lower bound of their dark current) the error is the parameter's whole allowed range and the
parameters are listed as ``degenerate``, never a spuriously tight value, with the range of values that
fit as well along that direction (``param_ranges``).

Candidates the data cannot tell apart form one explanation: two fitted candidates are equivalent when
their fitted models predict the same observables, i.e. the difference of their normalised residual
vectors (their predictions' difference in standard errors) has a chi-square of at most
``EQUIVALENT_CHI2`` and no entry beyond ``EQUIVALENT_Z`` (both scaled by the best-fitting candidate's
chi2/dof when above 1, like the F-test): even if one were exactly true, the data could not prefer it to
the other by more. Their predicted changes must also coincide: that difference is at most
``EQUIVALENT_SHARE`` of the change each makes to the model's predictions (weak fits near "no effect" lie
within a few chi-square of one another whatever their physics). A group forms around the best
candidate by BIC that the BIC prefers to no effect; each member must differ from no effect by more than
``EQUIVALENT_CHI2`` (fits that found nothing are never grouped). Members share the
group's rank (ranks count explanations: 1, 1, 2, ...) and its best member's significance, and carry
``equivalent_to`` and ``indistinguishable`` (:func:`.equivalence.explain`: what they agree on and which
observation would separate them).

Claims are made by forward selection (:func:`claim`): each candidate is tested alone against the camera's
model as above, which only says that it reproduces part of the residual; two candidates that reproduce
the same part would both pass. The groups are taken in rank order: the first group significant alone is
claimed; every later group is refitted (its best member) with the claimed explanations
in the model at their fitted values and claimed only if it is significant beyond them by the same tests,
all relative to the claimed model (:func:`assess`): F-test of the chi-square drop beyond it (degrees of
freedom net of every fitted parameter), MIN_EXPLAINED_FRACTION of the chi-square it leaves (not asked where that
chi-square is within its degrees of freedom, the measurement's stated scatter: :func:`_within_scatter`), the error cut
in the components the candidate changes and their position pattern against the claimed model's, no
contradiction the claimed model does not have. Its fit beyond them joins the claimed model for the
next. A group significant alone but not beyond them is ``explained_by`` them (with the refit's figures
and a plain reading in ``beyond``); one not significant alone but significant beyond them (an effect whose
part of the residual the first one's masked, e.g. 10 e- of extra read noise beside a DSNU) is claimed. The claimed effects are held at their fitted values rather than
refitted jointly: the refit then changes only the candidate, so the components it changes, their
position pattern and a contradiction are its own (refitted jointly, a temperature or exposure error on
top of a DSNU shifts the DSNU to make up for the dark signal it changes in the fixed-pattern noise and
passes the own-component cut, where it is read noise that is missing), and it is one fit of the
candidate's own parameters. Claims can only be withdrawn by this rule, never added, with two exceptions: two missing
effects that partly cancel (an unstated pedestal's phantom shot noise against extra read noise) may leave a residual
neither reproduces alone; and the first claim's fit alone may have taken up a second effect's residual (a DSNU the
PRNU's pattern, when both are missing), which its fit alone then also finds but not beyond the first. When the best
candidate whose fit alone passed the F-test and the explained fraction is not claimed (nothing is, or something
ranked below it), it is fitted jointly with each other one (:func:`_pair`); when it is claimed, with each other one
whose fit alone passed them too (a partner found only once the lead is bent to make room for it, e.g. a PRNU beside
the plug-in for random telegraph pixels, is not), one the forward selection claimed beside it only if the joint fit
moves the lead by more than MIN_PAIR_MOVE of its standard errors (held at its fit alone, a DSNU that took up the PRNU's
pattern leaves an excess a dark-current law would make up); the pair leaving the smallest
chi-square with each member significant beyond the other's joint fit (all the tests above) and most of the model's
error explained is claimed (with a partner claimed beside the lead: if it fits better than the two as the forward
selection fitted them), partners that fit as well named as alternatives, and the forward selection goes on beyond the
two (what it claimed before is tested beyond them); the pair's claims, so completed, replace the forward selection's if
their BIC is lower (a pair alone against a model that also holds hot pixels and column offsets would lose for lack of
them).
"""
from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import chi2 as chi2_dist
from scipy.stats import f as f_dist
from scipy.stats import norm

from ..physics import Effect, EffectError, Param, available
from ..physics.effects import PAPER_EFFECTS
from .compare import REGIONAL, Comparison, gaussian_fixed, rms_error, rms_error_raw, sigma_error
from .equivalence import explain
from .measure import POOLED
from .signature import position_pattern

#: F-test p-value below which a candidate's improvement counts as real
SIGNIFICANCE_P = 1e-6
#: ... and the fraction of the chi-square it must explain (beyond claimed effects whose model leaves a chi-square within
#: its degrees of freedom, waived: :func:`_within_scatter`)
MIN_EXPLAINED_FRACTION = 0.1
#: ... and the relative drop of the rms error it must bring in the components it changes (an effect that
#: explains its part of the residual removes most of it there; a wrong one bends the model a little
#: towards it; scene texture leaking into the statistics gives statistically significant tiny drops)
MIN_OWN_REDUCTION = 0.5
#: a component's net rms error not significantly above 0 at this p-value against its own noise (a few imprecise cells
#: make it) may be judged by its cells' chi-square where the error's cut fails (:func:`cuts_error`); an extra pass, so
#: its test of the error's existence is lenient (an error at p 2e-6 that an effect made larger is there to cut)
WITHIN_NOISE_P = 1e-3
#: a candidate whose fit puts the measured quantization step (output histogram) further than this many
#: standard errors from the model's is contradicted by a direct observation and never claimed
MAX_STEP_Z = 5.0
#: a candidate not significant alone is refitted beyond the claimed explanations (an effect their residual
#: masks alone) only if its own fit found something at this p-value (the F-test of its chi-square drop alone, against
#: the claimed model's residual per degree of freedom: the residual they explain dilutes the test alone, e.g. column
#: offsets of 0.45 DN beside a PRNU and a DSNU, p 0.1-0.4 alone): one that found nothing alone would find nothing on
#: top of them either, and each refit costs a fit
MASKED_P = 0.05
#: when the best candidate whose fit alone found something (F-test and explained fraction) is not claimed, it is fitted
#: jointly with each other candidate (from this many rounds of fitting each beyond the other) and the two are claimed
#: together when each is significant beyond the other's joint fit: two missing effects that partly cancel (an unstated
#: pedestal's phantom shot noise against extra read noise) leave a residual neither reproduces alone
PAIR_ROUNDS = 2
#: ... and the two must leave at most this share of the camera's model's rms error (net of the measurement's scatter) in
#: the components they change (:func:`_share_left`; other effects' errors elsewhere, e.g. hot pixels' outliers, are not
#: theirs to explain): a pair that cancels explains the residual; a wrong lead with a second effect bent to make up for
#: it does not (a cubic compression read as a gain error of 0.36 with 70 e- of extra read noise: 1.04 -> 0.60 DN)
MAX_PAIR_ERROR = 0.2
#: ... and a partner passing the screen (F-test and explained fraction beyond the lead's own fit, least squares from
#: its defaults) is refitted jointly only if its full fit beyond the lead leaves at most this share (on the pedestal
#: camera: 0 with extra read noise; the cubic compression's gain error with read noise: 0.57)
PAIR_SCREEN = 0.5
#: where the lead was claimed alone and the forward selection claimed a partner beside it (held at the lead's fit alone),
#: the two are refitted jointly only if that moves the lead by more than this many of its standard errors: its fit alone
#: took up the partner's residual (a DSNU the PRNU's pattern, 5-18 SE) rather than sharing a residual with it
MIN_PAIR_MOVE = 3.0
#: components an effect changes: those carrying at least this share of its total |variance change|
OWN_COMPONENT_SHARE = 0.25
#: a fitted parameter within this fraction of its allowed range from its upper bound is read as pushed to the limit
#: (:func:`fitted_reading`)
AT_LIMIT = 1e-6
#: smallest total sigma (DN) a component's variance mismatch is scaled by (8-bit rounding alone: 0.29)
MIN_SIGMA_DN = 0.1
#: a direction in parameter space is unidentified if crossing the whole allowed range along it changes
#: the chi-square (scaled by chi2/dof) by less than this
UNIDENTIFIED_CHI2 = 1.0
MAX_GRID = 32
#: best points of the coarse parameter scan refined by least squares
N_STARTS = 3
SCAN_PER_DECADE = 2
#: two candidates are equivalent when their fitted predictions differ by at most this chi-square (the
#: data could not prefer one to the other by more even if one were exactly true: 2 sigma) ...
EQUIVALENT_CHI2 = 4.0
#: ... and by at most this many standard errors in every observable ...
EQUIVALENT_Z = 1.0
#: ... and by at most this fraction of the change each makes to the model's predictions (rms over the
#: observables): weak fits near "no effect" all lie within a few chi-square of one another, yet their
#: changes need not coincide
EQUIVALENT_SHARE = 0.2


@dataclass
class FitResult:
    """A fitted effect set: effect instances, fitted values and their standard errors, chi-square."""

    effects: list[Effect]
    values: dict[str, dict[str, float]]
    errors: dict[str, dict[str, float | None]]
    chi2: float
    n_free: int
    degenerate: dict[str, list[str]] | None = None
    #: effect -> degenerate parameter -> (lowest, highest) value fitting as well (see :func:`_flat_range`)
    ranges: dict[str, dict[str, tuple[float, float]]] | None = None


@dataclass
class Candidate:
    """One candidate effect fitted to the measurements."""

    effect: str
    params: dict[str, float]
    param_errors: dict[str, float | None]
    chi2: float
    explained_fraction: float
    delta_bic: float
    p_value: float
    significant: bool
    reading: str
    rms_error_after_dn: float
    degenerate: list[str] | None = None
    param_ranges: dict[str, tuple[float, float]] | None = None
    components: dict[str, dict[str, float]] | None = None
    rms_error_after_raw_dn: float = float("nan")
    #: why a candidate that passes the statistical tests is not claimed (empty: it is, or it fails them)
    contradicted: str = ""
    #: rank among the explanations (equivalent candidates share one)
    rank: int = 0
    #: the candidates these data cannot tell apart from this one
    equivalent_to: list[str] = field(default_factory=list)
    #: what the equivalent candidates agree on and which observation would separate them
    indistinguishable: str = ""
    #: significant by its own fit against the camera's model (the group's, like ``significant``), before
    #: the claims' forward selection (:func:`claim`); ``significant`` is the claim
    significant_alone: bool = False
    #: the claimed explanations it was refitted on top of when significant alone but not beyond them
    explained_by: list[str] = field(default_factory=list)
    #: that refit on top of the claimed explanations (:func:`_beyond`); None when it was not refitted
    beyond: dict[str, Any] | None = None
    #: the fitted effect instance
    fitted: Effect | None = field(default=None, repr=False, compare=False)

    @property
    def claimed_params(self) -> dict[str, float] | None:
        """The values claimed (its refit beyond or with the other claims, else its fit alone: also for a member of a
        group claimed whole, whose ``beyond`` records the refit of the group's lead); None: not claimed."""
        if not self.significant:
            return None
        return self.beyond["params"] if self.beyond and self.beyond["effect"] == self.effect else self.params

    def as_dict(self) -> dict[str, Any]:
        return {
            "effect": self.effect,
            "rank": self.rank,
            "equivalent_to": self.equivalent_to,
            "indistinguishable": self.indistinguishable,
            "significant": self.significant,
            "significant_alone": self.significant_alone,
            "explained_by": self.explained_by,
            "beyond": self.beyond,
            "explained_fraction": round(self.explained_fraction, 6),
            "params": self.params,
            "claimed_params": self.claimed_params,
            "param_errors": self.param_errors,
            "delta_bic": round(self.delta_bic, 3),
            "p_value": self.p_value,
            "chi2": round(self.chi2, 3),
            "rms_error_after_dn": round(self.rms_error_after_dn, 5),
            "rms_error_after_raw_dn": round(self.rms_error_after_raw_dn, 5),
            "contradicted": self.contradicted,
            "reading": self.reading,
            "degenerate": self.degenerate or [],
            "param_ranges": {k: list(v) for k, v in (self.param_ranges or {}).items()},
            "components": self.components or {},
        }


@dataclass(frozen=True)
class EffectSpec:
    """An effect to fit: its class, fixed parameter values and the names of the parameters to fit."""

    cls: type[Effect]
    fixed: Mapping[str, float]
    free: tuple[str, ...]

    @classmethod
    def fit_all(cls, effect_cls: type[Effect]) -> EffectSpec:
        return cls(effect_cls, {}, tuple(p.name for p in effect_cls.params if p.fittable))


def fitted_reading(res: FitResult, effect: Effect) -> str:
    """A fitted effect's plain reading, naming the parameters these data do not identify with the range of values that
    fit as well (hot pixels that saturate: any dark multiplier above a few hundred), and those the fit pushed to the
    upper limit of their allowed range (hot pixels at 20 % of the pixels: the effect stretched, perhaps standing for
    another), so no reader takes the value the fit stopped at for a measurement."""
    ranges = (res.ranges or {}).get(effect.name, {})
    notes = []
    if ranges:
        spans = "; ".join(f"{name} anywhere from {lo:.3g} to {hi:.3g}" for name, (lo, hi) in ranges.items())
        notes.append(f"not identified by these data: {spans} fits as well")
    for name, hi in at_upper_limit(type(effect), res.values.get(effect.name, {}), ranges):
        notes.append(f"{name} at the upper limit of its allowed range, {hi:g}: the data would take more; "
                     "the effect may stand for another")
    return effect.reading() + "".join(f" ({n})" for n in notes)


def at_upper_limit(cls: type[Effect], fitted: Mapping[str, float], ranges: Mapping[str, Any]
                   ) -> list[tuple[str, float]]:
    """The ``fitted`` parameters of an effect of ``cls`` a fit pushed to the upper limit of their allowed range (name,
    limit), but those the data do not identify (``ranges``: any value in a range fits as well)."""
    return [(p.name, p.bounds[1]) for p in cls.params if p.name in fitted and p.name not in ranges
            and fitted[p.name] >= p.bounds[1] - AT_LIMIT * (p.bounds[1] - p.bounds[0])]


def _scan_values(p: Param) -> np.ndarray:
    """Coarse scan of a parameter: its default plus log-spaced magnitudes, SCAN_PER_DECADE per decade
    (both signs if allowed)."""
    per_decade = SCAN_PER_DECADE
    lo, hi = p.bounds
    if lo < 0.0 < hi:
        top = max(hi, -lo)
        mags = np.geomspace(top * 1e-3, top, 7)
        pts = np.concatenate([[0.0, p.default], mags, -mags])
    elif lo > 0.0:
        pts = np.concatenate([[p.default], np.geomspace(lo, hi, per_decade * _decades(lo, hi) + 1)])
    else:
        bottom = max(hi * 1e-9, 1e-12)
        pts = np.concatenate([[p.default, lo], np.geomspace(bottom, hi, per_decade * _decades(bottom, hi) + 1)])
    return np.unique(np.clip(pts, lo, hi))


def _decades(lo: float, hi: float) -> int:
    return max(1, int(np.ceil(np.log10(hi / lo))))


def fit(comp: Comparison, specs: Iterable[EffectSpec], given: Sequence[Effect] = (),
        start: Sequence[Effect] | None = None) -> FitResult:
    """Jointly fit the free parameters of ``specs`` (continuous: coarse log scan, then bounded least
    squares from the best scan points; integer: grid scan), with the ``given`` effects in the model at
    their values (the result holds the effects of ``specs`` only). ``start``: one instance per spec whose values
    replace the scan (least squares from them, integers held)."""
    specs = list(specs)
    given = list(given)
    cont: list[tuple[int, Param]] = []
    grid: list[tuple[int, Param]] = []
    for i, s in enumerate(specs):
        pmap = {p.name: p for p in s.cls.params}
        for name in s.free:
            p = pmap[name]
            (grid if p.integer and p.bounds[1] - p.bounds[0] < MAX_GRID else cont).append((i, p))

    # wide positive ranges (e.g. 0..1e7) are fitted in log10 (a floor of 1e-9 x the upper bound stands for 0)
    logs = np.array([p.bounds[0] >= 0.0 and p.bounds[1] > 1e3 * max(p.bounds[0], 1e-9 * p.bounds[1])
                     for _, p in cont], dtype=bool)
    floors = np.array([max(p.bounds[0], 1e-9 * p.bounds[1]) for _, p in cont])

    def to_internal(x: np.ndarray) -> np.ndarray:
        return np.where(logs, np.log10(np.maximum(x, floors)), x)

    def to_external(u: np.ndarray) -> np.ndarray:
        return np.where(logs, 10.0 ** np.where(logs, u, 0.0), u)

    def build(xc: np.ndarray, xg: tuple[float, ...]) -> list[Effect]:
        vals = [dict(s.fixed) for s in specs]
        for (i, p), x in zip(cont, to_external(np.asarray(xc, dtype=float))):
            vals[i][p.name] = float(np.clip(x, *p.bounds))
        for (i, p), x in zip(grid, xg):
            vals[i][p.name] = x
        return [s.cls(**v) for s, v in zip(specs, vals)]

    def resid(xc: np.ndarray, xg: tuple[float, ...]) -> np.ndarray:
        try:
            r = comp.residuals(given + build(xc, xg))
        except (EffectError, ValueError, FloatingPointError):
            return np.full(n_obs, 1e6)
        return np.where(np.isfinite(r), r, 1e6)

    n_obs = comp.residuals(given).size
    grids: list[tuple[float, ...]] = [()]
    for _, p in grid:
        grids = [g + (float(v),) for g in grids for v in range(int(p.bounds[0]), int(p.bounds[1]) + 1)]
    if start is not None:
        grids = [tuple(float(start[i].values[p.name]) for i, p in grid)]
    best: tuple[float, np.ndarray, tuple, Any] | None = None
    for xg in grids:
        if not cont:
            r = resid(np.zeros(0), xg)
            chi2 = float(r @ r)
            if best is None or chi2 < best[0]:
                best = (chi2, np.zeros(0), xg, None)
            continue
        lo = to_internal(np.array([p.bounds[0] for _, p in cont]))
        hi = to_internal(np.array([p.bounds[1] for _, p in cont]))
        scan = ([to_internal(np.array([start[i].values[p.name] for i, p in cont], dtype=float))] if start is not None
                else [to_internal(np.asarray(x)) for x in itertools.product(*[_scan_values(p) for _, p in cont])])
        chi = [float(np.sum(resid(x, xg) ** 2)) for x in scan]
        for j in np.argsort(chi)[:N_STARTS]:
            x0 = np.clip(scan[j], lo, hi)
            scale = np.where(logs, 0.3, np.maximum(np.abs(x0), 1e-3 * (hi - lo)))
            sol = least_squares(resid, x0, bounds=(lo, hi), x_scale=scale, args=(xg,), max_nfev=200)
            chi2 = float(sol.fun @ sol.fun)
            if best is None or chi2 < best[0]:
                best = (chi2, sol.x, xg, sol.jac)
    assert best is not None  # grids holds at least the empty tuple
    chi2, xc, xg, jac = best
    effects = build(xc, xg)
    errs: list[dict[str, float | None]] = [{} for _ in specs]
    degenerate: list[list[str]] = [[] for _ in specs]
    ranges: list[dict[str, tuple[float, float]]] = [{} for _ in specs]
    if cont and jac is not None:
        dof = max(n_obs - len(cont) - len(grid), 1)
        lo = to_internal(np.array([p.bounds[0] for _, p in cont]))
        hi = to_internal(np.array([p.bounds[1] for _, p in cont]))
        chi2_scale = max(1.0, chi2 / dof)
        cov, loose, flat_dirs = _covariance(jac, chi2_scale, hi - lo)
        ext = to_external(xc)
        limit = chi2 + UNIDENTIFIED_CHI2 * chi2_scale
        ends = [xc] + [_flat_range(lambda x: float(np.sum(resid(x, xg) ** 2)), xc, sign * u, lo, hi, limit)
                       for u in flat_dirs for sign in (1.0, -1.0)]
        span_lo, span_hi = to_external(np.min(ends, axis=0)), to_external(np.max(ends, axis=0))
        for k, (i, p) in enumerate(cont):
            sd = math.sqrt(max(cov[k, k], 0.0))
            err = 10.0 ** (xc[k] + sd) - ext[k] if logs[k] else sd  # log scale: the upper 1-sigma step
            if loose[k]:  # unidentified: the whole range, wherever in it the fit stopped
                err = p.bounds[1] - p.bounds[0]
                degenerate[i].append(p.name)
                ranges[i][p.name] = (float(span_lo[k]), float(span_hi[k]))
            errs[i][p.name] = float(min(err, p.bounds[1] - p.bounds[0]))
    for i, p in grid:
        errs[i][p.name] = None
    return FitResult(
        effects=effects,
        values={e.name: {p.name: e.values[p.name] for p in type(e).params if p.name in s.free}
                for e, s in zip(effects, specs)},
        errors={e.name: errs[i] for i, e in enumerate(effects)},
        chi2=chi2,
        n_free=len(cont) + len(grid),
        degenerate={e.name: d for e, d in zip(effects, degenerate) if d},
        ranges={e.name: r for e, r in zip(effects, ranges) if r},
    )


def _covariance(jac: np.ndarray, scale: float, ranges: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Covariance of the fitted (internal) parameters, which take part in an unidentified direction,
    and those directions (unit vectors).

    Along an eigen-direction u of J^T J that moves the chi-square by less than UNIDENTIFIED_CHI2 over the
    allowed range (extent R along u) the data say nothing: its variance becomes (R / 2)^2 (the range)
    instead of the pseudo-inverse's zero or the inverse's meaningless huge value.
    """
    w, vecs = np.linalg.eigh(jac.T @ jac / scale)
    extent = np.abs(vecs).T @ ranges  # R per direction
    unidentified = w * extent**2 < UNIDENTIFIED_CHI2
    inv = np.where(unidentified, (extent / 2.0) ** 2, 1.0 / np.maximum(w, 1e-300))
    loose = np.any(unidentified[None, :] & (np.abs(vecs) > 0.1), axis=1)
    return (vecs * inv) @ vecs.T, loose, [vecs[:, j] for j in np.flatnonzero(unidentified)]


#: bisection steps of :func:`_flat_range` (a range of 9 decades to 0.01 decade)
FLAT_RANGE_STEPS = 10


def _flat_range(chi2: Callable[[np.ndarray], float], x: np.ndarray, u: np.ndarray, lo: np.ndarray,
                hi: np.ndarray, limit: float) -> np.ndarray:
    """How far from the optimum ``x`` along direction ``u`` (internal parameters, within [lo, hi]) the
    chi-square stays within ``limit``: the end point. The Jacobian at the optimum says only that the
    direction is flat there; a saturated effect (hot pixels clipped in every hold) fits as well above some
    dark current and worse below it."""
    with np.errstate(divide="ignore", invalid="ignore"):
        steps = np.where(u > 0, (hi - x) / u, np.where(u < 0, (lo - x) / u, np.inf))
    t_max = max(float(np.min(steps)), 0.0)  # finite: u is a unit vector
    if chi2(x + t_max * u) <= limit:
        return x + t_max * u
    inside, outside = 0.0, t_max
    for _ in range(FLAT_RANGE_STEPS):
        mid = 0.5 * (inside + outside)
        inside, outside = (mid, outside) if chi2(x + mid * u) <= limit else (inside, mid)
    return x + inside * u


def candidate_names(extra: Iterable[str] = ()) -> list[str]:
    """Every registered effect except the paper's three sources (plus ``extra`` plug-in names)."""
    names = [n for n in available() if n not in PAPER_EFFECTS]
    return names + [n for n in extra if n not in names]


def _component_cells(rows: list[dict[str, Any]]) -> dict[str, np.ndarray]:
    """Per measured component, each cell's (error, standard error) in DN: the error its variance mismatch (measured -
    model) makes in the cell's total sigma (the measured total sigma minus what it would be with the model's variance in
    that component) and that error's standard error."""
    out: dict[str, list[tuple[float, float]]] = {}
    for r in rows:
        total = sum(r["measured_var_dn2"].values())
        sigma = max(r["measured_sigma_dn"], MIN_SIGMA_DN)
        for c, m in r["measured_var_dn2"].items():
            d = sigma - math.sqrt(max(total - m + r["model_var_dn2"].get(c, 0.0), 0.0))
            out.setdefault(c, []).append((d, sigma_error(sigma, r["measured_var_err_dn2"][c], below=d >= 0.0)))
    return {c: np.asarray(v) for c, v in out.items()}


def _net_rms(cells: np.ndarray) -> float:
    """The rms of a component's cell errors (:func:`_component_cells`) net of their scatter (0 if within it)."""
    return math.sqrt(max(float(np.mean(cells[:, 0] ** 2 - cells[:, 1] ** 2)), 0.0))


def _beyond_noise(cells: np.ndarray) -> bool:
    """Whether a component's net mean square error (:func:`_net_rms` squared) is significantly above 0 (WITHIN_NOISE_P)
    against its own noise, sqrt(2 sum se^4) / n for cell errors d ~ N(0, se): a few imprecise cells make it noisy."""
    ms = float(np.mean(cells[:, 0] ** 2 - cells[:, 1] ** 2))
    sd = math.sqrt(2.0 * float(np.sum(cells[:, 1] ** 4))) / len(cells)
    return ms > 0.0 and float(norm.sf(ms / max(sd, 1e-30))) < WITHIN_NOISE_P


def _segment_chi2(rows: list[dict[str, Any]], c: str, cells: np.ndarray) -> tuple[float, int]:
    """A pooled component's chi-square with each segment counted once (its one value is repeated in each of the
    segment's intensity cells): the sum over segments of the mean of their cells' (d/se)^2, and the segments' number."""
    segments = np.asarray([r["segment"] for r in rows if c in r["measured_var_dn2"]])
    z2 = np.square(cells[:, 0] / cells[:, 1])
    means = [float(np.mean(z2[segments == s])) for s in np.unique(segments)]
    return float(np.sum(means)), len(means)


def component_errors(rows: list[dict[str, Any]]) -> dict[str, float]:
    """Per measured component: the rms over cells of the error its variance mismatch makes in the cell's total sigma
    (DN, :func:`_component_cells`), net of the measurement's scatter like :func:`.compare.rms_error` (a component's
    cells can be noisy, even negative, where its variance is small: the rms of their square roots would be their noise,
    not the model's error)."""
    return {c: _net_rms(v) for c, v in _component_cells(rows).items()}


def own_components(before: list[dict[str, Any]], after: list[dict[str, Any]]) -> list[str]:
    """The measured components an added effect changes (OWN_COMPONENT_SHARE of its |variance change|)."""
    change: dict[str, float] = {}
    for b, a in zip(before, after):
        for c, p in a["model_var_dn2"].items():
            change[c] = change.get(c, 0.0) + abs(p - b["model_var_dn2"].get(c, 0.0))
    total = sum(change.values())
    return [c for c, x in change.items() if total > 0 and x >= OWN_COMPONENT_SHARE * total]


def cuts_error(rows0: list[dict[str, Any]], rows1: list[dict[str, Any]]) -> tuple[bool, dict[str, dict[str, float]]]:
    """Whether an added effect cuts the rms model error (DN, net of the measurement's scatter) by
    MIN_OWN_REDUCTION in every measured component it changes (an error within the scatter cannot be cut);
    and those components' errors before and after. Where a component's pooled error is within the scatter
    (a few cells far noisier than the rest can outweigh every other cell's error), its cells' chi-square
    judges instead: the error exists if that chi-square is significant (SIGNIFICANCE_P), and the effect
    must cut its excess over the cells' number as the rms error's square: to (1 - MIN_OWN_REDUCTION)^2. Where the
    pooled error is above 0 but within its own noise (not :func:`_beyond_noise`: a few imprecise cells make it), an
    effect that does not cut it passes if it cuts the chi-square so. A pooled component (one value per segment,
    repeated in each of its cells: the rms over cells weighs a segment by its cells' number, and a few imprecise
    segments sharing one sensor pattern's realization can dominate it) also passes where it cuts so its chi-square with
    each segment counted once (:func:`_segment_chi2`)."""
    cells0, cells1 = _component_cells(rows0), _component_cells(rows1)
    own = own_components(rows0, rows1)
    errors = {c: (_net_rms(cells0[c]), _net_rms(cells1[c])) for c in own}
    comps = {c: {"rms_error_before_dn": round(e0, 5), "rms_error_after_dn": round(e1, 5)} for c, (e0, e1) in errors.items()}

    def cut(c: str, e0: float, e1: float) -> bool:
        if e0 > 0.0 and e1 <= (1.0 - MIN_OWN_REDUCTION) * e0:
            return True
        if c in POOLED and _chi_cut(_segment_chi2(rows0, c, cells0[c]), _segment_chi2(rows1, c, cells1[c])[0]):
            return True
        if e0 > 0.0 and _beyond_noise(cells0[c]):
            return False
        chi0, chi1 = (float(np.sum(np.square(v[c][:, 0] / v[c][:, 1]))) for v in (cells0, cells1))
        return _chi_cut((chi0, len(cells0[c])), chi1)

    return bool(errors) and all(cut(c, e0, e1) for c, (e0, e1) in errors.items()), comps


def _chi_cut(before: tuple[float, int], chi1: float) -> bool:
    """Whether a chi-square of ``before`` = (chi-square, its number of terms) is significant (SIGNIFICANCE_P) and an
    effect cuts its excess over that number to (1 - MIN_OWN_REDUCTION)^2, as the rms error's square (``chi1``: after)."""
    chi0, n = before
    return bool(chi2_dist.sf(chi0, n) < SIGNIFICANCE_P and chi1 - n <= (1.0 - MIN_OWN_REDUCTION) ** 2 * (chi0 - n))


def own_errors(rows0: list[dict[str, Any]], rows1: list[dict[str, Any]]) -> dict[str, tuple[float, float]]:
    """Per measured component a change from ``rows0`` to ``rows1`` touches (:func:`own_components`), its rms model error
    (:func:`component_errors`) before and after."""
    e0, e1 = component_errors(rows0), component_errors(rows1)
    return {c: (e0[c], e1[c]) for c in own_components(rows0, rows1)}


def shapes_position(comp: Comparison, patterns: Mapping[str, dict[str, Any] | None], extra: Sequence[Effect],
                    own: Iterable[str]) -> tuple[bool, dict[str, float]]:
    """Whether the model with ``extra`` effects removes MIN_OWN_REDUCTION of the amplitude of every
    significant position pattern (``patterns``: the model's without the tested effect, per component) in
    the components ``own`` the tested effect changes; and for each such component the amplitude left (sqrt
    of the pattern's explained variance after / before). A position-independent effect changes the excess
    by an intensity law only and leaves the pattern."""
    left: dict[str, float] = {}
    for c in own:
        base = patterns.get(c)
        if not base or not base["significant"]:
            continue
        after = position_pattern(comp, c, extra, shape=base["shape"])
        left[c] = math.sqrt(after["strength"] / base["strength"]) if after and base["strength"] > 0 else 0.0
    return all(x <= 1.0 - MIN_OWN_REDUCTION for x in left.values()), left


def _contradiction(comp: Comparison, before: Sequence[Effect], after: Sequence[Effect], own: Iterable[str]) -> str:
    """Why the model with the effects ``after`` (``before`` plus a fitted one that changes the measured
    components ``own``) is contradicted by a direct observation ('' if it is not): the quantization step it
    predicts against the output histogram's, where ``before`` is not as far off (e.g. 6-bit quantization
    standing for the temporal excess of blinking pixels while every 8-bit level is occupied); or, for a fit
    that changes the fixed pattern while every fixed pattern of ``after`` is Gaussian, the measured pattern's
    sparseness (e.g. PRNU standing for random telegraph pixels below the outlier threshold)."""
    z0, z1 = comp.step_z(before), comp.step_z(after)
    if z1 is not None and z0 is not None and abs(z1) > MAX_STEP_Z and abs(z1) > abs(z0):
        return (f"the output histogram's quantization step ({comp.meas.quant_step_dn:.2f} +- "
                f"{comp.meas.quant_step_err_dn:.2f} DN) disagrees with the one this fit predicts by {abs(z1):.0f} "
                "standard errors")
    shape = comp.meas.fixed_shape
    if shape is None or not shape.sparse or "fixed" not in own or not gaussian_fixed(comp.replaced(after)):
        return ""
    return (f"the measured fixed pattern is sparse (kurtosis {shape.kurtosis:.1f} +- {shape.kurtosis_err:.1f}, "
            f"{shape.excess_z:.0f} standard errors above a Gaussian pattern's 3: a few pixels far off), which "
            "the Gaussian fixed pattern of this fit cannot produce")



@dataclass
class Given:
    """The model a candidate is tested against: the baseline plus ``effects`` (claimed explanations at
    their fitted values, ``n_params`` parameters fitted in all), with what the tests compare with."""

    effects: list[Effect]
    n_params: int
    chi2: float
    n_obs: int
    rows: list[dict[str, Any]]
    #: per regional component, the position pattern of the excess over this model
    patterns: dict[str, dict[str, Any] | None]

    @classmethod
    def of(cls, comp: Comparison, effects: Sequence[Effect] = (), n_params: int = 0) -> Given:
        r = comp.residuals(effects)
        return cls(list(effects), n_params, float(r @ r), r.size, comp.cell_table(extra=effects),
                   {c: position_pattern(comp, c, effects) for c in REGIONAL})


@dataclass
class Assessment:
    """A candidate fitted on top of a :class:`Given` model, and the significance tests' results."""

    fit: FitResult
    chi2_given: float
    p_value: float
    explained_fraction: float
    delta_bic: float
    rows: list[dict[str, Any]]
    components: dict[str, dict[str, float]]
    contradicted: str
    #: the tests it fails (empty: significant beyond the given model)
    failed: list[str]
    #: the given model holds claimed effects and leaves a residual within the measurement's scatter
    #: (:func:`_within_scatter`: no explained fraction asked)
    within_scatter: bool = False

    @property
    def effect(self) -> Effect:
        return self.fit.effects[0]

    @property
    def significant(self) -> bool:
        return not self.failed


def _f_test(drop: float, k: int, chi_left: float, given: Given) -> float:
    """F-test p-value of a chi-square ``drop`` by ``k`` more parameters beyond the ``given`` model, against ``chi_left``
    per degree of freedom (what is left, net of every fitted parameter)."""
    dof = max(given.n_obs - given.n_params - k, 1)
    return float(f_dist.sf((drop / k) / max(chi_left / dof, 1e-12), k, dof)) if drop > 0 else 1.0


def _drop(given: Given, res: FitResult) -> tuple[float, float, float]:
    """(F-test p-value, explained fraction, chi-square drop) of a fit beyond the ``given`` model."""
    chi1 = min(res.chi2, given.chi2)
    drop = given.chi2 - chi1
    return _f_test(drop, res.n_free, chi1, given), (drop / given.chi2 if given.chi2 > 0 else 0.0), drop


def _within_scatter(given: Given) -> bool:
    """Whether the ``given`` model holds effects (claimed ones, or a pair's partner) and leaves a chi-square within its
    degrees of freedom: its residual is no more than the scatter the measurement states, so a share of it is no
    yardstick for a candidate beyond it (column offsets of 0.45 DN beside a PRNU, a DSNU and hot pixels explain 5-9 %
    of such a residual)."""
    return bool(given.effects) and given.chi2 <= given.n_obs - given.n_params


def assess(comp: Comparison, given: Given, spec: EffectSpec) -> Assessment:
    """Fit ``spec`` with the ``given`` model's effects at their values and test whether it is significant
    beyond that model (module docstring): F-test of the chi-square drop, the fraction of the given model's
    chi-square it explains, the error cut in the components it changes (against the given model's), the
    position pattern there, no contradiction by a direct observation."""
    res = fit(comp, [spec], given.effects)
    after = [*given.effects, res.effects[0]]
    k = res.n_free
    p, explained, drop = _drop(given, res)
    rows = comp.cell_table(extra=after)
    cut, comps = cuts_error(given.rows, rows)
    shaped, left = shapes_position(comp, given.patterns, after, comps)
    for c, x in left.items():
        comps[c]["position_pattern_left"] = round(x, 4)
    contradicted = _contradiction(comp, given.effects, after, comps)
    scatter = _within_scatter(given)
    tests = (("F-test", p < SIGNIFICANCE_P), ("explained fraction", explained >= MIN_EXPLAINED_FRACTION or scatter),
             ("own-component error", cut), ("position pattern", shaped), ("contradicted", not contradicted))
    return Assessment(res, given.chi2, p, explained, drop - k * math.log(given.n_obs), rows, comps, contradicted,
                      [name for name, ok in tests if not ok], scatter)


@dataclass
class Diagnosis:
    """:func:`diagnose`'s answer: the candidates ranked best first with their verdicts, and the claimed model (the
    claimed effects at their claimed values, one per claimed group; ``claimed``: the candidate whose fit each is)."""

    candidates: list[Candidate]
    model: list[Effect]
    claimed: list[Candidate]


def diagnose(comp: Comparison, names: Iterable[str] | None = None, progress: Any = None) -> Diagnosis:
    """Fit every candidate alone, rank by BIC gain (best first), test significance, group the candidates
    the data cannot tell apart, and claim by forward selection (:func:`claim`)."""
    base = Given.of(comp)
    reg = available()
    out = []
    for name in names if names is not None else candidate_names():
        spec = EffectSpec.fit_all(reg[name])
        if not spec.free:
            continue
        a = assess(comp, base, spec)
        out.append(Candidate(
            effect=name,
            params=a.fit.values[name],
            param_errors=a.fit.errors[name],
            chi2=a.fit.chi2,
            explained_fraction=a.explained_fraction,
            delta_bic=a.delta_bic,
            p_value=a.p_value,
            significant=a.significant,
            reading=fitted_reading(a.fit, a.effect),
            rms_error_after_dn=rms_error(a.rows),
            rms_error_after_raw_dn=rms_error_raw(a.rows),
            contradicted=a.contradicted,
            degenerate=(a.fit.degenerate or {}).get(name),
            param_ranges=(a.fit.ranges or {}).get(name),
            components=a.components,
            fitted=a.effect,
        ))
        if progress is not None:
            progress.update(1)
    # BIC gains equal to the reported 0.001 tie (floating-point noise of fits that found nothing): by name
    out.sort(key=lambda c: (-round(c.delta_bic, 3), c.effect))
    return claim(comp, group_equivalent(comp, out))


def claim(comp: Comparison, ranked: list[Candidate]) -> Diagnosis:
    """Claim explanations by forward selection over the groups (ranked best first, significance per
    group from each candidate's own fit): the first group significant alone is claimed; each later one
    (significant alone or not) is refitted (its best member, then the others in turn: :func:`_refit_group`) with the
    claimed explanations at their fitted values and claimed only if it is significant beyond them by the same tests
    (:func:`assess`); its fit beyond them then joins the claimed model. A group significant alone but not beyond them is
    ``explained_by`` them; one significant neither alone nor beyond them keeps ``beyond`` None, and so do one
    whose fit alone found nothing (its drop alone against the claimed model's residual: F-test p >= MASKED_P; not
    refitted) and one whose own fit a direct observation contradicts (``contradicted``: refitted beyond a model with a
    sparse fixed pattern of its own, a Gaussian pattern would escape the shape test and take up the part of
    the sparse pattern that model does not describe, e.g. PRNU beside telegraph pixels). A pair claimed together
    (:func:`_pair`) replaces those claims where its claims, completed by the forward selection, fit better by the BIC;
    of partners that fit as well beside the pair's lead, each is completed so and the best kept."""
    for c in ranked:
        c.significant_alone = c.significant
    model: list[Effect] = []
    claimed: list[Candidate] = []  # the best member of each claimed group
    _forward(comp, ranked, model, claimed)
    options = _pair(comp, ranked, model)
    if options:  # the pair replaces what the forward selection claimed, which is then tested beyond it
        absorbed = options[0][0][0].significant  # claimed alone before: its fit had taken up part of the partner's residual
        forward = _Claims.of(model, claimed, ranked)
        best: tuple[float, _Claims, Candidate] | None = None
        for option in options:  # partners that fit as well: the claims completed with each, the best by the BIC
            _claim_pair(comp, ranked, model, claimed, absorbed, *option)
            bic = _bic(comp, model, claimed)
            if best is None or bic < best[0]:
                best = bic, _Claims.of(model, claimed, ranked), option[1][0]
        assert best is not None
        bic, pair, partner = best
        pair.restore(model, claimed, ranked)
        if not forward.holds(partner) and forward.model and forward.bic(comp) <= bic:
            forward.restore(model, claimed, ranked)  # the forward selection's claims fit better, each complete
    return Diagnosis(ranked, model, claimed)


def _claim_pair(comp: Comparison, ranked: list[Candidate], model: list[Effect], claimed: list[Candidate], absorbed: bool,
                first: tuple[Candidate, Assessment], second: tuple[Candidate, Assessment],
                alternatives: Sequence[Assessment]) -> None:
    """Claim a pair of :func:`_pair` in place of every claim (``model`` and ``claimed`` replaced, the verdicts reset),
    then the forward selection beyond it (``absorbed``: the pair's lead was claimed alone before, see :func:`_together`)."""
    (lead1, a), (lead2, b) = first, second
    model.clear()
    claimed.clear()
    for c in ranked:
        c.significant, c.beyond, c.explained_by = c.significant_alone, None, []
    for lead, fitted, beyond in ((lead1, a.effect, _together(lead2, a, absorbed)),
                                 (lead2, b.effect, _together(lead1, b, absorbed, alternatives))):
        for c in ranked:
            if c.rank == lead.rank:
                c.significant, c.beyond = True, beyond
        model.append(fitted)
        claimed.append(lead)
    _forward(comp, ranked, model, claimed, done={lead1.rank, lead2.rank})


@dataclass
class _Claims:
    """What :func:`claim`'s forward selection claimed (its ``model``, the ``claimed`` candidates and every candidate's
    verdict), kept to compare with the pair's claims, each complete, and to restore."""

    model: list[Effect]
    claimed: list[Candidate]
    verdicts: list[tuple[bool, dict[str, Any] | None, list[str]]]

    @classmethod
    def of(cls, model: list[Effect], claimed: list[Candidate], ranked: list[Candidate]) -> _Claims:
        return cls(list(model), list(claimed), [(c.significant, c.beyond, list(c.explained_by)) for c in ranked])

    def holds(self, c: Candidate) -> bool:
        return any(x is c for x in self.claimed)

    def bic(self, comp: Comparison) -> float:
        return _bic(comp, self.model, self.claimed)

    def restore(self, model: list[Effect], claimed: list[Candidate], ranked: list[Candidate]) -> None:
        model[:], claimed[:] = self.model, self.claimed
        for c, (significant, beyond, explained_by) in zip(ranked, self.verdicts, strict=True):
            c.significant, c.beyond, c.explained_by = significant, beyond, explained_by


def _bic(comp: Comparison, model: list[Effect], claimed: list[Candidate]) -> float:
    """The claims' chi-square (``model``, the fits of the ``claimed`` candidates) plus ln(n) per fitted parameter."""
    r = comp.residuals(model)
    return float(r @ r) + sum(len(c.params) for c in claimed) * math.log(r.size)


def _forward(comp: Comparison, ranked: list[Candidate], model: list[Effect], claimed: list[Candidate],
             done: Collection[int] = ()) -> None:
    """:func:`claim`'s forward selection over the groups not in ``done``, on top of ``model`` (the fits of the
    ``claimed`` candidates), both extended in place; repeated over the unclaimed groups judged (or passed over) before a
    pass's last claim, in that pass or an earlier one, beyond the model that claim completed, until a pass claims nothing
    (hot pixels at p 1.4e-6 beside a PRNU and a DSNU, tested before the column offsets joined them; hot pixels judged
    beyond a DSNU in the first pass, before the second claimed the PRNU)."""
    done = set(done)
    while stale := _forward_pass(comp, ranked, model, claimed, done):
        done = {c.rank for c in ranked} - stale


def _forward_pass(comp: Comparison, ranked: list[Candidate], model: list[Effect], claimed: list[Candidate],
                  done: Collection[int]) -> set[int]:
    """One pass of :func:`_forward`; the unclaimed groups judged before its last claim (in ``done``: in an earlier pass)."""
    n_params = sum(len(c.params) for c in claimed)
    given: Given | None = None
    r = comp.residuals([])
    chi_base = float(r @ r)
    held = {c.rank for c in claimed}
    waiting = {rank for rank in done if rank not in held}  # groups left unclaimed since the last claim
    stale: set[int] = set()
    for rank, members in itertools.groupby(ranked, key=lambda c: c.rank):
        group = list(members)
        lead = group[0]
        if rank in done:
            continue
        waiting.add(rank)
        if model and given is None:
            given = Given.of(comp, model, n_params)
        if given is None:  # alone
            if lead.fitted is None or not lead.significant:
                continue
            fitted = lead.fitted
        else:  # beyond the claimed model
            tried = _refit_group(comp, group, given, chi_base)
            if not tried or not (tried[-1][1].significant or lead.significant):
                continue  # nothing alone, nothing beyond: not reported as refitted
            beyond = {id(m): _beyond(claimed, a, alone=lead.significant) for m, a in tried}
            lead, a = tried[-1]
            parted = a.significant and len(tried) > 1  # alike alone; beyond the claims only ``lead`` is significant
            for c in group:  # a group claimed whole, or each member by its own refit (else the first one's)
                c.significant = a.significant and (c is lead or not parted)
                c.beyond = beyond[id(lead)] if a.significant and not parted else beyond.get(id(c), beyond[id(tried[0][0])])
                c.explained_by = [] if c.significant else c.beyond["given"]
            if not a.significant:
                continue
            if parted:
                _part(group, lead, beyond[id(lead)], [m for m, _ in tried[:-1]])
            fitted = a.effect
        model.append(fitted)
        claimed.append(lead)
        n_params += len(lead.params)
        given = None
        waiting.discard(rank)
        stale |= waiting
        waiting = set()
    return stale


def _refit_group(comp: Comparison, group: list[Candidate], given: Given, chi_base: float
                 ) -> list[tuple[Candidate, Assessment]]:
    """A group refitted beyond the ``given`` claimed model: its members in turn (grouped by their fits alone, which
    beyond the claims can part: hot pixels at the limit of their fraction standing for a DSNU alone, 0.1 % at 1000 x
    the dark current beyond a PRNU) until one is significant; each member refitted and its assessment (the last one
    significant, if any). A member whose fit found nothing alone (significant neither alone nor by :func:`_masked_p`),
    or one a direct observation contradicts, is not refitted."""
    tried = []
    for m in group:
        masked = not m.contradicted and _masked_p(m, chi_base, given) < MASKED_P
        if m.fitted is None or not (m.significant or masked):
            continue
        tried.append((m, assess(comp, given, EffectSpec.fit_all(type(m.fitted)))))
        if tried[-1][1].significant:
            break
    return tried


def _part(group: list[Candidate], claimed: Candidate, beyond: dict[str, Any], refitted: Sequence[Candidate]) -> None:
    """A group whose fits alone the data could not tell apart, of which beyond the claims only ``claimed`` is
    significant (``beyond``: its refit; ``refitted``: the members refitted before it, none significant): no longer
    alternatives, and its reading says so, naming as not significant beyond only the members refitted."""
    others = [c for c in group if c is not claimed]
    for c in group:
        c.equivalent_to, c.indistinguishable = [], ""
    was_refitted = {id(r) for r in refitted}
    tried = [c.effect for c in others if id(c) in was_refitted]
    untried = [c.effect for c in others if id(c) not in was_refitted]
    reading = f"; alone indistinguishable from {', '.join(c.effect for c in others)}, "
    if not untried:
        reading += f"which {_is(tried)} not significant beyond"
    else:
        reading += (f"of which {', '.join(tried)} {_is(tried)} not significant beyond and {', '.join(untried)}"
                    f" {'was' if len(untried) == 1 else 'were'} not refitted")
    beyond["reading"] += reading


def _is(names: Sequence[str]) -> str:
    return "is" if len(names) == 1 else "are"


def _masked_p(lead: Candidate, chi_base: float, given: Given) -> float:
    """The F-test p-value of a candidate's chi-square drop alone (from the camera's model's ``chi_base``) against the
    ``given`` model's residual chi-square per degree of freedom instead of its own: the residual the claimed effects
    explain would dilute it."""
    return _f_test(chi_base - lead.chi2, max(len(lead.params), 1), given.chi2, given)


def _pair(comp: Comparison, ranked: list[Candidate], model: Sequence[Effect] = ()
          ) -> list[tuple[tuple[Candidate, Assessment], tuple[Candidate, Assessment], list[Assessment]]]:
    """Two candidates claimed together: the best group lead whose fit alone passed the F-test and the explained
    fraction (the forward selection's ``model`` fitted; if it claimed that lead, the partners are only the
    leads whose fit alone passed them too, one it claimed beside the lead only if the joint fit moves the lead by more
    than :data:`MIN_PAIR_MOVE` of its standard errors), and the other group lead that (past
    :data:`PAIR_SCREEN`), fitted jointly with it
    (from :data:`PAIR_ROUNDS` rounds of each beyond the other), leaves the smallest chi-square with each significant
    beyond the other's joint fit and the two leaving at most :data:`MAX_PAIR_ERROR` of the model's rms error; each with
    that assessment; then as options too the pairs with the partners that fit as well (within ``EQUIVALENT_CHI2``,
    scaled like the equivalence test), best first, each with the other options' partners as the alternatives these
    data cannot tell from its own (:func:`claim` completes each and keeps the best by the BIC: beside a PRNU, hot
    pixels stretched to the limit of their fraction fit as well as the DSNU they stand for, but leave the real hot
    pixels unexplained). Empty without such a pair, or when the lead's partner is claimed in ``model`` and the pair
    fits no better than the two as ``model`` holds them (otherwise :func:`claim` compares the two sets of claims, each
    complete, by the BIC)."""
    leads = [next(g) for _, g in itertools.groupby(ranked, key=lambda c: c.rank)]
    usable = [(c, c.fitted) for c in leads if c.fitted is not None and not c.contradicted]
    found = [(c, f) for c, f in usable if c.p_value < SIGNIFICANCE_P and c.explained_fraction >= MIN_EXPLAINED_FRACTION]
    if not found:
        return []
    first, fitted = found[0]
    if first.significant:  # claimed alone: its fit may have taken up a partner's residual (a DSNU the PRNU's pattern),
        # a partner whose own fit found something alone too (a partner found only once the lead is bent to make room for
        # it, a PRNU beside telegraph pixels, is not); one claimed beside the lead only if the joint fit moves the lead
        usable = list(found)
    spec = EffectSpec.fit_all(type(fitted))
    on_first = Given.of(comp, [fitted], len(first.params))
    rows0 = comp.cell_table()
    pairs: list[tuple[float, tuple[Candidate, Assessment], tuple[Candidate, Assessment]]] = []
    for other, other_fit in usable:
        if other is first:
            continue
        other_spec = EffectSpec.fit_all(type(other_fit))
        # a screen, least squares from its defaults: the F-test and the explained fraction beyond the first's own fit
        p, explained, _ = _drop(on_first, fit(comp, [other_spec], [fitted], start=[type(other_fit)()]))
        if p >= SIGNIFICANCE_P or explained < MIN_EXPLAINED_FRACTION:
            continue
        b = assess(comp, on_first, other_spec)
        if _share_left(rows0, b.rows) > PAIR_SCREEN:
            continue
        for _ in range(PAIR_ROUNDS):  # alternately, to start the joint fit near its optimum
            a = assess(comp, Given.of(comp, [b.effect], len(other.params)), spec)
            b = assess(comp, Given.of(comp, [a.effect], len(first.params)), other_spec)
        joint = fit(comp, [spec, other_spec], start=[a.effect, b.effect])
        a = assess(comp, Given.of(comp, [joint.effects[1]], len(other.params)), spec)
        b = assess(comp, Given.of(comp, [joint.effects[0]], len(first.params)), other_spec)
        if first.significant and other.significant and _moved(first, a) <= MIN_PAIR_MOVE:
            continue
        if a.significant and b.significant and _share_left(rows0, b.rows) <= MAX_PAIR_ERROR:
            pairs.append((joint.chi2, (first, a), (other, b)))
    if not pairs:
        return []
    pairs.sort(key=lambda p: p[0])
    best, partner = pairs[0][0], pairs[0][2][0]
    if partner.significant:  # claimed beside the lead: against the two as the forward selection fitted them
        r = comp.residuals([e for e in model if e.name in (first.effect, partner.effect)])
        if best >= float(r @ r):
            return []
    limit = best + EQUIVALENT_CHI2 * max(1.0, best / max(on_first.n_obs - len(first.params), 1))
    alike = [p for p in pairs if p[0] <= limit]
    return [(p[1], p[2], [q[2][1] for q in alike if q is not p]) for p in alike]


def _moved(first: Candidate, a: Assessment) -> float:
    """How far (in its standard errors, largest over its parameters) the joint fit ``a`` moves the lead from its fit
    alone."""
    alone, errors = first.params, first.param_errors
    return max((abs(a.fit.values[first.effect][k] - v) / e for k, v in alone.items() if (e := errors.get(k))),
               default=0.0)


def _share_left(rows0: list[dict[str, Any]], rows1: list[dict[str, Any]]) -> float:
    """The share of the model's rms error (``rows0``; net of the measurement's scatter, summed in quadrature over the
    components) that the model with a pair (``rows1``) leaves in the components the pair changes: an error elsewhere
    (hot pixels' outliers beside a PRNU and a DSNU) is no part of what the pair must explain."""
    errors = own_errors(rows0, rows1).values()
    before = math.sqrt(sum(e0**2 for e0, _ in errors))
    return math.sqrt(sum(e1**2 for _, e1 in errors)) / before if before > 0.0 else math.inf


def _together(other: Candidate, a: Assessment, absorbed: bool, alternatives: Sequence[Assessment] = ()
              ) -> dict[str, Any]:
    """:attr:`Candidate.beyond` of a candidate claimed with ``other`` (:func:`_pair`): its fit beyond the other's,
    why the two are fitted jointly (``absorbed``: the lead claimed alone had taken up part of the partner's residual;
    else the two partly cancel), and the ``alternatives`` to it that fit as well beside the other."""
    figures = (f"fitted jointly with it: chi-square {a.chi2_given:.1f} -> {min(a.fit.chi2, a.chi2_given):.1f} "
               f"beyond it, p = {a.p_value:.2g}, {a.explained_fraction:.1%} of what it leaves")
    alt = [b.effect.name for b in alternatives]
    why = ("fitted jointly: alone, the first took up part of the other's residual" if absorbed else
           "not alone (the two partly cancel)")
    reading = (f"claimed together with {other.effect}, {why}: significant beyond it ({figures})"
               + (f"; {', '.join(alt)} would fit as well in its place" if alt else ""))
    return {**_refit(a, [other.effect], reading), "together": True, "absorbed": absorbed,
            "alternatives": [{"effect": b.effect.name, "params": b.fit.values[b.effect.name],
                              "fitted_reading": fitted_reading(b.fit, b.effect)} for b in alternatives]}


def _refit(a: Assessment, given: list[str], reading: str) -> dict[str, Any]:
    """A refit beyond the ``given`` explanations as :attr:`Candidate.beyond` records it, with its plain ``reading``."""
    name = a.effect.name
    return {"effect": name, "given": given, "significant": a.significant, "chi2_given": round(a.chi2_given, 3),
            "chi2": round(a.fit.chi2, 3), "p_value": a.p_value, "explained_fraction": round(a.explained_fraction, 6),
            "params": a.fit.values[name], "param_errors": a.fit.errors[name],
            "degenerate": (a.fit.degenerate or {}).get(name, []),
            "param_ranges": {k: list(v) for k, v in (a.fit.ranges or {}).get(name, {}).items()},
            "within_scatter": a.within_scatter, "components": a.components, "contradicted": a.contradicted,
            "failed": a.failed, "reading": reading,
            "fitted_reading": fitted_reading(a.fit, a.effect)}


def _beyond(claimed: Sequence[Candidate], a: Assessment, alone: bool = True) -> dict[str, Any]:
    """A refit on top of the ``claimed`` explanations (each group's best member) for :attr:`Candidate.beyond`,
    with a plain reading (naming each group's alternatives); ``alone``: whether the candidate was
    significant on its own (else it was masked by their residual)."""
    names = [c.effect for c in claimed]
    them, they = ("it", "it leaves") if len(names) == 1 else ("them", "they leave")
    listed = ", ".join(c.effect + (f" (or {', '.join(c.equivalent_to)})" if c.equivalent_to else "") for c in claimed)
    figures = (f"refitted on top of {them}: chi-square {a.chi2_given:.1f} -> {min(a.fit.chi2, a.chi2_given):.1f}, "
               f"p = {a.p_value:.2g}, {a.explained_fraction:.1%} of what {they}"
               + (", a residual within the measurement's scatter" if a.within_scatter else ""))
    if a.significant:
        masked = "" if alone else f", though not alone: {'its' if len(names) == 1 else 'their'} residual masked it"
        reading = f"significant beyond {listed} ({figures}){masked}"
    elif {"F-test", "explained fraction"} & set(a.failed):
        reading = (f"significant alone, but partly reproduces the same residual as {listed}; nothing significant "
                   f"beyond {them} ({figures})")
    else:  # it does explain part of what they leave, but not as an effect of its own
        why = []
        for c, e in a.components.items():
            if "own-component error" in a.failed:
                why.append(f"{c} error {e['rms_error_before_dn']:.3f} -> {e['rms_error_after_dn']:.3f} DN")
            if "position pattern" in a.failed and "position_pattern_left" in e:
                why.append(f"{e['position_pattern_left']:.0%} of the {c} position pattern left")
        if a.contradicted:
            why.append(a.contradicted)
        reading = (f"significant alone; beyond {listed} it lowers the chi-square ({figures}) but fails the "
                   f"{', '.join(a.failed)} test{'s' if len(a.failed) > 1 else ''} ({'; '.join(why)}): not an effect "
                   f"of its own beyond {them}")
    return _refit(a, list(names), reading)


def group_equivalent(comp: Comparison, ranked: list[Candidate]) -> list[Candidate]:
    """Group the candidates (ranked best first) the data cannot tell apart (see the module's docstring):
    each group right after its best member, ranks and significance per group."""
    r0 = comp.residuals()
    resid = {c.effect: comp.residuals([c.fitted]) for c in ranked if c.fitted is not None}

    def distance(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
        d = a - b
        return float(d @ d), float(np.max(np.abs(d))) if d.size else 0.0

    change = {name: distance(r, r0)[0] for name, r in resid.items()}  # chi-square of each fit's change

    # the errors' scale: the best-fitting model's chi2 per degree of freedom, when above 1
    scale = max(1.0, min((c.chi2 / max(r0.size - len(c.params), 1) for c in ranked), default=1.0))
    groups: list[list[Candidate]] = []
    spans: list[tuple[float, float]] = []
    taken: set[str] = set()
    for lead in ranked:
        if lead.effect in taken:
            continue
        taken.add(lead.effect)
        group, worst = [lead], (0.0, 0.0)
        if lead.delta_bic > 0 and change.get(lead.effect, 0.0) > EQUIVALENT_CHI2 * scale:
            for c in ranked:
                if c.effect in taken or c.effect not in resid:
                    continue
                chi2, z = distance(resid[c.effect], resid[lead.effect])
                if (chi2 <= EQUIVALENT_CHI2 * scale and z <= EQUIVALENT_Z * math.sqrt(scale)
                        and change[c.effect] > EQUIVALENT_CHI2 * scale
                        and chi2 <= EQUIVALENT_SHARE**2 * min(change[c.effect], change[lead.effect])):
                    group.append(c)
                    taken.add(c.effect)
                    worst = (max(worst[0], chi2), max(worst[1], z))
        groups.append(group)
        spans.append(worst)
    out: list[Candidate] = []
    for rank, (group, (chi2, z)) in enumerate(zip(groups, spans), start=1):
        text = explain(comp, group, chi2, z) if len(group) > 1 else ""
        for c in group:
            c.rank = rank
            c.equivalent_to = [o.effect for o in group if o is not c]
            c.indistinguishable = text
            c.significant = group[0].significant
        out.extend(group)
    return out


def diagnosis_line(candidates: Sequence[Mapping[str, Any]]) -> str:
    """The diagnosis in one line (from :meth:`Candidate.as_dict` entries, ranked): the best claimed
    explanation, as alternatives when the data cannot tell its candidates apart; then each explanation
    claimed beyond it (as fitted on top of the ones before)."""
    claimed = [c for c in candidates if c["significant"]]
    if not claimed:
        return "no candidate effect is significant"
    best = claimed[0]
    seen = {best["rank"]}
    together = (best.get("beyond") or {}).get("together")
    if together:  # two effects fitted jointly (:func:`_pair`)
        partner = next(c for c in claimed if c["effect"] == best["beyond"]["given"][0])
        seen.add(partner["rank"])
        others = [x["effect"] for x in partner["beyond"]["alternatives"]]
        why = (f"alone, {best['effect']} takes up part of the other's residual" if best["beyond"].get("absorbed") else
               "alone, each is masked by the other")
        line = (f"most likely missing effects, together ({why}): "
                f"{best['beyond']['fitted_reading']}; and {partner['beyond']['fitted_reading']}"
                + (f" (or {', '.join(others)} in its place: these data cannot tell them apart)" if others else ""))
    elif not best.get("equivalent_to"):
        line = f"most likely missing effect: {best['reading']}"
    else:
        n = len(best["equivalent_to"]) + 1
        line = f"most likely missing effect, one of {n} alternatives these data cannot tell apart: {best['indistinguishable']}"
    for c in claimed:
        if c["rank"] in seen:
            continue
        seen.add(c["rank"])
        alt = f" (or {', '.join(c['equivalent_to'])}: these data cannot tell them apart)" if c.get("equivalent_to") else ""
        line = line.rstrip(".") + f"; beyond {'it' if len(seen) == 2 else 'them'}, also missing: {(c.get('beyond') or {}).get('fitted_reading', c['reading'])}{alt}"
    return line
