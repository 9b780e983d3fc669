"""Fast physics-model prediction for a batch of patches: histogram x tables instead of per-pixel interpolation.

``NoiseModel.predict`` on an (N, H, W) clean-intensity batch interpolates the model's moment tables at
every pixel. Linear interpolation is linear in the table values, so the patch means of E[n|v] and
E[n^2|v] equal (linear-weight histogram of the patch on the table grid) @ (table): one bincount per
patch and a small matrix product, with the same result.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np

from noise_monitor.physics import CameraMetadata, NoiseModel
from noise_monitor.physics.constants import DN_MAX
from noise_monitor.physics.grid import grid_position, histogram


def histogram_weights(maps: np.ndarray) -> np.ndarray:
    """(N, G) linear-interpolation weights of each map's pixels on the grid 0, step, ..., 255 (rows sum to 1)."""
    levels = np.clip(maps.reshape(maps.shape[0], -1).astype(np.float64), 0.0, DN_MAX)
    return histogram(*grid_position(levels))


def predict_patches(model: NoiseModel, maps: np.ndarray, meta: CameraMetadata, mode: str = "joint") -> dict[str, np.ndarray]:
    """Predicted sigma (DN) per effect and ``"total"`` for each clean-intensity map of an (N, H, W) batch;
    equal to ``model.predict(maps, meta, mode)``."""
    return predict_histograms(model, histogram_weights(maps), meta, mode)


def predict_histograms(model: NoiseModel, weights: np.ndarray, meta: CameraMetadata, mode: str = "joint"
                       ) -> dict[str, np.ndarray]:
    """:func:`predict_patches` of maps given by their :func:`histogram_weights` (N, G): for maps seen at many
    metadata sets."""
    out: dict[str, np.ndarray] = {}
    for name, (t1, t2) in model.tables(meta, mode).items():
        var = weights @ t2 - (weights @ t1) ** 2
        out[name] = np.sqrt(np.maximum(var, 0.0))
    if "total" not in out:  # sequential protocol: total = sqrt of the sum of squares
        out["total"] = np.sqrt(sum(out[e.name] ** 2 for e in model.noise_effects))
    return out


def _total(model: NoiseModel, tables: Mapping[str, tuple[np.ndarray, np.ndarray]],
           sigma: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
    """The total sigma from the model's tables by ``sigma(E[n|v], E[n^2|v])``: the tabulated total, or the sequential
    protocol's sum of squares over the noise effects."""
    if "total" in tables:
        return sigma(*tables["total"])
    return np.sqrt(sum(sigma(*tables[e.name]) ** 2 for e in model.noise_effects))


def predict_total(model: NoiseModel, weights: np.ndarray, meta: CameraMetadata, mode: str = "joint") -> np.ndarray:
    """The ``"total"`` of :func:`predict_histograms` alone (one table product where the model tabulates it)."""
    return _total(model, model.tables(meta, mode),
                  lambda t1, t2: np.sqrt(np.maximum(weights @ t2 - (weights @ t1) ** 2, 0.0)))


def level_positions(levels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Grid positions of single intensities (DN) for :func:`predict_levels`."""
    return grid_position(np.clip(np.asarray(levels, dtype=np.float64).reshape(-1), 0.0, DN_MAX))


def predict_levels(model: NoiseModel, positions: tuple[np.ndarray, np.ndarray], meta: CameraMetadata,
                   mode: str = "joint") -> np.ndarray:
    """The total sigma (DN) at single intensities (:func:`level_positions`): :func:`predict_total` of maps of one
    intensity each, whose histograms hold two grid points (the tables' linear interpolation)."""
    i0, frac = positions

    def sigma(t1: np.ndarray, t2: np.ndarray) -> np.ndarray:
        m1, m2 = (t[i0] * (1.0 - frac) + t[i0 + 1] * frac for t in (t1, t2))
        return np.sqrt(np.maximum(m2 - m1**2, 0.0))

    return _total(model, model.tables(meta, mode), sigma)
