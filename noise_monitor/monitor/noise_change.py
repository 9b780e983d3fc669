"""A change of the camera's noise inside a static hold: where the hold's frames stop sharing one noise.

The hold's window pools up to ``temporal_frames`` frames. When the camera's noise steps while it looks at a still
scene (a component failing, an amplifier switching, the fault ending), the pooled measurement would lag the step
by up to the window's length and the alarm with it. So each frame's temporal noise is read on its own: from its
difference with the previous frame (the scene cancels), on the blocks the hold's last measurement accepted as pure
noise, after what the light's change and sub-pixel motion leave there is regressed out (each block's offset,
brightness and gradients, from the measurement's temporal mean blurred first: the mean holds a share of the
previous frame's noise, which its unblurred pixels would regress out of the difference, 8 % of the variance for a
mean of 4 frames), and relative to what the model expects at both frames' metadata (a temperature drifting
through the hold changes the dark-current noise as the model says it does). Where the hold's measurement fitted the
light row by row (LEDs dimmed by pulse-width modulation: sharp bands rolling from frame to frame), each row of the
difference is first rid of its projection on the row of the temporal mean (the light's change there, one gain per
row). The window is cut where the frames'
levels change most, when the change is significant (``CHANGE_SIGMAS`` standard errors) and large enough to
matter to the alarm (``change_dn`` in sigma).

The light can step too (a lamp switched, a cloud, a door opened): the shot noise follows it, and a window pooling
both lights measures neither, lagging by up to a window (EMVA set 003's irradiance series: 1.056 DN read on a
0.902 DN hold 10 frames after the step). :func:`light_step` finds a step of the frames' brightness beyond what their
exposure and gain explain, set against the light's own scatter from frame to frame (flicker, rolling bands).
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from noise_monitor.measure.temporal import blocks_of, row_gain
from noise_monitor.physics import CameraMetadata

#: standard errors by which the frames after a cut must differ from those before it
CHANGE_SIGMAS = 5.0
#: box blur (px) of the measurement's temporal mean before the regressors are taken from it
BASIS_BLUR = 3
#: regressors per block: offset, brightness, x and y gradient
N_BASIS = 4
#: standard error of a median of many values over that of their mean
MEDIAN_EFFICIENCY = 1.2533
#: standard deviation of Gaussian values over the median of their absolute values
ROBUST_SD = 1.4826
#: a step of a still hold's light (relative) that cuts its window: the shot noise moves by half of it
LIGHT_STEP_REL = 0.10
#: frames of one light on either side of such a step (one odd frame is no step)
LIGHT_STEP_SIDE = 2

#: the model's temporal sigma (K,) of a hold's patches over their accepted blocks at a frame's metadata
ModelAt = Callable[[CameraMetadata], np.ndarray]


@dataclass(frozen=True)
class Level:
    """One frame's temporal noise relative to the model: (K,) log variance ratio (NaN for a patch without
    accepted blocks) and the residual degrees of freedom behind each."""

    log_ratio: np.ndarray
    dof: np.ndarray
    model_dn: float  # the model's temporal sigma at the frame's metadata (median over the patches)


@dataclass(frozen=True)
class LevelReference:
    """What each frame's noise level is read on: a hold measurement's accepted blocks and scene (see module)."""

    basis: np.ndarray  # (M, b*b, N_BASIS) orthonormal regressors of the M accepted blocks
    selected: np.ndarray  # (K*N,) bool: the accepted blocks, patch after patch
    shape: tuple[int, int]  # (K, N)
    block: int
    model: ModelAt
    frames: int  # of the measurement it was made from
    rows: np.ndarray | None = None  # (K, s, s) the temporal mean when the light changes row by row, else None

    @classmethod
    def of(cls, mean_patches: np.ndarray, accepted: np.ndarray, frames: int, block: int,
           model: ModelAt, light_rows: bool = False) -> LevelReference | None:
        """From a measurement of ``frames`` frames: its temporal mean (K, s, s) and accepted blocks (K, N), and
        whether it fitted the light row by row; None without accepted blocks."""
        if not accepted.any():
            return None
        size = (BASIS_BLUR, BASIS_BLUR)
        mean = np.stack([cv2.blur(m, size) for m in np.asarray(mean_patches, dtype=np.float32)])
        gy, gx = np.gradient(mean, axis=(1, 2))
        selected = accepted.reshape(-1)

        def accepted_blocks(a: np.ndarray) -> np.ndarray:
            return blocks_of(a, block).reshape(-1, block * block)[selected]

        mb = accepted_blocks(mean)
        design = np.stack([np.ones_like(mb), mb - mb.mean(axis=1, keepdims=True), accepted_blocks(gx),
                           accepted_blocks(gy)], axis=2)
        basis, _ = np.linalg.qr(design)
        rows = np.asarray(mean_patches, dtype=np.float32) if light_rows else None
        return cls(basis, selected, accepted.shape, block, model, frames, rows)

    def level(self, patches: np.ndarray, previous: np.ndarray, meta: CameraMetadata,
              previous_meta: CameraMetadata) -> Level:
        """The temporal noise of ``patches`` (K, s, s) in their difference with the ``previous`` frame's, over
        the model's at both frames' metadata."""
        diff = np.asarray(patches, np.float32) - previous
        per_block = float(self.block**2 - N_BASIS)
        if self.rows is not None:  # each row's gain taken out: 1 / s of its noise with it
            diff = diff - row_gain(diff, self.rows)[..., None] * self.rows
            per_block -= self.block**2 / self.rows.shape[2]
        d = blocks_of(diff, self.block).reshape(-1, self.block**2)[self.selected]
        c = (d[:, None, :] @ self.basis)[:, 0, :]
        energy = np.zeros(self.selected.size)
        energy[self.selected] = np.einsum("mn,mn->m", d, d) - np.einsum("mr,mr->m", c, c)
        dof = self.selected.reshape(self.shape).sum(axis=1) * per_block
        model_dn = self.model(meta)
        now = model_dn**2
        expected = now + (now if previous_meta == meta else self.model(previous_meta) ** 2)
        ratio = energy.reshape(self.shape).sum(axis=1) / np.maximum(dof, 1) / np.maximum(expected, 1e-12)
        with np.errstate(divide="ignore"):
            log_ratio = np.where((dof > 0) & (ratio > 0) & (expected > 1e-12), np.log(ratio), np.nan)
        return Level(log_ratio, dof, float(np.nanmedian(model_dn)) if np.isfinite(model_dn).any() else math.nan)


def _relative(found: Sequence[Level]) -> tuple[np.ndarray, float] | None:
    """(each frame's level: the median over the patches of its log ratio less that patch's median over the frames, a
    patch's own offset (its blocks' intensities); their standard error, that of the median of Gaussian variance
    estimates of the patches' degrees of freedom), or None without a patch that every frame has."""
    ratios = np.array([lv.log_ratio for lv in found])
    ok = np.isfinite(ratios).all(axis=0)
    if not ok.any():
        return None
    z = np.median(ratios[:, ok] - np.median(ratios[:, ok], axis=0), axis=1)
    dof = float(np.median(np.array([lv.dof[ok] for lv in found])))
    return z, MEDIAN_EFFICIENCY * math.sqrt(2.0 / dof / ok.sum())


