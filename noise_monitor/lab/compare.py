"""Model vs measurement: the noise model's prediction for the measured cells, residuals in DN, tables.

The model is evaluated with ``NoiseModel.predict`` (joint mode, clip-aware) at every accepted block's
intensity with the segment's metadata (the ADC quantization is added as the temporal variance it
leaves for the noise in front of it, see :func:`quantized_temporal_variance`), split into the measured components (temporal, fixed-pattern
white, column, row) by each effect's ``temporal`` flag and line structure, and averaged per cell like
the measurement. For fitting candidate effects, :meth:`Comparison.predict_with` adds the unclipped
change of variance a set of effects makes (cheap, no new tables) to this clip-aware baseline.
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any, NamedTuple

import numpy as np
from cachetools import LRUCache
from scipy import sparse
from scipy.special import ndtr

from ..physics import CameraMetadata, CameraProfile, Effect, EffectError, NoiseModel, build_effects, make_effect
from ..physics.clipping import DN_MAX
from ..physics.effects import PAPER_EFFECTS
from ..physics.effects import Effect as _Effect
from ..physics.sensor import Conditions, Pixels
from .measure import (
    CONFIRM_SIGMAS,
    CONFIRM_VIEWS,
    OUTLIER_PIXEL_SIGMAS,
    POOLED,
    Cell,
    Measurements,
    SegmentMeasurement,
)
from .quantization import quantized_variance

MEASURED = ("temporal", "fixed", "column", "row", "outlier", "temporal_column", "temporal_row")
#: assumed standard error of the quantization-step measurement beyond its statistical error (DN)
STEP_SYSTEMATIC_DN = 0.05
#: relative systematic error of the measured mean outlier amplitude
AMPLITUDE_SYSTEMATIC = 0.05
#: blocks per cell at which the model is evaluated (evenly spread over the cell's intensities); a cross-view block's
#: model takes its partner views' intensities, which vary from block to block: at 16 a cell's model scattered 8-10 %
#: around its every-block value, noise in the fit's regressor that pulled the fits low (PRNU 1.5 % read 1.489,
#: seed-to-seed spread 0.0049; at 32 1.4955 and 0.0032, as with every block). Measured before each representative
#: took the partner weights and intensities of the blocks it stands for (:class:`Partner`): a cell's model then
#: scattered by up to 2x where the partners' patterns differ 300-fold (seed 1102's DSNU)
MAX_MODEL_BLOCKS = 32
#: half the temperature step (degC) of a fixed pattern's slope with the temperature (:meth:`Views.drift`)
DRIFT_STEP_C = 0.5
#: blocks a region (3 x 3 grid) needs for its contrast to be an observable
MIN_REGION_BLOCKS = 6
#: smallest per-block spread (DN^2) of a regional contrast
MIN_VAR_ERR = 0.01
#: components whose regional contrasts are fitted (where on the sensor the variance sits)
REGIONAL = ("temporal", "fixed")


def component_of(effect: Effect, temporal: bool | None = None) -> str | None:
    """Which measured component an effect's (``temporal`` or fixed-pattern) variance lands in, by its
    structure (None: modifiers and responses, which change the other effects)."""
    if effect.distribution in ("modifier", "response"):
        return None
    temporal = effect.temporal if temporal is None else temporal
    structure = effect.structure
    if structure == "pixel":
        return "temporal" if temporal else "fixed"
    return f"temporal_{structure}" if temporal else structure


def gaussian_fixed(effects: Iterable[Effect]) -> bool:
    """Whether every fixed pattern of a model is Gaussian per pixel: no mixture with a fixed part (hot pixels,
    the frame average of telegraph pixels: a few pixels far off)."""
    return not any(e.distribution == "mixture" and (not e.temporal or type(e).temporal_share is not _Effect.temporal_share)
                   for e in effects)


def is_plain(effect: Effect) -> bool:
    """A Poisson or Gaussian effect the clip-aware tables of ``NoiseModel.predict`` capture exactly:
    position-independent and wholly temporal or wholly fixed."""
    return (effect.distribution in ("poisson", "gaussian") and not effect.spatial
            and type(effect).temporal_share is _Effect.temporal_share)


def baseline_effects(profile: CameraProfile | None, meta: CameraMetadata, integer_output: bool) -> list[Effect]:
    """The camera's model: the paper's sources, the profile's effects and the ADC quantization."""
    effects = [make_effect(n) for n in PAPER_EFFECTS] + build_effects(dict(profile.effects) if profile else None)
    bits = meta.bit_depth or (profile.bit_depth if profile else None) or (8 if integer_output else None)
    if bits and not any(e.distribution == "quantization" for e in effects):
        effects.append(make_effect("quantization", bits=int(bits)))
    return effects


def _conditions(effects: Sequence[Effect], meta: CameraMetadata, position: np.ndarray | None = None) -> Conditions:
    cond = Conditions.from_meta(meta)
    for e in effects:
        if e.distribution == "modifier":
            cond = e.modify(cond)
    return cond if position is None else cond.replace(where=Pixels(position[:, 0], position[:, 1]))


def _slope(effects: Sequence[Effect], cond: Conditions, v: np.ndarray) -> np.ndarray | None:
    """Product of the response effects' slopes at block intensities ``v`` (None: linear)."""
    slopes = [np.asarray(e.at("slope", v, cond), dtype=float) for e in effects if e.distribution == "response"]
    return np.broadcast_to(np.prod(np.broadcast_arrays(*slopes), axis=0), v.shape) if slopes else None


def _linear(effects: Sequence[Effect], cond: Conditions, v: np.ndarray) -> np.ndarray:
    """The linear signal behind block intensities ``v`` (through the response effects, last first)."""
    for e in reversed([e for e in effects if e.distribution == "response"]):
        v = np.asarray(e.linear(v, cond), dtype=float)
    return v


