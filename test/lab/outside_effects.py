"""Four camera effects the library does not have, simulated directly in numpy (not through the plug-in
API), and the plug-ins a user would write for them from docs/physics.md.

The camera is the paper's model (``NoiseModel().simulate``) on the lab's tiled chart over a gain /
exposure / temperature sweep, moved between conditions; each effect is added to its frames here:

- ``amp_glow``: a readout amplifier glowing in the top-right corner: glow electrons
  ``rate * t * exp(-d / radius)`` (d: distance to the corner in sensor sizes), their shot noise (the
  camera's dark-frame subtraction removes their mean);
- ``row_noise``: temporal row noise: every row of every frame gets its own offset N(0, sigma^2), in DN
  (after the gain);
- ``nonlinearity``: the response compresses towards full well, ``out = x - beta x^3 / 255^2``, applied to
  the noisy linear signal (the noise shrinks by the local slope);
- ``rts``: random telegraph pixels: a fixed fraction of pixels, each frame "up" with probability q by a
  fixed amplitude in DN.

:func:`campaign_bag` applies the same effects to a field-like ``simulate-bag`` campaign (photographic scene,
sub-pixel pans, auto-exposure, temperature drifting every frame, vignetting) through the simulator's
frame hook: in sensor coordinates (the glow stays in the corner, the telegraph pixels are fixed sensor
pixels while the scene pans), with each frame's true metadata, before the 8-bit quantization.
"""
from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any

import numpy as np

from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.lab.synthetic import DEFAULT_SWEEP, tiled_scene
from noise_monitor.monitor.frame import Frame
from noise_monitor.physics import CameraMetadata, CameraProfile, NoiseModel

TRUTH = {
    "amp_glow": {"rate_e_per_s": 1.0e5, "radius": 0.3},
    "row_noise": {"sigma_dn": 2.0},
    "nonlinearity": {"beta": 0.2},
    "rts": {"fraction": 0.02, "q": 0.5, "amplitude_dn": 16.0},
}


def _compress(x: np.ndarray, beta: float) -> np.ndarray:
    return x - beta * x**3 / 255.0**2


