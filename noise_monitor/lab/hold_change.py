"""A change of the camera's noise inside one of the lab's static holds: where the hold's frames stop sharing one noise.

A hold pools up to 64 frames into one measurement per block. When the noise steps while the camera holds still (a
component failing or recovering, an amplifier switching), the pooled variance is a mix of both noises that no
function of the conditions gives: the comparison reads it as a missing law. So each frame's noise is read on its
own, as its deviation from the hold's mean in the blocks that are flat and show no scene change (the scene cancels),
less what each block's offset, brightness and gradients explain (the light's change, sub-pixel vibration), each
block relative to itself over the frames (its intensity's level cancels: no model is needed), and the hold is cut
where those levels change most (:func:`..monitor.noise_change.change_point`: beyond ``CHANGE_SIGMAS`` standard errors
and at least ``CHANGE_DN`` in sigma), unless the conditions explain the change (:func:`cut`). Every part is measured
again on its own, and may be cut again; a part of one frame at the hold's edge is not measured (it has no temporal
noise of its own), its change is kept.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from ..measure.temporal import blocks_of
from ..monitor.config import MonitorConfig
from ..monitor.noise_change import BASIS_BLUR, N_BASIS, Level, change_point, step_beats_ramp

#: most blocks the frames' levels are read on (evenly spread over them): the median over 2,048 blocks of 60
#: degrees of freedom has a standard error of 0.5 % in variance
MAX_BLOCKS = 2048
#: fewest frames on either side of a cut: a lone frame at a hold's edge has no temporal noise of its own, so it is
#: not measured (``measure.LONE``), but its change is kept (else it pools with the other side's frames)
MIN_SIDE_FRAMES = 1
#: fewest frames of a hold searched for a change
MIN_FRAMES = 4
#: smallest change (sigma, DN) cut at: what the live monitor cuts its window at with its default alarm threshold
CHANGE_DN = MonitorConfig.xi_threshold_dn / 2.0


@dataclass(frozen=True)
class Cut:
    """Where a hold's noise changed (``at``: the first frame after it among the hold's, 0: nowhere) and its typical
    temporal sigma (DN) before and after, read on the whole hold's blocks."""

    at: int
    sigma_before_dn: float = math.nan
    sigma_after_dn: float = math.nan


@dataclass(frozen=True)
class NoiseChange:
    """A change of the noise inside a hold, at the first frame of the noise after it."""

    frame: int  # the recording's frame index
    stamp_ns: int
    sigma_before_dn: float  # the typical temporal sigma (DN) of the still blocks before and after it (NaN: unread)
    sigma_after_dn: float

    def summary(self, t0_ns: int) -> dict[str, float | int | None]:
        return {"frame": self.frame, "time_s": round((self.stamp_ns - t0_ns) * 1e-9, 4),
                **{k: round(v, 4) if math.isfinite(v) else None for k, v in (
                    ("sigma_before_dn", self.sigma_before_dn), ("sigma_after_dn", self.sigma_after_dn))}}


def _level_blocks(still: np.ndarray) -> np.ndarray:
    """Indices of the ``still`` blocks (N,) bool the levels are read on: all of them, or MAX_BLOCKS evenly spread."""
    idx = np.flatnonzero(still)
    return idx if idx.size <= MAX_BLOCKS else idx[np.linspace(0, idx.size - 1, MAX_BLOCKS).astype(int)]


def residuals(frames: Sequence[np.ndarray], still: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray]:
    """((k, M, b*b) each frame's deviation from the frames' mean in M of the ``still`` blocks, less what each block's
    offset, brightness and gradients explain in it (a light changing from frame to frame, the camera's sub-pixel
    vibration): regressors from the mean blurred BASIS_BLUR x BASIS_BLUR, as the live monitor's; (k,) each frame's
    light over the mean's in those blocks)."""
    use = _level_blocks(still)
    mean = np.zeros(frames[0].shape, dtype=np.float32)
    for f in frames:  # frame by frame: a hold of big frames is large
        mean += f
    mean /= len(frames)
    blurred = cv2.blur(mean, (BASIS_BLUR, BASIS_BLUR))
    gy, gx = np.gradient(blurred)

    def blocks(a: np.ndarray) -> np.ndarray:
        return blocks_of(a, b)[..., use, :]

    mb = blocks(blurred)
    basis, _ = np.linalg.qr(np.stack([np.ones_like(mb), mb - mb.mean(axis=1, keepdims=True), blocks(gx), blocks(gy)],
                                     axis=2))
    d = np.stack([blocks(f - mean) for f in frames])
    light = 1.0 + d.sum(axis=(1, 2)) / max(float(blocks(mean).sum()), 1e-9)
    coef = np.einsum("mpr,kmp->kmr", basis, d, optimize=True)
    return d - np.einsum("mpr,kmr->kmp", basis, coef, optimize=True), light


def _variances(res: np.ndarray) -> np.ndarray:
    """(k, M) each frame's per-pixel variance estimate in each block: its residual's deviation from the frames'."""
    k = res.shape[0]
    dev = res - res.mean(axis=0)
    return np.einsum("kmp,kmp->km", dev, dev) / (res.shape[2] - N_BASIS) * k / (k - 1)


def cut(res: np.ndarray, light: np.ndarray, stepped: np.ndarray, change_dn: float = CHANGE_DN) -> Cut:
    """The hold's largest material noise change in its :func:`residuals` ``res`` and ``light``; ``Cut(0)`` without
    one or when the conditions explain it: ``stepped`` (k,) frames whose gain or exposure differ from the previous
    frame's (the noise follows them), a light changing in the hold by enough to explain half of it (shot
    noise's variance follows the light at most in proportion: a photon-transfer recording's illumination steps), a
    change no sharper than a ramp (a temperature drifting through the hold: the levels fit a line over the frames
    within ``CHANGE_SIGMAS`` standard errors of the step)."""
    k, m, p = res.shape
    if k < MIN_FRAMES or m == 0:
        return Cut(0)
    var = np.maximum(_variances(res), 1e-12)
    dofs = np.full(m, float(p - N_BASIS))
    typical = np.sqrt(np.median(var, axis=1))
    levels = [Level(np.log(var[i]), dofs, float(typical[i])) for i in range(k)]
    at = change_point(levels, change_dn, MIN_SIDE_FRAMES)
    if not at or stepped[at]:
        return Cut(0)
    # a side of one frame: its variance from the whole hold's mean (its own mean is itself)
    before, after = sigmas(*[(_variances(res[lo:hi]) if hi - lo > 1 else var[lo:hi]).mean(axis=0)
                             for lo, hi in ((0, at), (at, k))])
    noise = 2.0 * abs(math.log(max(after, 1e-9) / max(before, 1e-9)))
    log_light = np.log(np.maximum(light, 1e-9))
    if np.max(np.abs(log_light - np.median(log_light))) >= noise / 2.0:
        return Cut(0)
    return Cut(at, before, after) if step_beats_ramp(levels, at) else Cut(0)


def sigmas(before: np.ndarray, after: np.ndarray) -> tuple[float, float]:
    """The typical temporal sigma (DN) before and after a change from the same blocks' per-pixel variances (DN^2)
    on either side: the median before, and that plus the median of the blocks' changes (white noise added changes
    every block's variance alike; the median after would also move with the blocks' spread of intensities). NaN
    without blocks."""
    if before.size == 0:
        return math.nan, math.nan
    typical = float(np.median(before))
    return math.sqrt(max(typical, 0.0)), math.sqrt(max(typical + float(np.median(after - before)), 0.0))
