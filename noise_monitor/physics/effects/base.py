"""The effect plug-in API: a noise effect declares its parameters, variance and sampler.

Every effect is one of six kinds of distribution, which tells the analytic model how to combine it
with the others under clipping:

- ``poisson``: a shot noise; implement :meth:`Effect.electrons` (mean electrons per pixel).
- ``gaussian``: implement :meth:`Effect.sigma_dn` (standard deviation in DN at a clean signal).
- ``mixture``: a fraction of pixels gets an offset; implement :meth:`Effect.mixture`.
- ``quantization``: rounds the output; implement :meth:`Effect.lsb_dn`.
- ``modifier``: changes the physical conditions (true gain, dark-current law, ...); implement
  :meth:`Effect.modify`. Its variance contribution is the model's change with and without it.
- ``response``: the pixel response is non-linear; implement :meth:`Effect.slope` (the local slope of
  output vs linear signal at an output level, 1 = linear) and, if the response also bends the signal,
  :meth:`Effect.linear` (the linear signal behind an output level). The other effects are evaluated at
  the linear signal and their noise (all but quantization) is scaled by the slope, so the response's
  variance contribution may be negative (a response compressing near full well *reduces* the noise).
  Signals passed to effects are output levels (what the camera shows) everywhere else.

``temporal`` effects change from frame to frame; fixed-pattern ones (``temporal = False``) repeat in
every frame of a camera and vanish from frame differences; an effect that is both (random telegraph
pixels) overrides :meth:`Effect.temporal_share`. ``structure`` says how the noise is correlated:
``"pixel"`` (white), ``"row"`` (one value per image row, the same along it) or ``"column"``.
``spatial = True`` effects depend on where a pixel is on the sensor: they read ``cond.where``
(:class:`~noise_monitor.physics.sensor.Pixels`, normalised coordinates); where no position is known the
model averages them over the sensor. Samplers have working defaults for every kind, so a plug-in
usually implements one method.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from enum import StrEnum
from typing import Any, ClassVar

import numpy as np

from ..sampling import poisson, standard_normal
from ..sensor import Conditions, Pixels


class Distribution(StrEnum):
    """How an effect combines with the others under clipping (a str: plug-ins may declare the plain name)."""

    POISSON = "poisson"
    GAUSSIAN = "gaussian"
    MIXTURE = "mixture"
    QUANTIZATION = "quantization"
    MODIFIER = "modifier"
    RESPONSE = "response"


DISTRIBUTIONS = tuple(d.value for d in Distribution)
STRUCTURES = ("pixel", "row", "column")


class EffectError(ValueError):
    """An effect is unknown, misconfigured or failed to evaluate."""


@dataclass(frozen=True)
class Param:
    """One parameter of an effect."""

    name: str
    unit: str
    default: float
    bounds: tuple[float, float]
    fittable: bool = True
    integer: bool = False
    description: str = ""


class Effect:
    """Base class of all noise effects (built-in and plug-in). Its methods depend only on their arguments, the class
    and the parameter values: the lab reuses an effect's model contributions by them."""

    name: ClassVar[str] = ""
    distribution: ClassVar[Distribution] = Distribution.GAUSSIAN
    temporal: ClassVar[bool] = True
    #: correlation of the noise: "pixel" (white), "row" (constant along an image row), "column"
    structure: ClassVar[str] = "pixel"
    #: True if the effect depends on the pixel's position on the sensor (reads ``cond.where``)
    spatial: ClassVar[bool] = False
    params: ClassVar[tuple[Param, ...]] = ()
    description: ClassVar[str] = ""
    #: the file a plug-in effect was loaded from (None: built in, or registered by code)
    plugin_file: ClassVar[str | None] = None
    #: plain-language reading of the effect's signature in residuals (format fields: the parameters)
    signature: ClassVar[str] = ""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if cls.distribution in DISTRIBUTIONS:  # a plain name from a plug-in becomes the enum member
            cls.distribution = Distribution(cls.distribution)

    def __init__(self, **values: float) -> None:
        known = {p.name: p for p in self.params}
        unknown = sorted(set(values) - set(known))
        if unknown:
            raise EffectError(
                f"effect {self.name!r} has no parameter(s) {', '.join(unknown)}; "
                f"parameters: {', '.join(known) or 'none'}"
            )
        self.values: dict[str, float] = {}
        for p in self.params:
            v = values.get(p.name, p.default)
            try:
                v = float(v)
            except (TypeError, ValueError) as exc:
                raise EffectError(f"{self.name}.{p.name} must be a number, got {v!r}") from exc
            if not np.isfinite(v) or not p.bounds[0] <= v <= p.bounds[1]:
                raise EffectError(
                    f"{self.name}.{p.name} = {v:g} {p.unit} is outside [{p.bounds[0]:g}, {p.bounds[1]:g}] {p.unit}"
                )
            self.values[p.name] = round(v) if p.integer else v

    def __getattr__(self, item: str) -> Any:
        values = self.__dict__.get("values")
        if values is not None and item in values:
            return values[item]
        raise AttributeError(item)

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v:g}" for k, v in self.values.items())
        return f"{type(self).__name__}({args})"

    def reading(self) -> str:
        """The plain-language signature with this effect's parameter values filled in."""
        fields = {**self.values, **{f"{k}_pct": 100.0 * v for k, v in self.values.items()}}
        try:
            return self.signature.format(**fields) if self.signature else self.description
        except (KeyError, ValueError, IndexError):
            return self.signature

    # --- what the analytic model needs (override the one matching `distribution`) ---------------
    def electrons(self, signal_dn: np.ndarray, cond: Conditions) -> np.ndarray:
        """Mean electrons of a Poisson source at clean signal ``signal_dn``."""
        raise NotImplementedError

    def sigma_dn(self, signal_dn: np.ndarray, cond: Conditions) -> np.ndarray:
        """Standard deviation in DN of a Gaussian effect at clean signal ``signal_dn``."""
        raise NotImplementedError

    def mixture(self, signal_dn: np.ndarray, cond: Conditions) -> tuple[float, np.ndarray]:
        """(fraction of affected pixels, their offset in DN) of a mixture effect."""
        raise NotImplementedError

    def lsb_dn(self, cond: Conditions) -> float:
        """Quantization step in DN (8-bit scale) of a quantization effect."""
        raise NotImplementedError

    def modify(self, cond: Conditions) -> Conditions:
        """New physical conditions (modifier effects)."""
        return cond

    def slope(self, signal_dn: np.ndarray, cond: Conditions) -> np.ndarray:
        """Local slope d(output)/d(linear signal) of a response effect at output level ``signal_dn``."""
        raise NotImplementedError

    def linear(self, signal_dn: np.ndarray, cond: Conditions) -> np.ndarray:
        """The linear signal (DN) a response effect turns into output level ``signal_dn`` (default: the
        same: the response changes only the noise)."""
        return signal_dn

    def temporal_share(self, signal_dn: np.ndarray, cond: Conditions) -> np.ndarray | float:
        """Share (0..1) of the effect's variance that changes from frame to frame; the rest is a fixed
        pattern. Default: 1 for temporal effects, 0 for fixed-pattern ones."""
        return 1.0 if self.temporal else 0.0

    def fixed_mixture(self, signal_dn: np.ndarray, cond: Conditions) -> tuple[float, np.ndarray]:
        """(fraction, offset in DN) of the pixels a mixture effect leaves offset in a frame average:
        what stands out as outlier pixels there. Default: the mixture itself for fixed-pattern effects,
        none for temporal ones; effects both temporal and fixed override it."""
        if self.temporal:
            return 0.0, np.zeros(np.shape(signal_dn))
        return self.mixture(signal_dn, cond)

    # --- derived -------------------------------------------------------------------------------
    def at(self, method: str, signal_dn: np.ndarray, cond: Conditions):
        """``method(signal_dn, cond)`` (``"sigma_dn"``, ``"electrons"``, ``"slope"``), averaged over the
        sensor (rms for sigmas and slopes, mean for electrons) for a spatial effect without ``cond.where``."""
        fn = getattr(self, method)
        if not self.spatial or cond.where is not None:
            return fn(signal_dn, cond)
        s = np.asarray(signal_dn, dtype=float)
        val = np.asarray(fn(s.reshape(1, -1), cond.replace(where=Pixels.average_grid())), dtype=float)
        val = np.broadcast_to(val, (val.shape[0], s.size))
        avg = val.mean(axis=0) if method == "electrons" else np.sqrt(np.mean(val**2, axis=0))
        return avg.reshape(s.shape)

    def variance_dn2(self, signal_dn: np.ndarray | float, cond: Conditions) -> np.ndarray:
        """Unclipped variance contribution in DN^2 at clean signal ``signal_dn``.

        Modifiers and responses return 0 here: their contribution is a change of the other effects
        (see :meth:`noise_monitor.physics.NoiseModel.predict`).
        """
        s = np.asarray(signal_dn)
        if self.distribution is Distribution.POISSON:
            lam = np.asarray(self.at("electrons", s, cond))
            return np.broadcast_to(cond.dn_per_e**2 * (lam.reshape(-1)[0] if _constant(lam) else lam), s.shape)
        if self.distribution is Distribution.GAUSSIAN:
            sig = np.asarray(self.at("sigma_dn", s, cond))
            return np.broadcast_to(sig.reshape(-1)[0] ** 2 if _constant(sig) else sig**2, s.shape)
        if self.distribution is Distribution.MIXTURE:
            frac, off = self.mixture(s, cond)
            return np.broadcast_to(frac * (1.0 - frac) * np.asarray(off, dtype=float) ** 2, s.shape)
        if self.distribution is Distribution.QUANTIZATION:
            return np.full(s.shape, self.lsb_dn(cond) ** 2 / 12.0)
        return np.zeros(s.shape)

    # --- Monte-Carlo sampling ------------------------------------------------------------------
    def pattern(self, shape: tuple[int, ...], tag: str = "") -> np.ndarray:
        """A fixed pattern for this effect and image shape (same in every frame).

        Standardised to mean 0 and std 1 exactly, so a camera's fixed-pattern noise has exactly the
        stated magnitude (a short row/column pattern would otherwise be off by its sampling error).
        """
        key = (tuple(shape), tag)
        cache = self.__dict__.setdefault("_patterns", {})
        if key not in cache:
            digest = hashlib.sha256(f"{self.name}|{tag}|{shape}|{self.pattern_seed()}".encode()).digest()
            rng = np.random.default_rng(int.from_bytes(digest[:8], "little"))
            z = rng.standard_normal(shape, dtype=np.float64)
            if z.size > 1:
                z = (z - z.mean()) / z.std()
            cache[key] = z.astype(np.float32)
        return cache[key]

    def hit_mask(self, shape: tuple[int, ...], frac: float) -> np.ndarray:
        """Fixed set of exactly round(frac * size) affected pixels (fixed-pattern mixture effects)."""
        z = self.pattern(shape, "hit").reshape(-1)
        count = int(round(frac * z.size))
        mask = np.zeros(z.size, dtype=bool)
        if count:
            mask[np.argpartition(z, count - 1)[:count]] = True
        return mask.reshape(shape)

    def pattern_seed(self) -> int:
        """Seed of the fixed pattern (fixed-pattern effects); override to give cameras distinct ones."""
        return int(self.values.get("seed", 0))

    #: the simulator's fast path may draw this effect together with the other temporal Gaussian and
    #: Poisson effects as one normal of the summed variance (true for effects using the default sampler)
    @classmethod
    def mergeable(cls) -> bool:
        return (cls.distribution in (Distribution.POISSON, Distribution.GAUSSIAN) and cls.temporal
                and cls.structure == "pixel" and cls.sample is Effect.sample
                and cls.temporal_share is Effect.temporal_share)

    def sample(self, signal_dn: np.ndarray, cond: Conditions, rng: np.random.Generator) -> np.ndarray:
        """Noise in DN to add to ``signal_dn`` (before clipping); float32, same shape."""
        s = signal_dn
        if self.distribution is Distribution.POISSON:
            lam = np.broadcast_to(np.asarray(self.electrons(s, cond), dtype=np.float64), s.shape)
            return (cond.dn_per_e * (poisson(rng, lam) - lam)).astype(np.float32)
        if self.distribution is Distribution.GAUSSIAN:
            sigma = np.asarray(self.sigma_dn(s, cond), dtype=np.float32)
            return self._gaussian_field(s.shape, rng) * sigma
        if self.distribution is Distribution.MIXTURE:
            frac, off = self.mixture(s, cond)
            if self.temporal:
                hit = rng.random(s.shape, dtype=np.float32) < frac
            else:
                hit = self.hit_mask(s.shape, frac)
            return np.where(hit, np.asarray(off, dtype=np.float32), np.float32(0.0)).astype(np.float32)
        if self.distribution in (Distribution.MODIFIER, Distribution.RESPONSE):
            return np.zeros(s.shape, dtype=np.float32)
        raise EffectError(f"effect {self.name!r}: quantization is applied by the model, not sampled")


    def _gaussian_field(self, shape: tuple[int, ...], rng: np.random.Generator) -> np.ndarray:
        """Unit-variance noise with the effect's ``structure`` (one value per row or column), new in
        every frame for temporal effects and a fixed pattern otherwise."""
        if self.structure == "pixel" or len(shape) < 2:
            line = shape
        elif self.structure == "row":
            line = (*shape[:-1], 1)
        else:
            line = (*shape[:-2], 1, shape[-1])
        if self.temporal:
            z = standard_normal(rng, line)
        else:
            z = self.pattern(line if self.structure == "pixel" else line[-2:])
        return np.broadcast_to(z, shape)


def _constant(a: np.ndarray) -> bool:
    """True for a scalar or a broadcast (zero-stride) array."""
    return a.ndim == 0 or (a.size > 0 and all(st == 0 for st in a.strides))