def _sensor_maps(height: int, width: int, fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(each pixel's distance to the top-right sensor corner in sensor sizes, the telegraph pixels)."""
    y, x = np.mgrid[0:height, 0:width]
    dist = np.hypot((y + 0.5) / height - 0.0, (x + 0.5) / width - 1.0)
    return dist, np.random.default_rng(seed + 1).random((height, width)) < fraction


def _apply(effect: str | None, t: dict[str, float], img: np.ndarray, meta: CameraMetadata,
           rng: np.random.Generator, dist: np.ndarray, hit: np.ndarray) -> np.ndarray:
    """One frame (float DN, before quantization) with the outside ``effect`` under its true metadata."""
    if effect == "amp_glow":
        lam = t["rate_e_per_s"] * meta.exposure_time_s * np.exp(-dist / t["radius"])
        dn_per_e = 255.0 * meta.gain / meta.full_well_e
        return img + dn_per_e * (rng.poisson(lam) - lam)  # dark-frame subtracted: the noise stays
    if effect == "row_noise":
        return img + t["sigma_dn"] * rng.standard_normal((img.shape[0], 1))
    if effect == "nonlinearity":
        return _compress(img, t["beta"])
    if effect == "rts":
        return img + t["amplitude_dn"] * (hit & (rng.random(img.shape) < t["q"]))
    if effect is not None:
        raise ValueError(effect)
    return img


def simulate(profile: CameraProfile, effect: str | None, frames_per_condition: int = 6, width: int = 160,
             height: int = 128, seed: int = 0, truth: dict[str, float] | None = None) -> list[Frame]:
    """Frames of the paper's camera plus one outside ``effect`` (None: clean) with the parameters of
    ``TRUTH`` (``truth`` overrides them), 8-bit output."""
    t = {**TRUTH.get(effect, {}), **(truth or {})}
    model = NoiseModel()
    rng = np.random.default_rng(seed)
    scene = tiled_scene(height, width, seed)
    dist, hit = _sensor_maps(height, width, t.get("fraction", 0.0), seed)
    frames = []
    for c, (gain_db, exposure, temp) in enumerate(DEFAULT_SWEEP):
        meta = profile.metadata(gain_db=gain_db, exposure_time_s=exposure, sensor_temperature_c=temp)
        clean = np.roll(scene, (3 * c, 5 * c), axis=(0, 1)).astype(np.float64)
        for _ in range(frames_per_condition):
            noisy, _ = model.simulate(clean.astype(np.float32), meta, rng, per_source=False)
            img = _apply(effect, t, noisy.astype(np.float64), meta, rng, dist, hit)
            i = len(frames)
            frames.append(Frame(i * 50_000_000, np.rint(np.clip(img, 0, 255)).astype(np.float32), meta, index=i))
    return frames


class SensorEffect:
    """An outside effect as the simulator's frame hook (:class:`noise_monitor.bag.simulate.FrameHook`):
    in sensor coordinates, with each frame's true metadata, drawing from its own generator (``seed``)."""

    def __init__(self, effect: str | None, truth: dict[str, float], seed: int) -> None:
        self.effect, self.params, self.seed = effect, dict(truth), seed
        self._rng = np.random.default_rng(seed)
        self._maps: tuple[np.ndarray, np.ndarray] | None = None
        self.seen: list[CameraMetadata] = []  # the true metadata of every frame, in order

    @property
    def truth(self) -> dict[str, Any]:
        return {"outside_effect": self.effect, "params": self.params, "seed": self.seed}

    def __call__(self, index: int, clean: np.ndarray, noisy: np.ndarray, meta: CameraMetadata) -> np.ndarray:
        if self._maps is None:
            self._maps = _sensor_maps(*noisy.shape, self.params.get("fraction", 0.0), self.seed)
        self.seen.append(meta)
        return _apply(self.effect, self.params, noisy.astype(np.float64), meta, self._rng, *self._maps)


def campaign_bag(path: str | Path, effect: str | None, scenario: str = "campaign", seed: int = 11,
                 frames: int = 120, width: int = 320, height: int = 256,
                 truth: dict[str, float] | None = None) -> Path:
    """A field-like ``simulate-bag`` campaign (EV76C661, 10 Hz) with one outside ``effect`` (None: the
    clean campaign, the same noise realization) at ``TRUTH`` (``truth`` overrides), written as MCAP."""
    hook = SensorEffect(effect, {**TRUTH.get(effect, {}), **(truth or {})}, seed + 1000) if effect else None
    return simulate_bag(path, "ev76c661", scenario, frames=frames, width=width, height=height, fps=10.0,
                        seed=seed, frame_hook=hook)


#: the plug-ins, as a user writes them for these effects with the API of docs/physics.md
PLUGINS = {
    "amp_glow": textwrap.dedent('''
        import numpy as np
        from noise_monitor.physics.effects import Effect, Param


        class CornerGlow(Effect):
            """Amplifier glow in the top-right corner: shot noise of glow electrons growing with exposure."""

            name = "corner_glow"
            distribution = "poisson"
            spatial = True
            params = (
                Param("rate_e_per_s", "e-/s", 1e4, (0.0, 1e7), description="glow electrons per second at the corner"),
                Param("radius", "1", 0.3, (0.02, 2.0), description="decay length, in sensor heights"),
            )
            description = "Amplifier glow: shot noise of electrons leaking from a readout amplifier in a corner."
            signature = "glow {rate_e_per_s:.3g} e-/s in the top-right corner, radius {radius:.2f}"

            def electrons(self, signal_dn, cond):
                d = np.hypot(cond.where.y - 0.0, cond.where.x - 1.0)
                lam = self.rate_e_per_s * cond.exposure_time_s * np.exp(-d / self.radius)
                return np.broadcast_to(lam, np.broadcast_shapes(np.shape(signal_dn), np.shape(lam)))
    '''),
    "row_noise": textwrap.dedent('''
        import numpy as np
        from noise_monitor.physics.effects import Effect, Param


        class TemporalRowNoise(Effect):
            """Every row gets a new offset in every frame (a noisy row reference)."""

            name = "temporal_row_noise"
            distribution = "gaussian"
            temporal = True
            structure = "row"
            params = (Param("sigma_dn", "DN", 0.5, (0.0, 20.0), description="std of the per-row offsets"),)
            description = "Temporal row noise: row offsets that change from frame to frame."
            signature = "row offsets changing from frame to frame, std {sigma_dn:.2f} DN"

            def sigma_dn(self, signal_dn, cond):
                return np.broadcast_to(self.values["sigma_dn"], np.shape(signal_dn))
    '''),
    "nonlinearity": textwrap.dedent('''
        import numpy as np
        from noise_monitor.physics.effects import Effect, Param

        _X = np.linspace(0.0, 255.0, 2551)  # the linear signal (clipped to 255, where the response rises)


        class CubicCompression(Effect):
            """The response compresses towards full well: out = x - beta x^3 / 255^2."""

            name = "cubic_compression"
            distribution = "response"
            params = (Param("beta", "1", 0.1, (0.0, 0.3), description="cubic compression coefficient"),)
            description = "Response non-linearity near full well: the output compresses, and so does the noise."
            signature = "response compressing towards full well, beta = {beta:.3f}"

            def linear(self, signal_dn, cond):  # the linear signal behind an output level
                return np.interp(np.asarray(signal_dn, dtype=float), _X - self.beta * _X**3 / 255.0**2, _X)

            def slope(self, signal_dn, cond):
                x = self.linear(signal_dn, cond)
                return np.maximum(1.0 - 3.0 * self.beta * x**2 / 255.0**2, 0.0)
    '''),
    "rts": textwrap.dedent('''
        import numpy as np
        from noise_monitor.physics.effects import Effect, Param


        class TelegraphPixels(Effect):
            """Random telegraph pixels: a fixed set of pixels toggling between two levels from frame to frame."""

            name = "telegraph_pixels"
            distribution = "mixture"
            temporal = True
            params = (
                Param("fraction", "1", 0.01, (0.0, 0.2), description="fraction of telegraph pixels"),
                Param("amplitude_dn", "DN", 5.0, (0.0, 100.0), description="step between their two levels"),
                Param("q", "1", 0.5, (0.05, 0.95), fittable=False, description="probability of the upper level"),
            )
            description = "Random telegraph pixels: temporal (they toggle) and fixed (always the same pixels)."
            signature = "{fraction_pct:.2f} % telegraph pixels toggling by {amplitude_dn:.1f} DN"

            def mixture(self, signal_dn, cond):  # in one frame: fraction * q of the pixels are up
                return self.fraction * self.q, np.broadcast_to(self.amplitude_dn, np.shape(signal_dn))

            def temporal_share(self, signal_dn, cond):  # frame-to-frame part of the variance
                f, q = self.fraction, self.q
                return (1.0 - q) / (1.0 - f * q)

            def fixed_mixture(self, signal_dn, cond):  # in the frame average: the pixels sit q * amplitude up
                return self.fraction, np.broadcast_to(self.q * self.amplitude_dn, np.shape(signal_dn))

            def sample(self, signal_dn, cond, rng):
                hit = self.hit_mask(np.shape(signal_dn), self.fraction)
                up = rng.random(np.shape(signal_dn)) < self.q
                return np.where(hit & up, np.float32(self.amplitude_dn), np.float32(0.0))
    '''),
}
#: the plug-in's effect name and its parameter that carries the truth, per outside effect
PLUGIN_TRUTH = {
    "amp_glow": ("corner_glow", "rate_e_per_s", TRUTH["amp_glow"]["rate_e_per_s"]),
    "row_noise": ("temporal_row_noise", "sigma_dn", TRUTH["row_noise"]["sigma_dn"]),
    "nonlinearity": ("cubic_compression", "beta", TRUTH["nonlinearity"]["beta"]),
    "rts": ("telegraph_pixels", "fraction", TRUTH["rts"]["fraction"]),
}
