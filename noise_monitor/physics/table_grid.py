"""Moment tables interpolated over the dynamic conditions: no recomputation per new metadata set.

Real drivers report a temperature that changes every frame and auto-exposure/auto-gain that change
continuously; the exact tables of :class:`~noise_monitor.physics.NoiseModel` cost tens of milliseconds per
metadata set. :class:`TableGrid` computes exact tables only at the nodes of a lattice over the three
dynamic fields - gain in dB, the logarithm of the exposure time and the temperature - for the camera's
static fields, lazily and cached (LRU), and interpolates between the 8 nodes around the stated metadata:
E[n|v] linearly and the variance E[n^2|v] - E[n|v]^2 linearly in its logarithm (every source's variance
is a power law in gain and exposure and nearly exponential in temperature, so the log is close to
multilinear in these coordinates). With the default steps (1.5 dB, x1.42 exposure, 5 K) the per-level
sigma stays within 0.5 % or 0.01 DN of the exact tables over the paper's ranges
(``test/test_table_grid.py``; the worst cells are next to the clipping at 0 and 255 DN).
A metadata set whose surrounding nodes would leave the valid metadata ranges gets exact tables.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from cachetools import LRUCache

from .metadata import STATIC_FIELDS, CameraMetadata, MetadataError

Tables = dict[str, tuple[np.ndarray, np.ndarray]]
#: Below this variance (DN^2) a node's variance is interpolated linearly instead of in its logarithm.
VAR_FLOOR_DN2 = 1e-12


@dataclass(frozen=True)
class GridSpec:
    """Lattice steps of the interpolation: nodes at i * step (gain dB, ln exposure s, temperature degC)."""

    gain_step_db: float = 1.5
    log_exposure_step: float = 0.35
    temperature_step_c: float = 5.0
    #: exact node tables kept (each ~8 KB per table of the model), least recently used dropped first
    max_nodes: int = 2048
    #: held metadata gets exact tables: a new metadata set is computed exactly when the previous one served
    #: at least this many table requests (frames) - a camera's first set too - and interpolated when the
    #: conditions change faster (0 = always interpolate). Exact tables of one set cost less than a new
    #: lattice cell's nodes; the lattice pays off only for conditions that drift frame by frame.
    held_exact_requests: int = 0

    def __post_init__(self) -> None:
        for name in ("gain_step_db", "log_exposure_step", "temperature_step_c"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"GridSpec.{name} must be a positive number, got {value!r}")
        if int(self.max_nodes) < 8:
            raise ValueError(f"GridSpec.max_nodes must be at least 8, got {self.max_nodes!r}")

    def coordinates(self, meta: CameraMetadata) -> np.ndarray:
        """Lattice coordinates (gain, exposure, temperature) of a metadata set."""
        return np.array([meta.gain_db / self.gain_step_db, math.log(meta.exposure_time_s) / self.log_exposure_step,
                         meta.sensor_temperature_c / self.temperature_step_c])

    def node_metadata(self, meta: CameraMetadata, node: tuple[int, int, int]) -> CameraMetadata:
        """``meta`` moved to a lattice node (raises MetadataError where the node is out of range)."""
        i, j, k = node
        return meta.replace(gain_db=i * self.gain_step_db, exposure_time_s=math.exp(j * self.log_exposure_step),
                            sensor_temperature_c=k * self.temperature_step_c)


def static_key(meta: CameraMetadata) -> tuple:
    """The static fields of the metadata: identify a camera's lattice."""
    return tuple(getattr(meta, name) for name in STATIC_FIELDS) + (meta.bit_depth,)


_CORNERS = np.array([(a, b, c) for a in (0, 1) for b in (0, 1) for c in (0, 1)])


