"""NoiseModel: analytic per-source prediction (clip-aware) and Monte-Carlo simulation."""
from __future__ import annotations

from typing import Iterable, Mapping

import numpy as np

from .clipping import DN_MAX, clipped_pmf, noise_moments
from .effects import PAPER_EFFECTS, Effect, EffectError, build_effects, make_effect
from .metadata import CameraMetadata
from .sensor import Conditions

#: Intensity grid of the analytic tables (DN); predictions interpolate linearly between nodes.
TABLE_STEP_DN = 0.5
_V_GRID = np.arange(0.0, DN_MAX + 1e-9, TABLE_STEP_DN)
#: Grid carrying the intermediate image of the sequential protocol.
_Y_GRID = np.arange(0.0, DN_MAX + 1e-9, 0.25)
MODES = ("joint", "sequential")
SEQUENTIAL_ORDER = ("pn", "rn", "dcsn")


class NoiseModel:
    """The camera noise model as a list of effects (default: the paper's PN, DCSN and RN).

    ``predict`` returns the clip-aware sigma in DN per effect and in total; ``simulate`` corrupts an
    image by Monte-Carlo. Modes: ``"joint"`` (all effects in one pass, clipped once: a physical
    camera) and ``"sequential"`` (the paper's training protocol: PN, then RN, then DCSN, then any
    other effect, each on the previous output and clipped; total = sqrt(sum of squares)).
    """

    def __init__(self, effects: Iterable[Effect | str] | Mapping[str, Mapping[str, float]] | None = None,
                 extra: Iterable[Effect | str] | Mapping[str, Mapping[str, float]] | None = None) -> None:
        base = [make_effect(n) for n in PAPER_EFFECTS] if effects is None else build_effects(effects)
        base += build_effects(extra)
        names = [e.name for e in base]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise EffectError(f"effect(s) listed twice: {', '.join(dup)}")
        order = {n: i for i, n in enumerate(SEQUENTIAL_ORDER)}
        self.effects: list[Effect] = sorted(base, key=lambda e: order.get(e.name, len(order)))
        self._cache: dict = {}

    # --- structure ---------------------------------------------------------------------------
    @property
    def names(self) -> list[str]:
        return [e.name for e in self.effects]

    @property
    def noise_effects(self) -> list[Effect]:
        """Effects that add noise (every effect but the modifiers)."""
        return [e for e in self.effects if e.distribution != "modifier"]

    def with_effects(self, *extra: Effect | str) -> "NoiseModel":
        """A new model with more effects (an effect of the same name is replaced)."""
        new = build_effects(list(extra))
        names = {e.name for e in new}
        return NoiseModel([e for e in self.effects if e.name not in names] + new)

    def conditions(self, meta: CameraMetadata) -> Conditions:
        """Physical conditions for stated metadata, after the modifier effects."""
        cond = Conditions.from_meta(meta)
        for e in self.effects:
            if e.distribution == "modifier":
                cond = e.modify(cond)
        return cond

    # --- analytic ----------------------------------------------------------------------------
    def tables(self, meta: CameraMetadata, mode: str = "joint") -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """E[n | v] and E[n^2 | v] per effect and for the total on the intensity grid ``_V_GRID``."""
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        key = (meta, mode)
        if key not in self._cache:
            if len(self._cache) > 64:
                self._cache.clear()
            cond = self.conditions(meta)
            self._cache[key] = self._joint_tables(cond) if mode == "joint" else self._sequential_tables(cond)
        return self._cache[key]

    def _moments(self, effects: list[Effect], x: np.ndarray, cond: Conditions) -> tuple[np.ndarray, np.ndarray]:
        lam = np.zeros_like(x)
        s2 = np.zeros_like(x)
        mixes = []
        quant = 0.0
        for e in effects:
            d = e.distribution
            if d == "poisson":
                lam = lam + np.broadcast_to(e.electrons(x, cond), x.shape)
            elif d == "gaussian":
                s2 = s2 + np.broadcast_to(np.asarray(e.sigma_dn(x, cond), dtype=float) ** 2, x.shape)
            elif d == "mixture":
                mixes.append(e.mixture(x, cond))
            elif d == "quantization":
                quant += e.lsb_dn(cond) ** 2 / 12.0
        _check_finite(effects, lam, s2, mixes)
        m1, m2 = noise_moments(x, lam, cond.dn_per_e, s2, mixes)
        return m1, m2 + quant

    def _joint_tables(self, cond: Conditions) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        out = {e.name: self._moments([e], _V_GRID, cond) for e in self.noise_effects}
        out["total"] = self._moments(self.noise_effects, _V_GRID, cond)
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
                    pmf = self._pmf_after([e], _V_GRID, cond)
                continue
            y1, y2 = self._moments([e], _Y_GRID, cond)
            out[e.name] = (pmf @ y1, pmf @ y2)
            if not last and e.distribution != "quantization":
                pmf = pmf @ self._pmf_after([e], _Y_GRID, cond)
        return out  # the total (sqrt of the sum of squares, as in the paper) is formed in predict

    def _pmf_after(self, effects: list[Effect], x: np.ndarray, cond: Conditions) -> np.ndarray:
        mean = np.zeros_like(x)
        var = np.zeros_like(x)
        mixes = []
        for e in effects:
            if e.distribution in ("poisson", "gaussian"):
                var = var + e.variance_dn2(x, cond)
            elif e.distribution == "mixture":
                mixes.append(e.mixture(x, cond))
        return clipped_pmf(x, _Y_GRID, mean, var, mixes)

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
        for name, (t1, t2) in tables.items():
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
        return {k: (float(v) if np.ndim(v) == 0 else v) for k, v in out.items()}

    def noise_level_function(self, meta: CameraMetadata, mode: str = "joint") -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """(intensity grid in DN, sigma per effect and total on it)."""
        return _V_GRID.copy(), self.predict(_V_GRID, meta, mode)

    # --- Monte-Carlo ------------------------------------------------------------------------
    def simulate(
        self,
        clean_dn: np.ndarray,
        meta: CameraMetadata,
        rng: np.random.Generator,
        mode: str = "joint",
        overrides: Mapping[str, CameraMetadata] | None = None,
    ) -> tuple[np.ndarray, dict[str, float]]:
        """Corrupt a clean image (DN, 0..255); returns (noisy float32 image, sigma per effect and total).

        ``overrides`` maps effect names to the metadata that actually generates their noise (the
        paper's xi scheme: noise with another gain than the metadata states). Per-effect sigma is the
        std of the effect's own clipped noise map: alone on the clean image in joint mode, on the
        previous output in sequential mode (then total = sqrt of the sum of squares, as in the paper).
        """
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        clean = np.asarray(clean_dn, dtype=np.float32)
        if clean.ndim < 2:
            raise ValueError(f"clean_dn must be an image (H, W) or a batch (N, H, W), got shape {clean.shape}")
        overrides = overrides or {}
        cond = self.conditions(meta)
        conds = {e.name: (self.conditions(overrides[e.name]) if e.name in overrides else cond) for e in self.effects}
        noise_effects = [e for e in self.noise_effects if e.distribution != "quantization"]
        quant = [e for e in self.noise_effects if e.distribution == "quantization"]
        sigmas: dict[str, float] = {}
        if mode == "joint":
            total = np.zeros_like(clean)
            for e in noise_effects:
                n = _checked_sample(e, clean, conds[e.name], rng)
                total += n
                sigmas[e.name] = _std(np.clip(clean + n, 0.0, DN_MAX) - clean)
            noisy = np.clip(clean + total, 0.0, DN_MAX)
            for e in quant:
                noisy = _quantize(noisy, e.lsb_dn(conds[e.name]))
                sigmas[e.name] = e.lsb_dn(conds[e.name]) / np.sqrt(12.0)
            sigmas["total"] = _std(noisy - clean)
        else:
            noisy = clean
            for e in noise_effects:
                n = _checked_sample(e, noisy, conds[e.name], rng)
                nxt = np.clip(noisy + n, 0.0, DN_MAX)
                sigmas[e.name] = _std(nxt - noisy)
                noisy = nxt
            for e in quant:
                nxt = _quantize(noisy, e.lsb_dn(conds[e.name]))
                sigmas[e.name] = _std(nxt - noisy)
                noisy = nxt
            sigmas["total"] = float(np.sqrt(sum(v**2 for v in sigmas.values())))
        return noisy.astype(np.float32, copy=False), sigmas