def _detection(effect: Effect, cond: Conditions, v: np.ndarray, sigma: np.ndarray
               ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """A mixture's fixed part as the frame average shows it: (fraction, clipped offset, probability that
    an affected pixel is an outlier (beyond OUTLIER_PIXEL_SIGMAS), probability that it stands beyond
    CONFIRM_SIGMAS with its offset's sign, as a partner view must show it to confirm an outlier)."""
    frac, off = effect.fixed_mixture(v, cond)
    off = np.clip(np.broadcast_to(np.asarray(off, dtype=float), v.shape), -v, DN_MAX - v)
    s = np.maximum(sigma, 1e-6)
    thr = OUTLIER_PIXEL_SIGMAS * s
    return float(frac), off, ndtr((off - thr) / s) + ndtr((-off - thr) / s), ndtr((np.abs(off) - CONFIRM_SIGMAS * s) / s)


def _at_least(q: np.ndarray, need: np.ndarray) -> np.ndarray:
    """Probability that at least ``need`` (per column, 1..CONFIRM_VIEWS) of independent events with
    probabilities ``q`` (slots, n) happen."""
    dist = np.zeros((CONFIRM_VIEWS + 1, q.shape[1]))
    dist[0] = 1.0
    for qj in q:  # distribution of the number of events, the last bin holding CONFIRM_VIEWS or more
        top = dist[-1] + dist[-2] * qj
        dist[1:-1] = dist[1:-1] * (1.0 - qj) + dist[:-2] * qj
        dist[0] = dist[0] * (1.0 - qj)
        dist[-1] = top
    return np.sum(np.where(np.arange(CONFIRM_VIEWS + 1)[:, None] >= need[None, :], dist, 0.0), axis=0)


class Partner(NamedTuple):
    """A partner view of a segment's blocks (see :func:`.measure._cross_views`)."""

    meta: CameraMetadata
    v: np.ndarray  # the blocks' intensities there (of the blocks each stands for, by their weights)
    sigma: np.ndarray  # their robust sigma there
    weight: np.ndarray  # their weight in the cross energies (0: not flat there)
    #: the mean weight of the blocks each stands for (:class:`_SegmentBase`): the model's cross energies (one block's
    #: weight is 0 or up to 1 as the partner is flat and quiet there, and the partners' patterns differ 300-fold)
    cross_weight: np.ndarray
    confirms: np.ndarray  # whether the block there can confirm an outlier pixel


#: keys of the expected outlier pixels per pixel and of their sums of |offset| and of its square (the
#: pixel's noise included) in component dicts
OUTLIER_PIXELS = "outlier_pixels"
OUTLIER_OFFSET = "outlier_offset"
OUTLIER_OFFSET2 = "outlier_offset2"
OUTLIER_KEYS = (OUTLIER_PIXELS, OUTLIER_OFFSET, OUTLIER_OFFSET2)
#: key of the model's own uncertainty of the temporal variance (quantization phase) in component dicts
QUANT_SPREAD = "quantization_spread"
#: key of the fixed component at each representative block as that block's own measurement weighs its partner views,
#: minus the cells' model (which weighs them as the blocks it stands for: :class:`Partner`), in component dicts: a
#: block compared with itself (regional contrasts, position patterns) takes its own weights (at the partner intensities
#: of the blocks it stands for: seed 1142's regional chi-square 165.3 with its own, 166.1 so, 314.1 with the cells')
AT_BLOCK = "fixed_at_block"
#: per-block values in component dicts besides the measured components' variances
EXTRA = (QUANT_SPREAD, *OUTLIER_KEYS, AT_BLOCK)


#: memory the per-effect contributions of :meth:`Views.components` may keep for reuse (bytes, least recently used
#: dropped first): a fit re-evaluates the effects it holds at their values with every change of the one it varies, and
#: later fits the same effects at the same values (scan points, claims)
PARTS_CACHE_BYTES = 64 * 2**20

#: sets of modifier and response effects whose colder and warmer conditions (:meth:`Views._warmer`) are kept
WARMER_KEPT = 16

_Parts = tuple[dict[str, np.ndarray], dict[str, np.ndarray]]
_Warmer = list[tuple[list[Conditions | None], list[np.ndarray]]]


def _effect_key(e: Effect) -> tuple:
    """What an effect's model contributions depend on: its class and parameter values."""
    return type(e), tuple(e.values.items())


def _bending(effects: Sequence[Effect]) -> tuple:
    """The keys of the modifier and response effects among ``effects``, in order: what the conditions and linear
    signals the others are evaluated at depend on."""
    return tuple(_effect_key(e) for e in effects if e.distribution in ("modifier", "response"))


def _nbytes(parts: _Parts) -> float:
    return float(sum(np.asarray(a).nbytes for d in parts for a in d.values()))


def _keep(kept: LRUCache, key: tuple, value: Any) -> None:
    """``kept[key] = value``, unless the value alone is larger than the cache may hold (then it is not kept)."""
    try:
        kept[key] = value
    except ValueError:
        pass


class Views:
    """Every view the model is evaluated in, grouped by metadata: each segment's representative blocks in
    its own view (its metadata, the block intensities ``v``, their robust sigma and positions) and in its
    partner views (another segment's metadata, the blocks' intensities and robust sigmas there; see
    :func:`.measure._cross_views`). An effect is evaluated in one call per metadata over all the views
    that share it, instead of one per segment and partner; the per-block results are gathered back.

    Component arrays run over the segments' own blocks, concatenated in segment order (``bounds``).
    """

    def __init__(self, segments: Sequence[tuple[CameraMetadata, np.ndarray, np.ndarray, np.ndarray,
                                                Sequence[Partner]]],
                 drift: Sequence[tuple[float, int]] = ()) -> None:
        """``segments``: per segment (metadata, v, sigma, positions (B, 2), partners); ``drift``: per segment (the
        variance of its frames' sensor temperatures, degC^2, and its number of frames), for :meth:`drift` (none
        without)."""
        group_of: dict[int, int] = {}
        self.metas: list[CameraMetadata] = []
        chunks: list[list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = []
        placed: list[tuple[int, int, int]] = []  # (group, start in group, size) per view, in placing order

        def place(meta: CameraMetadata, v: np.ndarray, sigma: np.ndarray, pos: np.ndarray) -> int:
            g = group_of.setdefault(id(meta), len(self.metas))
            if g == len(self.metas):
                self.metas.append(meta)
                chunks.append([])
            placed.append((g, sum(c[0].size for c in chunks[g]), v.size))
            chunks[g].append((np.asarray(v, dtype=float), np.asarray(sigma, dtype=float), pos))
            return len(placed) - 1

        own = [place(m, v, s, pos) for m, v, s, pos, _ in segments]
        partner = [[place(p.meta, p.v, p.sigma, pos) for p in parts] for _, _, _, pos, parts in segments]
        self.v = [np.concatenate([c[0] for c in ch]) for ch in chunks]
        self.sigma = [np.concatenate([c[1] for c in ch]) for ch in chunks]
        pos = [np.concatenate([c[2] for c in ch]) for ch in chunks]
        starts = np.cumsum([0] + [v.size for v in self.v])

        def index(k: int) -> np.ndarray:
            g, start, size = placed[k]
            return starts[g] + start + np.arange(size)

        sizes = [v.size for _, v, _, _, _ in segments]
        self.bounds = np.cumsum([0] + sizes)
        self.own = np.concatenate([index(k) for k in own]) if own else np.zeros(0, dtype=int)
        self.meta_of_segment = [m for m, _, _, _, _ in segments]
        self.group_of_segment = [placed[k][0] for k in own]
        self.lone = np.repeat([not parts for *_, parts in segments], sizes)  # blocks without partner views
        n_slots = max((len(p) for p in partner), default=0)
        self.partner_index = np.zeros((n_slots, self.own.size), dtype=int)
        self.partner_cross_weight = np.zeros((n_slots, self.own.size))
        self.partner_valid = np.zeros((n_slots, self.own.size), dtype=bool)
        self.partner_confirms = np.zeros((n_slots, self.own.size), dtype=bool)
        self.partner_weight = np.zeros((n_slots, self.own.size))
        for s, (ks, (*_, parts)) in enumerate(zip(partner, segments)):
            sl = slice(self.bounds[s], self.bounds[s + 1])
            for j, (k, part) in enumerate(zip(ks, parts)):
                self.partner_index[j, sl] = index(k)
                self.partner_cross_weight[j, sl] = part.cross_weight
                self.partner_valid[j, sl] = True
                self.partner_confirms[j, sl] = part.confirms & (part.weight > 0)
                self.partner_weight[j, sl] = part.weight
        # outlier pixels need CONFIRM_VIEWS confirming partner views (all of them when fewer are flat there)
        self.confirm_need = np.maximum(np.minimum(CONFIRM_VIEWS, np.sum(self.partner_weight > 0, axis=0)), 1)
        self.base_conds = [Conditions.from_meta(m).replace(where=Pixels(p[:, 0], p[:, 1])) for m, p in zip(self.metas, pos)]
        self._pos = pos
        self.temperature_var = np.repeat([d[0] for d in drift], sizes) if drift else np.zeros(self.own.size)
        self.hold_frames = np.repeat([max(d[1], 1) for d in drift], sizes) if drift else np.ones(self.own.size)
        self._warmer_kept: LRUCache[tuple, _Warmer] = LRUCache(WARMER_KEPT)
        self._parts: LRUCache[tuple, _Parts] = LRUCache(PARTS_CACHE_BYTES, getsizeof=_nbytes)

    def split(self, arrays: dict[str, np.ndarray]) -> list[dict[str, np.ndarray]]:
        """Per segment: its part of the component arrays."""
        return [{c: a[lo:hi] for c, a in arrays.items()} for lo, hi in zip(self.bounds[:-1], self.bounds[1:])]

    def components(self, effects: Sequence[Effect], span: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Unclipped variance (DN^2) per measured component at every segment's blocks (concatenated).

        Each effect's variance is split by its ``temporal_share`` into a temporal and a fixed-pattern part and
        lands in the components of its ``structure``. The fixed part of a mixture (hot pixels) goes to
        "outlier" where its offset stands out of the block's noise ``sigma`` (robust, DN) and to the white
        fixed-pattern core elsewhere; its offsets are clipped. The mixture's expected outlier pixels (per
        pixel) and their sums of |offset| and squared offset are returned under OUTLIER_KEYS (detected
        and confirmed by partner views as the measurement requires). Response effects scale everything by their
        slope squared. Quantization acts on the temporal noise at each block's level ``v`` over its range
        of levels ``span`` (DN; None: phase-averaged).
        For segments with partner views (cross-view measurement) the fixed-pattern parts (fixed, column, row)
        are the weighted products of each effect's fixed sigma (slope included) here and in the partner
        views, which see the same sensor blocks (same positions) at other intensities; the quantization's
        fixed part, a pattern of the scene's levels, moves with the scene and cancels.
        An effect's contributions are computed once for its values and the modifier and response effects beside it
        (kept within :data:`PARTS_CACHE_BYTES`).
        """
        bending = _bending(effects)
        if bending:
            conds = [_conditions(effects, m, p) for m, p in zip(self.metas, self._pos)]
            lins = [_linear(effects, c, v) for c, v in zip(conds, self.v)]
            slopes = [_slope(effects, c, v) for c, v in zip(conds, self.v)]
        else:
            conds, lins, slopes = self.base_conds, self.v, [None] * len(self.v)
        slope_all = None if not slopes or slopes[0] is None else np.concatenate([x for x in slopes if x is not None])
        slope = None if slope_all is None else slope_all[self.own]
        n = self.own.size
        out = {c: np.zeros(n) for c in MEASURED + OUTLIER_KEYS}
        cross = {c: np.zeros(n) for c in (*MEASURED, AT_BLOCK)}  # cross-view parts, slopes already applied
        for e in effects:
            if component_of(e) is None or e.distribution == "quantization":
                continue
            key = (_effect_key(e), bending)
            parts = self._parts.get(key)
            if parts is None:
                parts = self._effect_parts(e, conds, lins, slope_all)
                for c, a in self._effect_drift(e, effects, bending).items():
                    parts[0][c] = parts[0].get(c, 0.0) + a
                _keep(self._parts, key, parts)
            part, part_cross = parts
            for c, a in part.items():
                out[c] = out[c] + a
            for c, a in part_cross.items():
                cross[c] = cross[c] + a
        counts = {c: out[c] for c in OUTLIER_KEYS}
        if slope is not None:
            out = {c: a * slope**2 for c, a in out.items()}
        out = {c: out[c] + cross[c] for c in MEASURED} | counts | {AT_BLOCK: cross[AT_BLOCK]}
        own_conds = [conds[g] for g in self.group_of_segment]
        added, fixed, spread = self._quantization(effects, own_conds, out["temporal"], span)
        out["temporal"] = out["temporal"] + added
        out["fixed"] = out["fixed"] + np.where(self.lone, fixed, 0.0)
        out[QUANT_SPREAD] = spread
        return out

    def drift(self, effects: Sequence[Effect]) -> dict[str, np.ndarray]:
        """Per component, over the segments' own blocks: what the fixed patterns of ``effects`` whose size follows the
        sensor temperature (a DSNU) add to the temporal noise of holds whose temperature moved from frame to frame and
        take from a single view's fixed component (:meth:`_effect_drift`), response slopes included."""
        out: dict[str, np.ndarray] = {}
        bending = _bending(effects)
        for e in effects:
            for c, a in self._effect_drift(e, effects, bending).items():
                out[c] = out.get(c, 0.0) + a
        if out and any(e.distribution == "response" for e in effects):
            conds = [_conditions(effects, m, p) for m, p in zip(self.metas, self._pos)]
            slopes = [(_slope(effects, c, v), v) for c, v in zip(conds, self.v)]
            slope = np.concatenate([np.ones(v.shape) if sl is None else sl for sl, v in slopes])
            out = {c: a * slope[self.own] ** 2 for c, a in out.items()}
        return out

    def _effect_drift(self, e: Effect, effects: Sequence[Effect], bending: tuple) -> dict[str, np.ndarray]:
        """One effect's part of :meth:`drift` (before the response slope): a fixed pattern whose size ``a`` follows the
        temperature changes between a hold's frames by its slope ``da/dT`` (central difference over +-DRIFT_STEP_C in
        the conditions ``effects`` make) times the frames' temperature deviations: ``(da/dT)^2`` times their variance
        in the temporal component of its structure, and ``/ k`` less in a single view's fixed component (measured as
        the hold mean's minus temporal / k); across views the hold means' cross energy holds none of it. Linear over a
        hold (``SegmentTolerance``: within 3 degC). Nothing for temporal effects and mixtures (hot pixels: a few
        pixels far off, left out of the temporal noise as blinking when they move much)."""
        if (component_of(e) is None or e.distribution in ("mixture", "quantization")
                or (e.temporal and type(e).temporal_share is _Effect.temporal_share)
                or not np.any(self.temperature_var > 0.0)):
            return {}
        size = []
        for conds, lins in self._warmer(effects, bending):
            size.append(np.concatenate([
                np.sqrt(np.maximum((1.0 - _temporal_share(e, lin, c, lin.shape)) * e.variance_dn2(lin, c), 0.0))
                if c is not None else np.zeros(lin.shape) for c, lin in zip(conds, lins)])[self.own])
        var = ((size[1] - size[0]) / (2.0 * DRIFT_STEP_C)) ** 2 * self.temperature_var
        return {str(component_of(e, True)): var,
                str(component_of(e, False)): -np.where(self.lone, var / self.hold_frames, 0.0)}

    def _warmer(self, effects: Sequence[Effect], bending: tuple) -> _Warmer:
        """The conditions (None for a group with no segment's own view) and linear signals of every metadata group
        DRIFT_STEP_C colder and warmer, computed once for each of the last WARMER_KEPT sets of modifier and response
        effects (``bending``, :func:`_bending`: all they depend on)."""
        kept = self._warmer_kept.get(bending)
        if kept is not None:
            return kept
        own = set(self.group_of_segment)
        out: _Warmer = []
        for step in (-DRIFT_STEP_C, DRIFT_STEP_C):
            conds = [_conditions(effects, m.replace(sensor_temperature_c=m.sensor_temperature_c + step), p)
                     if g in own else None for g, (m, p) in enumerate(zip(self.metas, self._pos))]
            out.append((conds, [_linear(effects, c, v) if c is not None else v for c, v in zip(conds, self.v)]))
        self._warmer_kept[bending] = out
        return out

    def _effect_parts(self, e: Effect, conds: Sequence[Conditions], lins: Sequence[np.ndarray],
                      slope_all: np.ndarray | None) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        """One effect's (single-view, cross-view) variance contributions per component, see
        :meth:`components` (single-view parts before the response slope)."""
        shares, variances, detected, visible, offsets, fracs = [], [], [], [], [], []
        for cond, lin, v, sigma in zip(conds, lins, self.v, self.sigma):
            shares.append(_temporal_share(e, lin, cond, v.shape))
            if e.distribution == "mixture":
                variances.append(_mixture_var(e, cond, lin, v))
                frac, off, p_out, p_beyond = _detection(e, cond, v, sigma)
                detected.append(p_out)
                visible.append(p_beyond)
                offsets.append(np.abs(off))
                fracs.append(np.full(v.shape, frac))
            else:
                variances.append(np.broadcast_to(np.asarray(e.variance_dn2(lin, cond), dtype=float), v.shape))
        share_all, var_all = np.concatenate(shares), np.concatenate(variances)
        share, var = share_all[self.own], var_all[self.own]
        comp_t, comp_f = str(component_of(e, True)), str(component_of(e, False))
        out: dict[str, np.ndarray] = {}
        if detected:
            p = np.concatenate(detected)[self.own]
            if self.partner_index.size:  # confirmed by partner views (where there are any)
                q = np.concatenate(visible)[self.partner_index] * self.partner_confirms
                p = p * np.where(self.lone, 1.0, _at_least(q, self.confirm_need))
            fixed_var = (1.0 - share) * var
            # detected pixels the partner views do not confirm leave the measurement (neither outlier nor core)
            out["outlier"] = fixed_var * p
            out[OUTLIER_PIXELS] = np.concatenate(fracs)[self.own] * p
            off = np.concatenate(offsets)[self.own]
            out[OUTLIER_OFFSET] = out[OUTLIER_PIXELS] * off
            out[OUTLIER_OFFSET2] = out[OUTLIER_PIXELS] * (off**2 + np.concatenate(self.sigma)[self.own] ** 2)
            core = fixed_var * (1.0 - np.concatenate(detected)[self.own])
        else:
            core = (1.0 - share) * var
        out[comp_t] = share * var
        out[comp_f] = np.where(self.lone, core, 0.0)  # with partner views: the cross-view part instead
        if not self.partner_index.size:
            return out, {}
        # each view's fixed sigma (slope included); a mixture's affected pixel adds to the cross energy
        # only where neither view took it out as an outlier pixel (independent noise: (1 - p_here) x
        # (1 - p_there), not the square root of that product the two single-view cores would give)
        kept = 1.0 - np.concatenate(detected) if detected else 1.0
        there_all = np.sqrt(np.maximum((1.0 - share_all) * var_all, 0.0)) * kept
        if slope_all is not None:
            there_all = there_all * slope_all
        here = there_all[self.own]
        acc, own = np.zeros(here.shape), np.zeros(here.shape)
        for idx, w, w_own, valid in zip(self.partner_index, self.partner_cross_weight, self.partner_weight,
                                        self.partner_valid):
            prod = np.where(valid, here * there_all[idx], 0.0)
            acc, own = acc + w * prod, own + w_own * prod
        return out, {comp_f: acc} | ({AT_BLOCK: own - acc} if comp_f == "fixed" else {})

    def _quantization(self, effects: Sequence[Effect], conds: Sequence[Conditions], temporal_var: np.ndarray,
                      span: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:func:`quantization_variance` for every segment (its own conditions' step) in one call per step."""
        lsb = np.repeat([max((e.lsb_dn(c) for e in effects if e.distribution == "quantization"), default=0.0)
                         for c in conds], np.diff(self.bounds))
        added, fixed, spread = (np.zeros(temporal_var.shape) for _ in range(3))
        level = np.concatenate(self.v)[self.own] if span is not None else None
        for step in np.unique(lsb[lsb > 0.0]):
            m = lsb == step
            a, f, s = quantization_variance_at(float(step), temporal_var[m], None if level is None else level[m],
                                               None if span is None else span[m])
            added[m], fixed[m], spread[m] = a, f, s
        return added, fixed, spread


def _temporal_share(effect: Effect, lin: np.ndarray, cond: Conditions, shape: tuple[int, ...]) -> np.ndarray:
    """The share of an effect's variance that is temporal at linear signals ``lin`` (0..1, broadcast to ``shape``)."""
    return np.broadcast_to(np.clip(np.asarray(effect.temporal_share(lin, cond), dtype=float), 0.0, 1.0), shape)


def _mixture_var(effect: Effect, cond: Conditions, lin: np.ndarray, v: np.ndarray) -> np.ndarray:
    """A mixture's variance at linear signal ``lin`` (block intensities ``v``), offsets clipped."""
    frac, off = effect.mixture(lin, cond)
    off = np.clip(np.broadcast_to(np.asarray(off, dtype=float), v.shape), -v, DN_MAX - v)
    return frac * (1.0 - frac) * off**2



def quantization_variance(effects: Sequence[Effect], cond: Conditions, temporal_var: np.ndarray,
                          level_dn: np.ndarray | None = None,
                          span_dn: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(added temporal variance, added fixed-pattern variance, the model's spread of the temporal part)
    in DN^2 of the coarsest quantization step acting on temporal noise of variance ``temporal_var``
    (see :mod:`.quantization`)."""
    lsb = max((e.lsb_dn(cond) for e in effects if e.distribution == "quantization"), default=0.0)
    return quantization_variance_at(lsb, temporal_var, level_dn, span_dn)


def quantization_variance_at(lsb: float, temporal_var: np.ndarray, level_dn: np.ndarray | None = None,
                             span_dn: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`quantization_variance` of a quantization step ``lsb`` (DN; 0: none)."""
    if lsb <= 0.0:
        zero = np.zeros_like(temporal_var)
        return zero, zero, zero
    # fits of fixed-pattern candidates leave the temporal noise unchanged: reuse the last results
    key = (lsb, temporal_var.tobytes(), None if level_dn is None else level_dn.tobytes(),
           None if span_dn is None else np.asarray(span_dn).tobytes())
    if key not in _QUANT_CACHE:
        if len(_QUANT_CACHE) > 1024:
            _QUANT_CACHE.clear()
        _QUANT_CACHE[key] = quantized_variance(np.sqrt(np.maximum(temporal_var, 0.0)), lsb, level_dn, span_dn)
    return _QUANT_CACHE[key]


_QUANT_CACHE: dict[tuple, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}


def predicted_step(effects: Sequence[Effect], meta: CameraMetadata, output_step: float) -> float:
    """Median gap between occupied output levels that the model's quantization produces."""
    lsbs = [e.lsb_dn(Conditions.from_meta(meta)) for e in effects if e.distribution == "quantization"]
    lsb = max(lsbs, default=0.0)
    if output_step <= 0.0:
        return lsb
    if lsb <= output_step:
        return output_step
    levels = np.unique(np.rint(np.arange(0.0, 255.0 + lsb, lsb) / output_step))
    return float(np.median(np.diff(levels))) * output_step


def model_curve(effects: Sequence[Effect], meta: CameraMetadata, v: np.ndarray) -> np.ndarray:
    """Model total sigma (DN) at intensities ``v``: clip-aware ``predict`` plus the quantization."""
    v = np.asarray(v, dtype=float)
    clip_model = NoiseModel([e for e in effects if e.distribution != "quantization"])
    pred = clip_model.predict(v, meta)
    temporal = np.zeros(v.shape) + sum(np.asarray(pred[e.name]) ** 2 for e in clip_model.noise_effects if e.temporal)
    added, fixed, _ = quantization_variance(effects, clip_model.conditions(meta), temporal)
    return np.sqrt(np.maximum(np.asarray(pred["total"]) ** 2 + added + fixed, 0.0))


class _SegmentBase:
    """A segment's cells and the representative blocks the model is evaluated at: up to
    ``MAX_MODEL_BLOCKS`` per cell, evenly spread over the cell's block intensities (weights: blocks
    represented; ``members``: per representative block, the cell's blocks it stands for, nearest in intensity)."""

    def __init__(self, seg: SegmentMeasurement, cells: list[Cell]) -> None:
        self.seg, self.cells = seg, cells
        picks, weights = [], []
        self.members: list[np.ndarray] = []
        self.average = np.zeros((len(cells), sum(min(c.block_index.size, MAX_MODEL_BLOCKS) for c in cells)))
        start = 0
        for i, c in enumerate(cells):
            idx = c.block_index[np.argsort(seg.intensity_dn[c.block_index], kind="stable")]
            at = np.unique(np.rint(np.linspace(0, idx.size - 1, min(idx.size, MAX_MODEL_BLOCKS))).astype(int))
            pick = idx[at]
            edges = np.r_[0, (at[1:] + at[:-1] + 1) // 2, idx.size]
            self.members += [idx[a:b] for a, b in zip(edges[:-1], edges[1:])]
            picks.append(pick)
            weights.append(np.full(pick.size, idx.size / pick.size))
            self.average[i, start:start + pick.size] = 1.0 / pick.size
            start += pick.size
        self.average = self.average[:, :start]
        rep = np.concatenate(picks)
        self.rep = rep
        self.weights = np.concatenate(weights)
        self.v, self.sigma, self.pos = seg.intensity_dn[rep], seg.robust_sigma_dn[rep], seg.position[rep]
        # range of clean levels in a block: its gradient plus the measured spread beyond temporal noise
        spread = np.zeros(rep.size)
        if "temporal" in seg.values:
            spread = np.sqrt(np.maximum(self.sigma**2 - seg.values["temporal"][rep] / seg.n_frames, 0.0))
        self.span = seg.span_dn[rep] + 2.0 * spread
        self.clip_aware: dict[str, np.ndarray] = {}
        # per-cell observables; line offsets are pooled per segment (one observable each); the sparse
        # outlier energy is fitted through the outlier count and amplitude instead
        self.observed = tuple(k for k in cells[0].values if k not in POOLED)
        self.values = np.array([[c.values[k] for k in self.observed] for c in cells])
        self.errors = np.maximum(np.array([[c.errors[k] for k in self.observed] for c in cells]), 1e-9)
        self.pooled = tuple(k for k in cells[0].values if k in POOLED and k != "outlier")
        self.pooled_values = np.array([cells[0].values[k] for k in self.pooled])
        self.pooled_errors = np.maximum(np.array([cells[0].errors[k] for k in self.pooled]), 1e-9)
        self.pixels_per_block = seg.pixels_checked // max(1, seg.intensity_dn.size)
        # regional contrasts: mean block excess (measured - model) per region minus the segment's mean
        regions = seg.region[rep]
        self.regions = [np.flatnonzero(regions == k) for k in np.unique(regions)]
        self.regions = [idx for idx in self.regions if idx.size >= MIN_REGION_BLOCKS] if len(self.regions) > 1 else []
        # a single view that shows the scene: its fixed pattern's regions differ by the scene's texture there
        self.regional = tuple(k for k in REGIONAL if k in seg.values and not (k == "fixed" and seg.scene_dn2 is not None))

        self.region_errors: dict[str, list[float]] = {}
        self.partners: list[Partner] = []

    def set_region_errors(self, comps: dict[str, np.ndarray]) -> None:
        """Standard errors of the regional contrasts (a region's mean block excess over the baseline model
        ``comps`` minus the segment's), from the spread of the blocks' excess inside the region and outside
        it (a sparse effect, e.g. a hot pixel no view took out, lifts a few blocks elsewhere and with them
        the segment's mean); fixed once, so a fit cannot widen its own errors."""
        n_all = self.rep.size
        for k in self.regional:
            x = self.seg.values[k][self.rep] - at_block(comps, k)
            floor = max(float(np.median(np.abs(comps[k]))) * 0.01, MIN_VAR_ERR)
            errs = []
            for idx in self.regions:
                out = np.delete(x, idx)
                s_in = max(float(x[idx].std(ddof=1)), floor)
                s_out = max(float(out.std(ddof=1)), floor) if out.size > 1 else s_in
                n = idx.size  # contrast = (1/n - 1/N) sum(inside) - (1/N) sum(outside)
                errs.append(math.sqrt((1.0 / n - 1.0 / n_all) ** 2 * n * s_in**2 + out.size * s_out**2 / n_all**2))
            self.region_errors[k] = errs

    def set_partners(self, metas: Sequence[CameraMetadata]) -> None:
        """Partner views (cross-view fixed pattern) of the representative blocks; ``metas``: every
        segment's metadata by index."""
        seg = self.seg
        if seg.partner_weight is not None:
            # recorded together with the weights
            assert seg.partner_intensity_dn is not None and seg.partner_sigma_dn is not None
            assert seg.partner_confirms is not None
            rep = self.rep
            # the blocks each stands for: their mean weights, and their intensities there by weight (a block not flat
            # there, its weight 0, may be clipped or on an edge there)
            w = [seg.partner_weight[m] for m in self.members]
            cross = np.stack([x.mean(axis=0) for x in w])
            total = np.stack([x.sum(axis=0) for x in w])
            there = np.stack([np.sum(x * seg.partner_intensity_dn[m], axis=0) for x, m in zip(w, self.members)])
            v = np.where(total > 0.0, there / np.maximum(total, 1e-300), seg.partner_intensity_dn[rep])
            self.partners = [Partner(metas[p], v[:, j], seg.partner_sigma_dn[rep, j], seg.partner_weight[rep, j],
                                     cross[:, j], seg.partner_confirms[rep, j])
                             for j, p in enumerate(seg.partners)]


def _pooled(x: np.ndarray, weights: np.ndarray) -> float:
    return float(np.sum(x * weights) / np.sum(weights))


def as_measured(sb: _SegmentBase, comps: dict[str, np.ndarray], comp: str) -> np.ndarray:
    """A model component as the segment measures it: a single frame cannot tell temporal from fixed."""
    if comp == "single":
        return comps["temporal"] + comps["fixed"]
    if "temporal" in sb.seg.values:
        return comps[comp]
    if comp in ("column", "row"):
        return comps[comp] + comps[f"temporal_{comp}"]
    return comps[comp]


def at_block(comps: dict[str, np.ndarray], comp: str) -> np.ndarray:
    """A component's model at each representative block as that block's own measurement weighs its partner views
    (:data:`AT_BLOCK`): what a block is compared with on its own."""
    return comps[comp] + comps[AT_BLOCK] if comp == "fixed" else comps[comp]


def _cell_values(sb: _SegmentBase, comps: dict[str, np.ndarray], comp: str) -> np.ndarray:
    if comp in ("temporal_column", "temporal_row") and "temporal" not in sb.seg.values:
        return np.zeros(sb.average.shape[0])
    if comp in POOLED:
        return np.full(sb.average.shape[0], _pooled(as_measured(sb, comps, comp), sb.weights))
    return sb.average @ as_measured(sb, comps, comp)


class Observables:
    """Every segment's observables in one set of arrays, so that a model's residuals take a few vectorised
    steps over all segments: cell averages, pooled line offsets and regional contrasts as sparse matrices
    over the segments' representative blocks (concatenated in segment order), and the order in which
    :meth:`Comparison.residuals` lists them (per segment: cell variances, their likelihood terms, pooled
    offsets, regional contrasts, outlier count, amplitude and its likelihood term)."""

    def __init__(self, segments: Sequence[_SegmentBase]) -> None:
        self.comps = sorted({k for sb in segments for k in sb.observed + sb.pooled})
        col = {k: i for i, k in enumerate(self.comps)}
        sizes = [sb.v.size for sb in segments]
        n_cells = [len(sb.cells) for sb in segments]
        no_temporal = np.array(["temporal" not in sb.seg.values for sb in segments], dtype=bool)
        self.no_temporal_block = np.repeat(no_temporal, sizes)
        self.no_temporal_cell = np.repeat(no_temporal, n_cells)
        self.average = sparse.block_diag([sb.average for sb in segments], format="csr")
        self.pooling = sparse.block_diag([(sb.weights / np.sum(sb.weights))[None, :] for sb in segments], format="csr")
        #: per segment, the sum over its blocks of per-pixel values times the pixels each block stands for
        self.totals = sparse.block_diag([(sb.pixels_per_block * sb.weights)[None, :] for sb in segments], format="csr")
        cell0, block0 = np.cumsum([0] + n_cells), np.cumsum([0] + sizes)
        n_entries = sum(len(sb.cells) * len(sb.observed) for sb in segments)
        n_pooled = sum(len(sb.pooled) for sb in segments)
        n_regional = sum(len(sb.regional) * len(sb.regions) for sb in segments)
        cell_idx: list[np.ndarray] = []
        comp_idx: list[np.ndarray] = []
        values: list[np.ndarray] = []
        errors: list[np.ndarray] = []
        order: list[np.ndarray] = []
        pooled_seg: list[int] = []
        pooled_comp: list[int] = []
        region_comp: list[int] = []
        region_row: list[int] = []
        region_err: list[float] = []
        rows: list[int] = []  # regional contrast matrix: region mean minus its segment's mean
        cols: list[int] = []
        vals: list[float] = []
        c = p = r = n_regions = 0
        for s, sb in enumerate(segments):
            nc, no = len(sb.cells), len(sb.observed)
            cell_idx.append(np.repeat(cell0[s] + np.arange(nc), no))
            comp_idx.append(np.tile([col[k] for k in sb.observed], nc))
            values.append(sb.values.ravel())
            errors.append(sb.errors.ravel())
            pooled_seg.extend([s] * len(sb.pooled))
            pooled_comp.extend(col[k] for k in sb.pooled)
            first = n_regions
            n_regions += len(sb.regions)
            blocks = block0[s] + np.arange(sizes[s])
            for i, idx in enumerate(sb.regions):
                rows.extend([first + i] * (idx.size + blocks.size))
                cols.extend((block0[s] + idx).tolist() + blocks.tolist())
                vals.extend([1.0 / idx.size] * idx.size + [-1.0 / blocks.size] * blocks.size)
            for k in sb.regional:
                region_comp.extend([REGIONAL.index(k)] * len(sb.regions))
                region_row.extend(range(first, first + len(sb.regions)))
                region_err.extend(sb.region_errors[k])
            nr = len(sb.regional) * len(sb.regions)
            order.extend([np.arange(c, c + nc * no), n_entries + np.arange(c, c + nc * no),
                          2 * n_entries + np.arange(p, p + len(sb.pooled)),
                          2 * n_entries + n_pooled + np.arange(r, r + nr),
                          2 * n_entries + n_pooled + n_regional + 3 * s + np.arange(3)])
            c, p, r = c + nc * no, p + len(sb.pooled), r + nr
        self.cell_idx, self.comp_idx = np.concatenate(cell_idx), np.concatenate(comp_idx)
        self.values, self.errors = np.concatenate(values), np.concatenate(errors)
        self.spread_entry = np.isin(self.comp_idx, [col[k] for k in ("temporal", "single") if k in col])
        self.pooled_seg, self.pooled_comp = np.array(pooled_seg, dtype=np.intp), np.array(pooled_comp, dtype=np.intp)
        self.pooled_values = np.concatenate([sb.pooled_values for sb in segments])
        self.pooled_errors = np.concatenate([sb.pooled_errors for sb in segments])
        self.contrast = sparse.csr_matrix((vals, (rows, cols)), shape=(n_regions, int(block0[-1])))
        self.region_comp, self.region_row = np.array(region_comp, dtype=np.intp), np.array(region_row, dtype=np.intp)
        self.region_err = np.asarray(region_err, dtype=float)
        self.region_measured = [np.concatenate([sb.seg.values[k][sb.rep] if k in sb.seg.values else np.zeros(sb.v.size)
                                                for sb in segments]) for k in REGIONAL]
        self.order = np.concatenate(order)
        self.outlier_pixels = np.array([sb.seg.outlier_pixels for sb in segments], dtype=float)
        #: 0 where a single view's outlier pixels are the scene's specks (not a measurement of the sensor's)
        self.outliers_measured = np.array([sb.seg.outliers_measured for sb in segments], dtype=float)
        self.amplitude = np.array([sb.seg.outlier_amplitude_dn for sb in segments], dtype=float)
        self.amplitude_err = np.maximum(np.hypot([sb.seg.outlier_amplitude_err_dn for sb in segments],
                                                 AMPLITUDE_SYSTEMATIC * self.amplitude), 1e-6)

    def as_measured(self, comps: dict[str, np.ndarray], comp: str) -> np.ndarray:
        """:func:`as_measured` over all segments' blocks."""
        if comp == "single":
            return comps["temporal"] + comps["fixed"]
        if comp in ("column", "row"):
            return comps[comp] + np.where(self.no_temporal_block, comps[f"temporal_{comp}"], 0.0)
        return comps[comp]

    def outliers(self, comps: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per segment: the model's expected outlier pixels, their mean |offset| (DN) and its spread over
        the pixels (DN: the clipped offset differs from block to block, plus the pixel's noise)."""
        count, s1, s2 = (self.totals @ comps[k] for k in OUTLIER_KEYS)
        n = np.maximum(count, 1e-300)
        return count, s1 / n, np.sqrt(np.maximum(s2 / n - (s1 / n) ** 2, 0.0))

    def residuals(self, comps: dict[str, np.ndarray]) -> np.ndarray:
        """Normalised residuals of the model ``comps`` (component arrays over all blocks) in
        :meth:`Comparison.residuals`' order."""
        measured = {k: self.as_measured(comps, k) for k in self.comps}
        cells = np.stack([self.average @ measured[k] for k in self.comps])
        for k in ("temporal_column", "temporal_row"):
            if k in measured:
                cells[self.comps.index(k), self.no_temporal_cell] = 0.0
        spread = (self.average @ comps[QUANT_SPREAD])[self.cell_idx]
        err = np.sqrt(self.errors**2 + np.where(self.spread_entry, spread, 0.0) ** 2)
        cell_res = (self.values - cells[self.comp_idx, self.cell_idx]) / err
        # Gaussian likelihood: a vaguer model pays log(err^2) (no escape into its own uncertainty)
        like = np.sqrt(2.0 * np.log(err / self.errors))
        pooled = np.stack([self.pooling @ measured[k] for k in self.comps])[self.pooled_comp, self.pooled_seg]
        pooled_res = (self.pooled_values - pooled) / self.pooled_errors
        contrasts = np.stack([self.contrast @ (m - at_block(comps, k)) for k, m in zip(REGIONAL, self.region_measured)])
        region_res = contrasts[self.region_comp, self.region_row] / self.region_err
        count, amp, spread = self.outliers(comps)
        count_res = (self.outlier_pixels - count) / np.sqrt(np.maximum(np.maximum(count, self.outlier_pixels), 1.0))
        # the mean of n >= 1 outlier amplitudes: the standard error of n draws from the model's spread (a
        # sample of a few pixels cannot show its own), at least the sample's, with its likelihood term (a
        # vaguer model pays); weighted by the share of the n pixels the model expects (the others'
        # amplitudes say nothing about it): smooth, where a gate on the expected count would let a fit
        # switch it off
        n = np.maximum(self.outlier_pixels, 1.0)
        share = np.where(self.outlier_pixels >= 1, np.sqrt(np.clip(count / n, 0.0, 1.0)), 0.0)
        amp_err = np.maximum(self.amplitude_err, np.hypot(AMPLITUDE_SYSTEMATIC * self.amplitude, spread / np.sqrt(n)))
        amp_res = share * (self.amplitude - amp) / amp_err
        amp_like = share * np.sqrt(2.0 * np.log(amp_err / self.amplitude_err))
        tail = (np.stack([count_res, amp_res, amp_like], axis=1) * self.outliers_measured[:, None]).ravel()
        return np.concatenate([cell_res, like, pooled_res, region_res, tail])[self.order]


class Comparison:
    """Measurements paired with a model's prediction for the same segments and blocks.

    Poisson and Gaussian effects come from ``NoiseModel.predict`` (joint mode, clip-aware, each effect's
    sigma at the block intensity); fixed mixtures (hot pixels) are split between the outlier and the
    white core components with clipped offsets; quantization acts on the temporal noise.
    """

    def __init__(self, meas: Measurements, model: NoiseModel, progress: Any = None) -> None:
        self.meas = meas
        self.model = model
        self.effects = list(model.effects)
        by_seg: dict[int, list[Cell]] = {}
        for c in meas.cells:
            by_seg.setdefault(c.segment, []).append(c)
        self.segments: list[_SegmentBase] = []
        analytic = [e for e in self.effects if is_plain(e)]
        rest = [e for e in self.effects if e not in analytic]
        clip_model = NoiseModel(analytic + [e for e in rest if e.distribution in ("modifier", "response")])
        metas = [s.meta for s in meas.segments]
        for seg in meas.segments:
            if seg.index in by_seg:
                sb = _SegmentBase(seg, by_seg[seg.index])
                sb.set_partners(metas)
                self.segments.append(sb)
        self.views = Views([(sb.seg.meta, sb.v, sb.sigma, sb.pos, sb.partners) for sb in self.segments],
                           [(sb.seg.temperature_var_c2, sb.seg.n_frames) for sb in self.segments])
        self.span = np.concatenate([sb.span for sb in self.segments]) if self.segments else np.zeros(0)
        unclipped_rest = self.views.split(self.views.components([e for e in rest if e.distribution != "quantization"]))
        drift = self.views.split(self.views.drift(clip_model.effects))  # the analytic effects' (the rest's is in theirs)
        for sb, comps, drifted in zip(self.segments, unclipped_rest, drift, strict=True):
            seg = sb.seg
            pred = clip_model.predict(sb.v, seg.meta)
            comps = dict(comps)
            preds_p = [clip_model.predict(p.v, p.meta) for p in sb.partners]
            for e in analytic:
                here = np.asarray(pred[e.name], dtype=float)
                name = component_of(e)
                if sb.partners and not e.temporal:  # cross-view: product of the sigmas in both views
                    prods = [here * np.asarray(pp[e.name], dtype=float) for pp in preds_p]
                    var = sum(p.cross_weight * x for p, x in zip(sb.partners, prods))
                    if name == "fixed":
                        comps[AT_BLOCK] = comps[AT_BLOCK] + sum(p.weight * x for p, x in zip(sb.partners, prods)) - var
                else:
                    var = here**2
                assert name is not None  # analytic effects are poisson or gaussian: a measured component
                comps[name] = comps[name] + var
            for name, var in drifted.items():
                comps[name] = comps[name] + var
            added, fixed, comps[QUANT_SPREAD] = quantization_variance(
                self.effects, clip_model.conditions(seg.meta), comps["temporal"], sb.v, sb.span)
            comps["temporal"] = comps["temporal"] + added
            if not sb.partners:
                comps["fixed"] = comps["fixed"] + fixed
            sb.clip_aware = comps
            sb.set_region_errors(comps)
            if progress is not None:
                progress.update(1)
        self.clip_aware = {c: np.concatenate([sb.clip_aware[c] for sb in self.segments]) if self.segments
                           else np.zeros(0) for c in (*MEASURED, *EXTRA)}
        self.observables = Observables(self.segments)
        self.unclipped = self.views.components(self.effects, self.span)

    # --- predictions -------------------------------------------------------------------------
    def replaced(self, extra: Sequence[Effect]) -> list[Effect]:
        """The model's effects with ``extra`` added (replacing effects of the same name)."""
        names = {e.name for e in extra}
        return [e for e in self.effects if e.name not in names] + list(extra)

    def predict_with(self, extra: Sequence[Effect] = ()) -> list[tuple[_SegmentBase, dict[str, np.ndarray]]]:
        """Per segment: per-block component variances of the model with ``extra`` effects added
        (replacing effects of the same name): clip-aware baseline + unclipped change."""
        if not extra:
            return [(sb, sb.clip_aware) for sb in self.segments]
        return list(zip(self.segments, self.views.split(self._components(extra))))

    def _components(self, extra: Sequence[Effect]) -> dict[str, np.ndarray]:
        """:meth:`predict_with` over all segments' blocks (concatenated)."""
        if not extra:
            return self.clip_aware
        effects = self.replaced(extra)
        names = ", ".join(e.name for e in extra)
        try:
            new = self.views.components(effects, self.span)
        except EffectError:
            raise
        except Exception as exc:  # a plug-in's own failure, named (the CLI prints one line)
            raise EffectError(f"effect(s) {names} failed to evaluate: {str(exc) or type(exc).__name__}") from exc
        if not all(np.all(np.isfinite(a)) for a in new.values()):
            raise EffectError(f"effect(s) {names} returned a NaN or infinite variance")
        comps = {c: np.maximum(self.clip_aware[c] + new[c] - self.unclipped[c], 0.0) for c in MEASURED}
        return comps | {c: new[c] for c in EXTRA}

    def residuals(self, extra: Sequence[Effect] = ()) -> np.ndarray:
        """Normalised residuals (measured - model) / error of every observable, for chi-square fits:
        cell variances per component, outlier count and amplitude per segment, quantization step."""
        res = self.observables.residuals(self._components(extra))
        z = self.step_z(extra)
        return res if z is None else np.append(res, z)

    def outlier_expectation(self, extra: Sequence[Effect] = ()) -> tuple[np.ndarray, np.ndarray]:
        """Per segment: expected outlier pixels (detected in the frame average and confirmed by partner
        views, as :func:`.measure._cross_views` counts them) and their mean |offset| (DN)."""
        return self.observables.outliers(self._components(extra))[:2]

    def step_z(self, extra: Sequence[Effect] = ()) -> float | None:
        """(measured - model) quantization step over its error, None when the step was not measured."""
        if not math.isfinite(self.meas.quant_step_dn):
            return None
        effects = self.replaced(extra) if extra else self.effects
        step = predicted_step(effects, self.segments[0].seg.meta, self.meas.output_step_dn)
        step_err = math.hypot(self.meas.quant_step_err_dn, STEP_SYSTEMATIC_DN)
        return (self.meas.quant_step_dn - step) / step_err

    # --- reporting ---------------------------------------------------------------------------
    def cell_table(self, extra: Sequence[Effect] = ()) -> list[dict[str, Any]]:
        """One row per cell: conditions, measured and model sigma (DN) per component and in total
        (with ``extra`` effects: the additive approximation of :meth:`predict_with`); the measured sigma's standard
        error below and above it and on the model's side (:func:`sigma_error`)."""
        pairs = self.predict_with(extra)
        rows = []
        t0 = self.meas.segments[0].stamp_ns
        for sb, comps in pairs:
            seg = sb.seg
            table = {c: _cell_values(sb, comps, c) for c in MEASURED + ("single",)}
            for i, cell in enumerate(sb.cells):
                model = {c: float(a[i]) for c, a in table.items()}
                meas_total = sum(cell.values.values())
                err_total = math.sqrt(sum(e * e for e in cell.errors.values()))
                model_total = sum(model[c] for c in MEASURED)
                ms, mm = math.sqrt(max(meas_total, 0.0)), math.sqrt(max(model_total, 0.0))
                below, above = sigma_error(ms, err_total, below=True), sigma_error(ms, err_total, below=False)
                rows.append({
                    "segment": seg.index,
                    "time_s": (seg.stamp_ns - t0) * 1e-9,
                    "gain_db": seg.meta.gain_db,
                    "exposure_time_s": seg.meta.exposure_time_s,
                    "sensor_temperature_c": seg.meta.sensor_temperature_c,
                    "intensity_dn": cell.intensity_dn,
                    "blocks": int(cell.block_index.size),
                    "frames": seg.n_frames,
                    "measured_sigma_dn": ms,
                    "measured_sigma_err_dn": below if ms >= mm else above,
                    "measured_sigma_err_below_dn": below,
                    "measured_sigma_err_above_dn": above,
                    "model_sigma_dn": mm,
                    "residual_dn": ms - mm,
                    "measured_var_dn2": dict(cell.values),
                    "measured_var_err_dn2": dict(cell.errors),
                    "model_var_dn2": {c: model[c] for c in cell.values},
                } | ({"cross_view": _cross_view_conditions(seg, cell)} if seg.partners else {}))
        return rows


def _cross_view_conditions(seg: SegmentMeasurement, cell: Cell) -> dict[str, Any]:
    """What a cell's cross-view components (fixed, column, row: products of a sensor pattern's size here and in the
    partner views) are measured at: the geometric means, over its blocks and their partner views (by weight), of
    the intensity here and there (a pattern of variance ~ I^n gives (I_here I_partner)^(n/2), so a law fitted
    against it has the pattern's own power), and each partner segment's share of the weight (for the same means of
    the exposure, gain and dark current: :func:`.signature.cross_view_condition`)."""
    assert seg.partner_weight is not None and seg.partner_intensity_dn is not None
    w = seg.partner_weight[cell.block_index]
    total = max(float(w.sum()), 1e-300)
    here = np.log(np.maximum(seg.intensity_dn[cell.block_index], 1e-3))[:, None]
    there = np.log(np.maximum(seg.partner_intensity_dn[cell.block_index], 1e-3))
    shares = w.sum(axis=0) / total
    return {"intensity_dn": float(np.exp(np.sum(w * 0.5 * (here + there)) / total)),
            "partners": {int(j): float(x) for j, x in zip(seg.partners, shares)}}


def region_table(comp: Comparison, extra: Sequence[Effect] = ()) -> list[dict[str, Any]]:
    """Which part of the image: measured vs model total sigma per region of a 3 x 3 grid (row-major),
    from the blocks the model is evaluated at."""
    meas_var: dict[int, list[float]] = {}
    model_var: dict[int, list[float]] = {}
    for sb, comps in comp.predict_with(extra):
        seg = sb.seg
        measured = np.sum([seg.values[c][sb.rep] for c in seg.values], axis=0)
        model = np.sum([comps[c] for c in MEASURED], axis=0) + comps[AT_BLOCK]
        for region, m, p in zip(seg.region[sb.rep], measured, model):
            meas_var.setdefault(int(region), []).append(float(m))
            model_var.setdefault(int(region), []).append(float(p))
    rows = []
    for region in sorted(meas_var):
        ms = math.sqrt(max(float(np.mean(meas_var[region])), 0.0))
        mm = math.sqrt(max(float(np.mean(model_var[region])), 0.0))
        n = len(meas_var[region])
        var_err = float(np.std(meas_var[region], ddof=1)) / math.sqrt(n) if n > 1 else 0.0  # of the blocks' mean
        rows.append({"region": region, "blocks": n, "measured_sigma_dn": ms,
                     "measured_sigma_err_dn": var_err / (2.0 * ms) if ms > 0 else 0.0,
                     "model_sigma_dn": mm, "mean_residual_dn": ms - mm, "rms_residual_dn": abs(ms - mm)})
    return rows


def sigma_error(sigma: float, var_err: float, below: bool) -> float:
    """The standard error (DN) of a measured sigma from that of its variance (DN^2), on one side: ``below`` it (the
    side of a model under the measurement) or above it. They differ where the variance's error is comparable to the
    variance (a single view's scene: the sigma could be down to 0); var_err / (2 sigma) on either side elsewhere."""
    if below:
        return sigma - math.sqrt(max(sigma * sigma - var_err, 0.0))
    return math.sqrt(sigma * sigma + var_err) - sigma


def rms_error_raw(rows: Iterable[dict[str, Any]]) -> float:
    """Raw rms over cells of measured - model total sigma (DN): the model's error plus the measurement's
    own scatter (each cell's standard error)."""
    r = np.asarray([row["residual_dn"] for row in rows])
    return float(np.sqrt(np.mean(r**2))) if r.size else float("nan")


def measurement_scatter(rows: Iterable[dict[str, Any]]) -> float:
    """rms of the cells' standard errors of the measured total sigma (DN): the raw rms error an exact
    model would get."""
    e = np.asarray([row["measured_sigma_err_dn"] for row in rows])
    return float(np.sqrt(np.mean(e**2))) if e.size else float("nan")


def rms_error(rows: Iterable[dict[str, Any]]) -> float:
    """The model's rms error (DN), net of the measurement's expected scatter:
    ``sqrt(max(0, mean(residual^2 - se^2)))`` over cells (``se``: the cell's standard error of the measured
    total sigma). Unbiased for the model's mean square error when the standard errors are honest; 0 when
    the residuals are within the measurement's scatter."""
    rows = list(rows)
    if not rows:
        return float("nan")
    excess = rms_error_raw(rows) ** 2 - measurement_scatter(rows) ** 2
    return float(math.sqrt(max(excess, 0.0)))


def _group_key(row: dict[str, Any], key: str, time_edges: np.ndarray) -> Any:
    if key == "intensity_dn":
        return int(row["intensity_dn"] // 32) * 32
    if key == "gain_db":
        return round(row["gain_db"], 1)
    if key == "exposure_time_s":
        return float(f"{row['exposure_time_s']:.3g}")
    if key == "sensor_temperature_c":
        return round(row["sensor_temperature_c"] / 5.0) * 5.0
    if key == "time_s":
        i = int(np.searchsorted(time_edges, row["time_s"], side="right")) - 1
        return round(float(time_edges[max(i, 0)]), 3)
    raise KeyError(key)


def signed_sigma(var: np.ndarray | float) -> np.ndarray:
    """sign(var) sqrt|var| (DN): a zero-mean noisy variance estimate of 0 stays near 0 instead of reading
    as a positive noise level."""
    v = np.asarray(var, dtype=float)
    return np.sign(v) * np.sqrt(np.abs(v))


def _clustered_se(values: np.ndarray, clusters: Sequence[Any]) -> float:
    """Standard error of ``values.mean()`` when values of one cluster (a segment's cells, which share its
    frames) are correlated: from the spread of the cluster sums (cluster-robust; 0 with one cluster)."""
    keys = sorted(set(clusters), key=str)
    if len(keys) < 2:
        return 0.0
    index = {k: i for i, k in enumerate(keys)}
    sums = np.bincount([index[c] for c in clusters], values - values.mean(), len(keys))
    return float(np.sqrt(len(keys) / (len(keys) - 1) * np.sum(sums**2)) / len(values))


def by_condition(rows: Sequence[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    """Where the model fails: residual tables per intensity, gain, exposure, temperature, time and
    per component (temporal vs fixed-pattern vs column / row structure)."""
    out: dict[str, list[dict[str, Any]]] = {}
    if not rows:
        return out
    times = np.asarray([r["time_s"] for r in rows])
    time_edges = np.linspace(times.min(), times.max() + 1e-9, min(8, len(set(times.tolist()))) + 1)[:-1]
    for key in ("intensity_dn", "gain_db", "exposure_time_s", "sensor_temperature_c", "time_s"):
        groups: dict[Any, list[dict[str, Any]]] = {}
        for r in rows:
            groups.setdefault(_group_key(r, key, time_edges), []).append(r)
        table = []
        for value in sorted(groups):
            g = groups[value]
            res = np.asarray([r["residual_dn"] for r in g])
            sigma = np.asarray([r["measured_sigma_dn"] for r in g])
            err = np.asarray([0.5 * (r["measured_sigma_err_below_dn"] + r["measured_sigma_err_above_dn"]) for r in g])
            rms = float(np.sqrt(np.mean(sigma**2)))
            table.append({
                key: value,
                "cells": len(g),
                "measured_sigma_dn": rms,
                # the rms's standard error from the cells' (independent) errors
                "measured_sigma_err_dn": float(np.sqrt(np.sum((sigma * err) ** 2)) / (len(g) * max(rms, 1e-12))),
                "model_sigma_dn": float(np.sqrt(np.mean([r["model_sigma_dn"] ** 2 for r in g]))),
                "mean_residual_dn": float(res.mean()),
                "rms_residual_dn": float(np.sqrt(np.mean(res**2))),
            })
        out[key] = table
    comp_table = []
    for comp in ("temporal", "fixed", "column", "row", "temporal_column", "temporal_row", "single"):
        g = [r for r in rows if comp in r["measured_var_dn2"]]
        if not g:
            continue
        mv = np.asarray([r["measured_var_dn2"][comp] for r in g])
        pv = np.asarray([r["model_var_dn2"][comp] for r in g])
        ev = np.maximum([r["measured_var_err_dn2"][comp] for r in g], 1e-12)
        ms = signed_sigma(mv)
        mm = np.sqrt(np.maximum(pv, 0.0))
        comp_table.append({
            "component": comp,
            "cells": len(g),
            "measured_var_dn2": float(mv.mean()),
            "measured_var_err_dn2": _clustered_se(mv - pv, [r["segment"] for r in g]),
            "model_var_dn2": float(pv.mean()),
            # mean and spread of (measured - model) / standard error: (0, 1) when the model is right
            "z_mean": float(np.mean((mv - pv) / ev)),
            "z_std": float(np.std((mv - pv) / ev)),
            "measured_sigma_dn": float(signed_sigma(mv.mean())),
            "model_sigma_dn": float(math.sqrt(max(pv.mean(), 0.0))),
            "mean_residual_dn": float(np.mean(ms - mm)),
            "rms_residual_dn": float(np.sqrt(np.mean((ms - mm) ** 2))),
        })
    out["component"] = comp_table
    return out