class TableGrid:
    """Interpolated moment tables for any metadata, from exact tables at lattice nodes.

    ``exact(meta, mode)`` computes the exact tables (``NoiseModel._exact_tables``); its errors (e.g. a
    failing plug-in effect) propagate unchanged. ``surrogate(meta, mode)``, optional, computes cheap
    approximate tables for some of the names (``NoiseModel._surrogate_tables``): for those, the
    interpolation carries only the exact tables' deviation from the surrogate (E[n|v] as a difference,
    the variance as a ratio) and the surrogate is evaluated at the stated metadata itself. The clipping at
    0 and 255 DN - where a moving offset or width makes the exact tables bend sharply with the conditions -
    is then mostly in the surrogate, and what is interpolated is smooth.
    """

    def __init__(self, exact: Callable[[CameraMetadata, str], Tables], spec: GridSpec | None = None,
                 surrogate: Callable[[CameraMetadata, str], Tables] | None = None) -> None:
        self.exact = exact
        self.surrogate = surrogate
        self.spec = spec or GridSpec()
        self._nodes: LRUCache[tuple, tuple[tuple[str, ...], np.ndarray]] = LRUCache(self.spec.max_nodes)
        self._cells: LRUCache[tuple, tuple[tuple[str, ...], np.ndarray] | None] = LRUCache(16)
        self.nodes_computed = 0

    def _surrogate(self, meta: CameraMetadata, mode: str, names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
        """Surrogate E[n|v] and variance (names, G): 0 and 1 for names without a surrogate."""
        approx = self.surrogate(meta, mode) if self.surrogate else {}
        first = next(iter(approx.values()), None)
        g = len(first[0]) if first is not None else 0
        a1, avar = np.zeros((len(names), g)), np.ones((len(names), g))
        for i, n in enumerate(names):
            if n in approx:
                a1[i], avar[i] = _mean_var(*approx[n])
        return a1, avar

    def _node(self, key: tuple, meta: CameraMetadata, mode: str,
              node: tuple[int, int, int]) -> tuple[tuple[str, ...], np.ndarray]:
        """(names, float64 (names, 4, G)) at a node, cached: E[n|v] minus the surrogate's, log variance
        minus the surrogate's, the variance itself and 1 where both variances are above the floor."""
        ck = (key, mode, node)
        hit = self._nodes.get(ck)
        if hit is not None:
            return hit
        node_meta = self.spec.node_metadata(meta, node)
        tables = self.exact(node_meta, mode)
        names = tuple(tables)
        m1, var = (np.stack(x) for x in zip(*(_mean_var(*tables[n]) for n in names)))
        a1, avar = self._surrogate(node_meta, mode, names)
        if a1.shape[-1] == 0:
            a1, avar = np.zeros_like(m1), np.ones_like(var)
        ok = (var > VAR_FLOOR_DN2) & (avar > VAR_FLOOR_DN2)
        with np.errstate(divide="ignore"):
            log_ratio = np.where(ok, np.log(np.where(ok, var, 1.0)) - np.log(np.where(ok, avar, 1.0)), 0.0)
        entry = (names, np.stack([m1 - a1, log_ratio, var, ok.astype(float)], axis=1))
        self._nodes[ck] = entry
        self.nodes_computed += 1
        return entry

    def _cell(self, meta: CameraMetadata, mode: str, base: tuple[int, int, int]
              ) -> tuple[tuple[str, ...], np.ndarray] | None:
        """(names, the 8 corner nodes stacked) of a lattice cell, None where a corner is out of range;
        the last cells are kept (the conditions drift slowly: most frames stay in their cell)."""
        key = static_key(meta)
        ck = (key, mode, base)
        if ck in self._cells:
            return self._cells[ck]
        i, j, k = base
        try:  # the extreme corners within the valid ranges (then all corners are)
            self.spec.node_metadata(meta, (i, j, k))
            self.spec.node_metadata(meta, (i + 1, j + 1, k + 1))
        except MetadataError:
            cell = None
        else:
            corners = [self._node(key, meta, mode, (i + a, j + b, k + c)) for a, b, c in _CORNERS]
            cell = (corners[0][0], np.stack([c[1] for c in corners]))
        self._cells[ck] = cell
        return cell

    def tables(self, meta: CameraMetadata, mode: str) -> Tables:
        """Tables for ``meta`` interpolated between the 8 surrounding nodes (exact outside the lattice)."""
        u = self.spec.coordinates(meta)
        base = np.floor(u).astype(np.int64)
        frac = u - base
        cell = self._cell(meta, mode, (int(base[0]), int(base[1]), int(base[2])))
        if cell is None:  # a corner beyond the valid ranges (e.g. an exposure above 600 s / e^0.35)
            return self.exact(meta, mode)
        names, stack = cell  # stack: (8, names, 4, G)
        weights = np.prod(np.where(_CORNERS == 1, frac, 1.0 - frac), axis=1)
        d_m1, d_log, lin_var, _ = np.tensordot(weights, stack, axes=1).transpose(1, 0, 2)
        ok = stack[:, :, 3].min(axis=0) > 0.5
        a1, avar = self._surrogate(meta, mode, names) if self.surrogate else (0.0, 1.0)
        m1 = a1 + d_m1
        var = np.where(ok & (avar > VAR_FLOOR_DN2), avar * np.exp(d_log), lin_var)
        m2 = var + m1**2
        return {n: (m1[i], m2[i]) for i, n in enumerate(names)}


def _mean_var(m1: np.ndarray, m2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return m1, np.maximum(m2 - m1**2, 0.0)
