"""NoiseModel: analytic per-source prediction (clip-aware) and Monte-Carlo simulation."""
from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from .clipping import DN_MAX, POISSON_EXACT_MAX, clipped_pmf, noise_moments, poisson_terms, scatter_pmf
from .constants import MODES
from .effects import PAPER_EFFECTS, Effect, EffectError, build_effects, make_effect
from .metadata import CameraMetadata
from .sampling import standard_normal
from .sensor import Conditions, Pixels
from .table_grid import GridSpec, TableGrid

#: Intensity grid of the analytic tables (DN); predictions interpolate linearly between nodes.
TABLE_STEP_DN = 0.5
_V_GRID = np.arange(0.0, DN_MAX + 1e-9, TABLE_STEP_DN)
#: Grid carrying the intermediate image of the sequential protocol.
_Y_GRID = np.arange(0.0, DN_MAX + 1e-9, 0.5)
#: The fast simulation path draws Poisson sources exactly below this mean (normal above: skewness < 0.1).
FAST_POISSON_LAMBDA = 100.0
SEQUENTIAL_ORDER = ("pn", "rn", "dcsn")
#: table key of the total without the response effects (predict reports each response's signed change)
_LINEAR_TOTAL = "_linear_total"


class NoiseModel:
    """The camera noise model as a list of effects (default: the paper's PN, DCSN and RN).

    ``predict`` returns the clip-aware sigma in DN per effect and in total; ``simulate`` corrupts an
    image by Monte-Carlo. Modes: ``"joint"`` (all effects in one pass, clipped once: a physical
    camera) and ``"sequential"`` (the paper's training protocol: PN, then RN, then DCSN, then any
    other effect, each on the previous output and clipped; total = sqrt(sum of squares)).

    ``interpolate`` (True or a :class:`~noise_monitor.physics.table_grid.GridSpec`): the tables of a
    metadata set are interpolated between exact tables on a lattice over gain, exposure and temperature
    (for metadata that changes every frame: a live camera); False computes them exactly per set.
    """

    def __init__(self, effects: Iterable[Effect | str] | Mapping[str, Mapping[str, float]] | None = None,
                 extra: Iterable[Effect | str] | Mapping[str, Mapping[str, float]] | None = None,
                 interpolate: bool | GridSpec = False) -> None:
        base = [make_effect(n) for n in PAPER_EFFECTS] if effects is None else build_effects(effects)
        base += build_effects(extra)
        names = [e.name for e in base]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise EffectError(f"effect(s) listed twice: {', '.join(dup)}")
        order = {n: i for i, n in enumerate(SEQUENTIAL_ORDER)}
        self.effects: list[Effect] = sorted(base, key=lambda e: order.get(e.name, len(order)))
        self._cache: dict = {}
        self._served: dict[str, int] = {}  # per mode: requests served by the latest new metadata set
        self.interpolate = interpolate
        self._surrogate_last: tuple | None = None
        spec = interpolate if isinstance(interpolate, GridSpec) else GridSpec()
        self.grid: TableGrid | None = TableGrid(self._exact_tables, spec, self._surrogate_tables) if interpolate else None

    # --- structure ---------------------------------------------------------------------------
    @property
    def names(self) -> list[str]:
        return [e.name for e in self.effects]

    @property
    def noise_effects(self) -> list[Effect]:
        """Effects that add noise (every effect but the modifiers and responses)."""
        return [e for e in self.effects if e.distribution not in ("modifier", "response")]

    @property
    def responses(self) -> list[Effect]:
        """Non-linear response effects (scale the noise in front of them)."""
        return [e for e in self.effects if e.distribution == "response"]

    def slope(self, x: np.ndarray, cond: Conditions) -> np.ndarray | None:
        """Product of the response effects' slopes at clean values ``x`` (None: linear camera)."""
        if not self.responses:
            return None
        out = np.ones(np.shape(x))
        for e in self.responses:
            k = np.asarray(_guarded(e, "evaluate", e.at, "slope", x, cond), dtype=float)
            if not (np.all(np.isfinite(k)) and np.all(k >= 0.0)):
                raise EffectError(f"effect {e.name!r} returned a NaN, infinite or negative response slope")
            out = out * k
        return out

    def linear_signal(self, x: np.ndarray, cond: Conditions) -> np.ndarray:
        """The linear signal behind output levels ``x`` (through the response effects, last first)."""
        for e in reversed(self.responses):
            x = np.asarray(_guarded(e, "evaluate", e.linear, x, cond), dtype=np.asarray(x).dtype)
            if not np.all(np.isfinite(x)):
                raise EffectError(f"effect {e.name!r} returned a NaN or infinite linear signal")
        return x

    def with_effects(self, *extra: Effect | str) -> NoiseModel:
        """A new model with more effects (an effect of the same name is replaced)."""
        new = build_effects(list(extra))
        names = {e.name for e in new}
        return NoiseModel([e for e in self.effects if e.name not in names] + new, interpolate=self.interpolate)

    def conditions(self, meta: CameraMetadata) -> Conditions:
        """Physical conditions for stated metadata, after the modifier effects."""
        cond = Conditions.from_meta(meta)
        for e in self.effects:
            if e.distribution == "modifier":
                cond = _guarded(e, "modify", e.modify, cond)
                if not isinstance(cond, Conditions):
                    raise EffectError(f"effect {e.name!r}: modify() must return Conditions, got {type(cond).__name__}")
                values = (cond.gain, cond.exposure_time_s, cond.temperature_k, cond.dark_scale, cond.dark_rate_per_k)
                if not all(np.isfinite(v) for v in values) or cond.gain <= 0 or cond.exposure_time_s < 0 \
                        or cond.temperature_k <= 0 or cond.dark_scale < 0:
                    raise EffectError(f"effect {e.name!r} produced impossible conditions: gain {cond.gain:g}, "
                                      f"exposure {cond.exposure_time_s:g} s, temperature {cond.temperature_k:g} K")
        return cond

    def lsb(self, effect: Effect, cond: Conditions) -> float:
        """Quantization step of a quantization effect, checked."""
        lsb = _guarded(effect, "evaluate", effect.lsb_dn, cond)
        if not (np.isfinite(lsb) and 0.0 < lsb <= DN_MAX):
            raise EffectError(f"effect {effect.name!r} returned an invalid quantization step {lsb!r} DN")
        return float(lsb)

    # --- analytic ----------------------------------------------------------------------------
    def tables(self, meta: CameraMetadata, mode: str = "joint") -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """E[n | v] and E[n^2 | v] per effect and for the total on the intensity grid ``_V_GRID``
        (interpolated over the conditions when the model was built with ``interpolate``)."""
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        key = (meta, mode)
        if key in self._cache:
            self._served[mode] = self._served.get(mode, 0) + 1
            return self._cache[key]
        if len(self._cache) > 64:
            self._cache.clear()
        held = self._served.get(mode, 1 << 30)  # the previous set's use (a first set counts as held)
        self._served[mode] = 1
        if self.grid is not None and held < max(self.grid.spec.held_exact_requests, 1):
            self._cache[key] = self.grid.tables(meta, mode)
        else:
            self._cache[key] = self._exact_tables(meta, mode)
        return self._cache[key]

    def _exact_tables(self, meta: CameraMetadata, mode: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        cond = self.conditions(meta)
        return self._joint_tables(cond) if mode == "joint" else self._sequential_tables(cond)

    def _surrogate_tables(self, meta: CameraMetadata, mode: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Cheap stand-ins for the tables (Poisson sources as Gaussians of equal variance, each effect in
        one pass on the clean value, no rounding): they carry the clipping's dependence on the conditions,
        which the interpolation of the exact tables then only corrects (see ``table_grid``). The per-effect
        ones are shared by both modes (cached for the last metadata set)."""
        if self._surrogate_last is None or self._surrogate_last[0] != meta:
            cond = self.conditions(meta)
            adders = [e for e in self.noise_effects if e.distribution != "quantization"]
            own = {e.name: self._gaussian_moments([e], cond) for e in adders}
            total = self._gaussian_moments(adders, cond) if len(adders) > 1 else next(iter(own.values()), None)
            self._surrogate_last = (meta, own, total)
        _, own, total = self._surrogate_last
        if mode == "sequential":
            return _carried(own)
        out = {**own, "total": total} if total is not None else dict(own)
        if self.responses and total is not None:  # the same keys as the exact tables
            out[_LINEAR_TOTAL] = total
        return out

    def _gaussian_moments(self, effects: list[Effect], cond: Conditions) -> tuple[np.ndarray, np.ndarray]:
        lam, s2, mixes = self._components(effects, _V_GRID, cond)
        m1, m2, _ = noise_moments(_V_GRID, 0.0, 1.0, s2 + cond.dn_per_e**2 * lam, mixes)
        return m1, m2

    @staticmethod
    def _components(effects: list[Effect], x: np.ndarray, cond: Conditions):
        """(Poisson electrons, Gaussian variance in DN^2, mixtures) of effects at clean values x."""
        lam = np.zeros_like(x)
        s2 = np.zeros_like(x)
        mixes = []
        for e in effects:
            if e.distribution == "poisson":
                lam = lam + np.broadcast_to(np.asarray(_guarded(e, "evaluate", e.at, "electrons", x, cond), dtype=float),
                                            x.shape)
            elif e.distribution == "gaussian":
                sig = np.asarray(_guarded(e, "evaluate", e.at, "sigma_dn", x, cond), dtype=float)
                s2 = s2 + np.broadcast_to(sig**2, x.shape)
            elif e.distribution == "mixture":
                frac, off = _guarded(e, "evaluate", e.mixture, x, cond)
                mixes.append((float(frac), np.broadcast_to(np.asarray(off, dtype=float), x.shape)))
        return lam, s2, mixes

    def _moments(self, effects: list[Effect], x: np.ndarray, cond: Conditions,
                 linear: bool = False, pedestal: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """E[n|x], E[n^2|x] of the effects applied together in one pass (through the response unless
        ``linear``; clipped, then quantized); ``pedestal``: the camera's black level, so that the output
        ``x + pedestal + n`` is what the ADC clips at 0 and 255 and rounds."""
        lam, s2, mixes = self._components(effects, x if linear else self.linear_signal(x, cond), cond)
        _check_finite(effects, lam, s2, mixes)
        lsbs = [self.lsb(e, cond) for e in effects if e.distribution == "quantization"]
        if lsbs and len(lsbs) == len(effects):
            # rounding of the previous output alone (sequential protocol): each node of the carried
            # distribution stands for its bin of the grid step, i.e. a spread of step/sqrt(12) DN
            step = _Y_GRID[1] - _Y_GRID[0]
            r1, r2, _ = noise_moments(x, 0.0, 1.0, step**2 / 12.0, None, lsb=max(lsbs), rounding=True)
            return r1, r2
        slope = None if linear else self.slope(x, cond)
        m1, m2, _ = noise_moments(x + pedestal, lam, cond.dn_per_e, s2, mixes, lsb=max(lsbs) if lsbs else None,
                                  slope=slope)
        return m1, m2

    def output_moments(self, meta: CameraMetadata, black_level_dn: float = 0.0) -> tuple[np.ndarray, np.ndarray,
                                                                                            np.ndarray]:
        """(clean signal, mean, variance) of a camera's output with the black level taken off, on the table grid up
        to ``DN_MAX - black_level_dn``: every effect in one pass, the ADC's clipping at ``-black_level_dn`` and
        ``DN_MAX - black_level_dn`` and its rounding (joint mode, exact; e.g. the EMVA photon-transfer curve)."""
        if not 0.0 <= black_level_dn < DN_MAX:
            raise ValueError(f"black_level_dn must be in [0, {DN_MAX:g}) DN, got {black_level_dn}")
        v = _V_GRID[_V_GRID <= DN_MAX - black_level_dn + 1e-9]
        m1, m2 = self._moments(self.noise_effects, v, self.conditions(meta), pedestal=float(black_level_dn))
        return v, v + m1, m2 - m1**2

    def _quantization_moments(self, e: Effect, x: np.ndarray, cond: Conditions) -> tuple[np.ndarray, np.ndarray]:
        """Joint mode: moments of the rounding error of the one-pass noisy output (as ``simulate``)."""
        others = [o for o in self.noise_effects if o.distribution != "quantization"]
        lam, s2, mixes = self._components(others, self.linear_signal(x, cond), cond)
        r1, r2, _ = noise_moments(x, lam, cond.dn_per_e, s2, mixes, lsb=self.lsb(e, cond), rounding=True,
                                  slope=self.slope(x, cond))
        return r1, r2

    def _joint_tables(self, cond: Conditions) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        out = {
            e.name: self._quantization_moments(e, _V_GRID, cond) if e.distribution == "quantization"
            else self._moments([e], _V_GRID, cond)
            for e in self.noise_effects
        }
        out["total"] = self._moments(self.noise_effects, _V_GRID, cond)
        if self.responses:
            out[_LINEAR_TOTAL] = self._moments(self.noise_effects, _V_GRID, cond, linear=True)
        return out

    def _sequential_tables(self, cond: Conditions) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        effects = self.noise_effects
        pmf = None  # distribution of the current image on _Y_GRID per clean value (rows: _V_GRID)
        for i, e in enumerate(effects):
            last = i == len(effects) - 1
            if pmf is None:
                m1, m2 = self._moments([e], _V_GRID, cond)
                out[e.name] = (m1, m2)
                if not last:
                    pmf = self._pmf_after(e, _V_GRID, cond)
                continue
            y1, y2 = self._moments([e], _Y_GRID, cond)
            out[e.name] = (pmf @ y1, pmf @ y2)
            if not last and e.distribution != "quantization":
                pmf = pmf @ self._pmf_after(e, _Y_GRID, cond)
        return out  # the total (sqrt of the sum of squares, as in the paper) is formed in predict

    def _pmf_after(self, effect: Effect, x: np.ndarray, cond: Conditions) -> np.ndarray:
        """Distribution on ``_Y_GRID`` of clip(x + one effect's noise), rows: x."""
        lam, s2, mixes = self._components([effect], x, cond)
        if effect.distribution == "gaussian":
            return clipped_pmf(x, _Y_GRID, np.zeros_like(x), s2)
        if effect.distribution == "poisson":
            if float(lam.max()) > POISSON_EXACT_MAX:
                return clipped_pmf(x, _Y_GRID, np.zeros_like(x), cond.dn_per_e**2 * lam)
            shifts, probs = poisson_terms(lam, cond.dn_per_e)
            return scatter_pmf(x, shifts, probs, _Y_GRID)
        frac, off = mixes[0]
        shifts = np.stack([np.zeros_like(x), off])
        probs = np.stack([np.full_like(x, 1.0 - frac), np.full_like(x, frac)])
        return scatter_pmf(x, shifts, probs, _Y_GRID)

    def predict(self, intensity_dn, meta: CameraMetadata, mode: str = "joint") -> dict[str, float | np.ndarray]:
        """Predicted sigma in DN per effect and ``"total"`` (clipping at 0 and 255 included).

        ``intensity_dn`` is a mean intensity (scalar), a 1-D array of intensities (one sigma each),
        a clean intensity map (2-D: one sigma for the map) or a batch of maps (N, H, W: N sigmas).
        A map's sigma is the std of its noise map: sqrt(mean E[n^2|v] - (mean E[n|v])^2).
        """
        tables = self.tables(meta, mode)
        x = np.asarray(intensity_dn, dtype=float)
        if not np.all(np.isfinite(x)):
            raise ValueError("intensity_dn contains NaN or inf")
        x = np.clip(x, 0.0, DN_MAX)
        out: dict[str, float | np.ndarray] = {}
        for name, (t1, t2) in tables.items():  # includes the linear total of a model with responses
            m1 = np.interp(x, _V_GRID, t1)
            m2 = np.interp(x, _V_GRID, t2)
            if x.ndim >= 2:
                axes = (-2, -1)
                var = m2.mean(axis=axes) - m1.mean(axis=axes) ** 2
            else:
                var = m2 - m1**2
            out[name] = np.sqrt(np.maximum(var, 0.0))
        if mode == "sequential":
            out["total"] = np.sqrt(sum(np.asarray(out[e.name]) ** 2 for e in self.noise_effects))
        linear = out.pop(_LINEAR_TOTAL, None)
        for e in self.responses:  # signed: how much the response changes the total sigma
            out[e.name] = np.asarray(out["total"]) - (np.asarray(out["total"]) if linear is None else linear)
        return {k: (float(v) if np.ndim(v) == 0 else v) for k, v in out.items()}

    # --- Monte-Carlo ------------------------------------------------------------------------
    def simulate(
        self,
        clean_dn: np.ndarray,
        meta: CameraMetadata,
        rng: np.random.Generator,
        mode: str = "joint",
        overrides: Mapping[str, CameraMetadata] | None = None,
        per_source: bool = True,
        black_level_dn: float = 0.0,
    ) -> tuple[np.ndarray, dict[str, float]]:
        """Corrupt a clean image (DN, 0..255); returns (noisy float32 image, sigma per effect and total).

        ``overrides`` maps effect names to the metadata that actually generates their noise (the
        paper's xi scheme: noise with another gain than the metadata states). Per-effect sigma is the
        std of the effect's own clipped noise map: alone on the clean image in joint mode, on the
        previous output in sequential mode (then total = sqrt of the sum of squares, as in the paper).
        ``per_source=False`` (joint mode only) is the fast path for frames: the temporal Poisson and
        Gaussian effects are drawn as one normal of their summed variance (exact Poisson where the mean
        is below 100 electrons) and only the total sigma is returned. The image is the whole sensor:
        position-dependent effects see its pixel grid (``cond.where``); response effects scale the
        noise by their slope at the clean value (at the previous output in sequential mode).
        ``black_level_dn``: the camera's pedestal, which keeps the noise down to ``-black_level_dn`` below black (the
        image returned is without the pedestal; its ADC's saturation at ``DN_MAX - black_level_dn`` is the caller's).
        """
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        clean = np.asarray(clean_dn, dtype=np.float32)
        if clean.ndim < 2:
            raise ValueError(f"clean_dn must be an image (H, W) or a batch (N, H, W), got shape {clean.shape}")
        if not np.all(np.isfinite(clean)):
            raise ValueError("clean_dn contains NaN or inf")
        overrides = overrides or {}
        lo, hi = -float(black_level_dn), DN_MAX
        where = Pixels.frame(clean.shape)
        cond = self.conditions(meta).replace(where=where)
        conds = {e.name: (self.conditions(overrides[e.name]).replace(where=where) if e.name in overrides else cond)
                 for e in self.effects}
        adders = [e for e in self.noise_effects if e.distribution != "quantization"]
        quant = [e for e in self.noise_effects if e.distribution == "quantization"]
        sigmas: dict[str, float] = {}
        slope = self.slope(clean, cond)
        slope = None if slope is None else slope.astype(np.float32)
        signal = clean if slope is None else self.linear_signal(clean, cond).astype(np.float32)
        if mode == "joint" and not per_source:
            noisy = self._merged_noise(adders, signal, conds, rng)
            if slope is not None:
                noisy *= slope
            noisy += clean
            np.clip(noisy, lo, hi, out=noisy)
        elif mode == "joint":
            total = np.zeros_like(clean)
            for e in adders:
                n = _checked_sample(e, signal, conds[e.name], rng)
                if slope is not None:
                    n = n * slope
                total += n
                sigmas[e.name] = _std(np.clip(clean + n, lo, hi) - clean)
            noisy = np.clip(clean + total, lo, hi)
        else:
            noisy = clean
            for e in adders:
                if slope is None:
                    n = _checked_sample(e, noisy, conds[e.name], rng)
                else:
                    n = _checked_sample(e, self.linear_signal(noisy, cond).astype(np.float32), conds[e.name], rng)
                    n = n * np.asarray(self.slope(noisy, cond), dtype=np.float32)
                nxt = np.clip(noisy + n, lo, hi)
                sigmas[e.name] = _std(nxt - noisy)
                noisy = nxt
        for e in quant:
            nxt = _quantize(noisy, self.lsb(e, conds[e.name]))
            if per_source:  # the rounding error of the output
                sigmas[e.name] = _std(nxt - noisy)
            noisy = nxt
        if mode == "joint":
            sigmas["total"] = _std(noisy - clean)
        else:
            sigmas["total"] = float(np.sqrt(sum(v**2 for v in sigmas.values())))
        return noisy.astype(np.float32, copy=False), sigmas

    @staticmethod
    def _merged_noise(effects: list[Effect], clean: np.ndarray, conds: Mapping[str, Conditions],
                      rng: np.random.Generator) -> np.ndarray:
        """Joint noise with all mergeable effects drawn as one normal (fast path of ``simulate``)."""
        var: float | np.ndarray = 0.0  # variance in DN^2 of the merged Gaussian part
        lam: float | np.ndarray = 0.0  # electrons of the Poisson sources sharing the image's gain
        scale = conds[effects[0].name].dn_per_e if effects else 1.0
        noise = None
        for e in effects:
            c = conds[e.name]
            if not type(e).mergeable():
                n = _checked_sample(e, clean, c, rng)
                noise = n if noise is None else noise + n
            elif e.distribution == "poisson" and c.dn_per_e == scale:
                lam = lam + _compact(e.electrons(clean, c))
            else:
                var = var + _compact(e.variance_dn2(clean, c))
        lam_arr = np.asarray(lam, dtype=np.float32)
        var_arr = np.asarray(var, dtype=np.float32)
        for arr in (lam_arr, var_arr):  # min() propagates NaN; max() catches inf
            if not (arr.min() >= 0.0 and np.isfinite(arr.max())):
                raise EffectError("an effect returned a NaN, infinite or negative variance")
        z = standard_normal(rng, clean.shape)
        sd = var_arr + np.float32(scale**2) * lam_arr
        own = sd.shape == clean.shape  # a fresh full-frame array: reuse it for the result
        out = np.multiply(z, np.sqrt(sd, out=sd if own else None), out=sd if own else None)
        exact = lam_arr <= FAST_POISSON_LAMBDA
        if exact.any():
            exact = np.broadcast_to(exact, clean.shape)
            lam_x = np.broadcast_to(lam_arr, clean.shape)[exact].astype(np.float64)
            sd_other = np.sqrt(np.broadcast_to(var_arr, clean.shape)[exact])
            out[exact] = z[exact] * sd_other + np.float32(scale) * (rng.poisson(lam_x) - lam_x).astype(np.float32)
        if noise is not None:
            out += noise
        return out


#: Gauss-Hermite nodes and weights (probabilists') carrying the intermediate image of the sequential surrogate.
_GH_Z, _GH_W = np.polynomial.hermite_e.hermegauss(9)
_GH_W = _GH_W / _GH_W.sum()


def _carried(own: dict[str, tuple[np.ndarray, np.ndarray]]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Sequential surrogates: each effect beyond the paper's chain gets its one-pass moments averaged over
    the image the effects before it left (a clipped normal around the clean value with their summed
    variance); the paper's sources keep their one-pass moments (measured closer for them)."""
    out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    prev_var = np.zeros_like(_V_GRID)
    for name, (m1, m2) in own.items():
        if name in PAPER_EFFECTS or not prev_var.any():
            out[name] = (m1, m2)
        else:
            y = np.clip(_V_GRID[None, :] + np.sqrt(prev_var)[None, :] * _GH_Z[:, None], 0.0, DN_MAX)
            out[name] = (_GH_W @ np.interp(y, _V_GRID, m1), _GH_W @ np.interp(y, _V_GRID, m2))
        prev_var = prev_var + np.maximum(m2 - m1**2, 0.0)
    return out


def _compact(a) -> float | np.ndarray:
    """A constant array as a scalar (saves full-frame passes), anything else as float32."""
    arr = np.asarray(a)
    if arr.ndim == 0:
        return float(arr)
    if arr.strides and all(st == 0 for st in arr.strides):
        return float(arr.reshape(-1)[0])
    return arr.astype(np.float32, copy=False)


def _std(a: np.ndarray) -> float:
    """Standard deviation from float64 sums of a float32 array (BLAS dot for the squares: fast)."""
    flat = np.ascontiguousarray(a, dtype=np.float32).reshape(-1)
    if flat.size == 0:
        return float("nan")
    centred = flat - np.float32(float(flat.sum(dtype=np.float64)) / flat.size)  # no cancellation
    resid = float(centred.sum(dtype=np.float64)) / flat.size  # float32 rounding of the mean
    return float(np.sqrt(max(float(np.dot(centred, centred)) / flat.size - resid * resid, 0.0)))


def _quantize(img: np.ndarray, lsb: float) -> np.ndarray:
    return (np.rint(img / np.float32(lsb)) * np.float32(lsb)).astype(np.float32)


def _checked_sample(e: Effect, signal: np.ndarray, cond: Conditions, rng: np.random.Generator) -> np.ndarray:
    n = np.asarray(_guarded(e, "sample", e.sample, signal, cond, rng), dtype=np.float32)
    if n.shape != signal.shape:
        n = np.broadcast_to(n, signal.shape)
    if not np.all(np.isfinite(n)):
        raise EffectError(f"effect {e.name!r} produced NaN or inf noise")
    return n


def _guarded(e: Effect, what: str, fn, *args):
    """Call an effect's method; any failure becomes an EffectError naming the effect."""
    try:
        return fn(*args)
    except EffectError:
        raise
    except Exception as exc:
        raise EffectError(f"effect {e.name!r} failed to {what}: {exc}") from exc


def _check_finite(effects: list[Effect], lam, s2, mixes) -> None:
    bad = not (np.all(np.isfinite(lam)) and np.all(np.isfinite(s2)) and np.all(lam >= 0) and np.all(s2 >= 0))
    bad = bad or any(not (0 <= f <= 1 and np.all(np.isfinite(o))) for f, o in mixes)
    if bad:
        names = ", ".join(e.name for e in effects)
        raise EffectError(f"effect(s) {names} returned a NaN, infinite or negative variance")