def _step_beats_line(z: np.ndarray, sd: float, at: int) -> bool:
    """Whether a step at ``at`` fits the series ``z`` better than a line by more than ``CHANGE_SIGMAS`` of ``sd``."""
    t = np.arange(z.size)
    step = z - np.where(t < at, z[:at].mean(), z[at:].mean())
    line = z - np.polyval(np.polyfit(t, z, 1), t)
    return bool((np.sum(line**2) - np.sum(step**2)) / sd**2 > CHANGE_SIGMAS**2)


def step_beats_ramp(levels: Sequence[Level], at: int) -> bool:
    """Whether a step at frame ``at`` fits the frames' ``levels`` better than a line over the frames by more than
    ``CHANGE_SIGMAS`` standard errors (a change no sharper than a ramp, e.g. a temperature drifting, does not)."""
    relative = _relative(levels)
    return relative is not None and _step_beats_line(*relative, at)


def _steps(z: np.ndarray, sd: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For every cut of the series ``z`` (values of ``sd`` standard error each): (values before the cut, the mean
    after less the mean before, that step in standard errors)."""
    n = z.size
    j = np.arange(1, n)
    before = np.cumsum(z)[:-1]
    step = (z.sum() - before) / (n - j) - before / j
    return j, step, np.abs(step) / (sd * np.sqrt(1.0 / (n - j) + 1.0 / j))


def change_point(levels: Sequence[Level | None], change_dn: float, min_side: int = 1) -> int:
    """Index of the first frame after the largest change of the frames' noise ``levels`` (None: a frame without
    a level) that is both significant and at least ``change_dn`` in sigma at the newest frame's model, with at
    least ``min_side`` levels on either side; 0 without one. The frames' levels relative to each patch:
    :func:`_relative`."""
    found = [(i, lv) for i, lv in enumerate(levels) if lv is not None]
    if len(found) < 2 * max(min_side, 1) or not math.isfinite(change_dn):
        return 0
    at = [i for i, _ in found]
    relative = _relative([lv for _, lv in found])
    if relative is None:
        return 0
    z, sd = relative
    n = len(z)
    j, step, score = _steps(z, sd)
    large = found[-1][1].model_dn * np.abs(np.expm1(step / 2.0)) >= change_dn
    score = np.where(large & (score > CHANGE_SIGMAS) & (j >= min_side) & (n - j >= min_side), score, 0.0)
    return at[int(j[np.argmax(score)])] if score.max() > 0 else 0


def light_step(light: np.ndarray) -> int:
    """Index of the first frame after the largest step of the frames' ``light`` (log of each frame's brightness over
    what its exposure and gain give) when it is a step (:func:`_step_beats_line`), significant (``CHANGE_SIGMAS`` of
    the frame-to-frame scatter, robust: the step's own difference is one of many), sharp (at least ``LIGHT_STEP_REL``
    between the two frames either side of it, and as much between the means before and after) and has
    ``LIGHT_STEP_SIDE`` frames on either side; 0 without one or with a frame of unknown light (NaN: a dark frame). A
    light flickering from frame to frame or changing smoothly (a ramp, a slow swell) has no such step."""
    z = np.asarray(light, dtype=np.float64)
    n = z.size
    if n < 2 * LIGHT_STEP_SIDE or not np.isfinite(z).all():
        return 0
    sd = max(ROBUST_SD * float(np.median(np.abs(np.diff(z)))) / math.sqrt(2.0), 1e-9)
    j, step, score = _steps(z, sd)
    best = int(np.argmax(score))  # where the light steps, wherever that is; then whether it is a step to cut at
    at = int(j[best])
    least = math.log1p(LIGHT_STEP_REL)
    return at if (min(at, n - at) >= LIGHT_STEP_SIDE and abs(step[best]) >= least and abs(z[at] - z[at - 1]) >= least
                  and score[best] > CHANGE_SIGMAS and _step_beats_line(z, sd, at)) else 0