def _std(a: np.ndarray) -> float:
    return float(np.std(a, dtype=np.float64))


def _quantize(img: np.ndarray, lsb: float) -> np.ndarray:
    return (np.rint(img / np.float32(lsb)) * np.float32(lsb)).astype(np.float32)


def _checked_sample(e: Effect, signal: np.ndarray, cond: Conditions, rng: np.random.Generator) -> np.ndarray:
    try:
        n = e.sample(signal, cond, rng)
    except Exception as exc:
        raise EffectError(f"effect {e.name!r} failed to sample: {exc}") from exc
    n = np.asarray(n, dtype=np.float32)
    if n.shape != signal.shape:
        n = np.broadcast_to(n, signal.shape)
    if not np.all(np.isfinite(n)):
        raise EffectError(f"effect {e.name!r} produced NaN or inf noise")
    return n


def _check_finite(effects: list[Effect], lam, s2, mixes) -> None:
    bad = not (np.all(np.isfinite(lam)) and np.all(np.isfinite(s2)) and np.all(lam >= 0) and np.all(s2 >= 0))
    bad = bad or any(not (0 <= f <= 1 and np.all(np.isfinite(o))) for f, o in mixes)
    if bad:
        names = ", ".join(e.name for e in effects)
        raise EffectError(f"effect(s) {names} returned a NaN, infinite or negative variance")
