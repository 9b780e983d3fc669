"""Temporal noise from frame differences where the scene is static.

Three steps, no model and no lab dependencies (the live monitor reuses them for ``sigma_temporal``):

1. :func:`global_shift`: the camera's global motion between two frames by phase correlation
   (OpenCV, Hanning window, sub-pixel; :func:`camera_shift` checks it on downsampled frames, where a
   sensor-fixed pattern cannot pin it at 0); :func:`static_runs` cuts a sequence into runs of frames that stay
   within ``HOLD_SHIFT_PX`` of the run's first frame (a vibrating camera returns about one pose; a pan or a slow
   drift leaves it).
2. :func:`block_temporal` on a static run: first each frame's light change against the run mean (a flicker, a
   rolling shutter's bands under lamps on the mains: :func:`light_change`) is fitted on the blocks' means and
   taken out (:meth:`LightChange.undo`: noise that follows the light is weighed without bias); then per B x B block, each frame's deviation from the run's temporal mean is regressed on what scene changes would put there (a per-frame offset, a brightness
   scaling ``mean - <mean>``, and sub-pixel motion: the mean image's x and y gradients; when the light changed, also a
   brightness changing along the block's rows: the sharp edges of an LED's pulse-width-modulated bands, which the
   light's smooth profile does not follow, are no noise). For pure noise
   the explained energy is a small, F-distributed fraction; a block is accepted when its F-test
   p-value exceeds ``p_value`` (residual motion, light changing in part of the view or a moving object reject it).
3. For accepted blocks, the temporal variance is the per-pixel variance over the run, averaged over the
   block, with its standard error from the spread of the per-pixel variances (never below the Gaussian value
   ``var * sqrt(2 / (dof n))``). When the camera moved within the run (a vibration: the frames' displacements,
   :func:`run_displacement`, spread beyond ``MOTION_RMS_PX``), each pixel's series is first regressed on a
   polynomial of the displacement (the scene at a sensor pixel is a smooth function of the camera's pose, the
   noise is independent per frame): a fine texture too weak for the test to reject otherwise puts its change
   under the shift into the variance (+1.8-2.7 % of sigma at 0.4 px rms), which the block's gradient regressors
   remove only to first order. A run of 2 or 3 frames that measurably moved, or whose light changed enough to
   bias its noise by more than ``LIGHT_BIAS``, has no static block: too few frames to take the motion or the
   light out.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
from scipy.stats import chi2 as chi2_dist
from scipy.stats import f as f_dist
from scipy.stats import norm as norm_dist

#: largest displacement (px) of a frame of a static run from the run's first frame, by global shift (phase
#: correlation on a weakly textured noisy frame scatters by up to ~0.1 px per pair): a camera vibrating by up to
#: ~0.3 px rms per axis stays within it; what moves inside it is the block test's
HOLD_SHIFT_PX = 1.0
#: downsampling factor (area average) of the coarse camera-motion estimate in :func:`camera_shift`
COARSE_FACTOR = 4
#: the coarse estimate overrides the full-resolution one when they differ by more than this (px)
COARSE_SHIFT_PX = 2.0
#: rms displacement (px) of a run's frames about their mean beyond which the temporal variance is taken from
#: each pixel's series regressed on the displacement (below it the regression would only cost degrees of freedom)
MOTION_RMS_PX = 0.05
#: ... and only when that spread and the deviations it explains exceed what noise makes by this many standard errors
MOTION_SIGMAS = 5.0
#: spread of the frames' global gains (light flicker) beyond which they are undone before the test (and beyond
#: ``MOTION_SIGMAS`` standard errors)
FLICKER_MIN = 0.001
#: a run of fewer than 4 frames (too few to weigh the noise that follows the light) has no static block when the
#: light's change would bias its noise variance by more than this (:meth:`LightChange.noise_bias`)
LIGHT_BIAS = 0.005
#: frames from which that regression is quadratic in the displacement (linear from 4 frames, none below)
QUADRATIC_FRAMES = 8
#: a rolling shutter's bands that a smooth profile cannot follow (LEDs dimmed by pulse-width modulation: sharp edges)
#: are fitted row by row (:func:`light_change`) when the light's first-order bias of the noise variance
#: (:meth:`LightChange.noise_bias`, which :meth:`LightChange.undo` corrects to first order) is at most this: beyond,
#: the correction errs by 2-6 % in sigma (changes of 70-120 % on 4-7 frames), within it by under 1 %
ROW_LIGHT_BIAS = 0.2
#: F-test p-value below which a block's frame differences are not pure noise
P_VALUE = 1e-4
#: regressors of the pure-noise test: offset, brightness scaling, x and y motion
N_REGRESSORS = 4


@lru_cache(maxsize=8)
def _window(height: int, width: int) -> np.ndarray:
    return cv2.createHanningWindow((width, height), cv2.CV_64F)


@lru_cache(maxsize=64)
def _dft_side(n: int) -> int:
    """The largest even side <= n that OpenCV's DFT takes without padding (n when n is too small)."""
    m = n - n % 2
    while m > 2 and cv2.getOptimalDFTSize(m) != m:
        m -= 2
    return m if m > 2 else n


def global_shift(a: np.ndarray, b: np.ndarray) -> tuple[float, float, float]:
    """(dx, dy, response): translation of ``b`` relative to ``a`` in pixels (phase correlation, sub-pixel)
    and the correlation peak's response (near 1 for a clean translation, near 0 for no match).

    Both images are cropped (centred) to even sides OpenCV's DFT takes as they are: ``phaseCorrelate``
    pads other sides, to an odd size for e.g. 224 = 2^5 x 7 (225), which biases the estimate by half a
    pixel (identical frames 224 px wide read 0.5 px apart)."""
    a64 = np.array(a, dtype=np.float64)  # copies: OpenCV windows its inputs in place
    b64 = np.array(b, dtype=np.float64)
    if a64.shape != b64.shape or a64.ndim != 2:
        raise ValueError(f"global_shift needs two gray images of one size, got {a64.shape} and {b64.shape}")
    h, w = a64.shape
    hc, wc = _dft_side(h), _dft_side(w)
    crop = (slice((h - hc) // 2, (h - hc) // 2 + hc), slice((w - wc) // 2, (w - wc) // 2 + wc))
    a64, b64 = np.ascontiguousarray(a64[crop]), np.ascontiguousarray(b64[crop])
    (dx, dy), response = cv2.phaseCorrelate(a64, b64, _window(hc, wc))
    return float(dx), float(dy), float(response)


def camera_shift(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(dx, dy): the camera's translation between two frames, robust to a sensor-fixed pattern.

    Phase correlation whitens the spectrum, so a strong pattern that stays in sensor coordinates (DSNU at
    a high dark signal, hot pixels, line offsets) can outweigh a panning scene at high spatial
    frequencies and pin the full-resolution estimate at 0. The frames averaged down by ``COARSE_FACTOR``
    (the pixel pattern averages out, the scene stays) decide when the two estimates differ by more than
    ``COARSE_SHIFT_PX`` (to about ``COARSE_FACTOR / 2`` px: enough to see motion and place the pose);
    otherwise the sub-pixel full-resolution estimate is kept."""
    dx, dy, _ = global_shift(a, b)
    h, w = np.shape(a)
    size = (w // COARSE_FACTOR, h // COARSE_FACTOR)
    if min(size) < 16:
        return dx, dy
    small = [cv2.resize(np.asarray(x, dtype=np.float64), size, interpolation=cv2.INTER_AREA) for x in (a, b)]
    cx, cy, _ = global_shift(*small)
    cx, cy = cx * w / size[0], cy * h / size[1]
    return (cx, cy) if math.hypot(cx - dx, cy - dy) > COARSE_SHIFT_PX else (dx, dy)


def static_runs(shifts: np.ndarray, limit_px: float = HOLD_SHIFT_PX) -> list[tuple[int, int]]:
    """[start, stop) frame ranges of runs whose frames stay within ``limit_px`` of the run's first frame,
    by the consecutive shifts ``shifts[i]`` (frame i -> i + 1, shape (n - 1, 2)) accumulated; a frame
    beyond it starts the next run; single frames are runs of length 1."""
    steps = np.asarray(shifts, dtype=float).reshape(-1, 2)
    runs, start, offset = [], 0, np.zeros(2)
    for i, step in enumerate(steps):
        offset = offset + step
        if math.hypot(*offset) > limit_px:
            runs.append((start, i + 1))
            start, offset = i + 1, np.zeros(2)
    runs.append((start, len(steps) + 1))
    return runs


@dataclass
class BlockTemporal:
    """Per-block temporal statistics of a static run (blocks row-major over the image's block grid)."""

    block: int
    grid: tuple[int, int]
    frames: int
    mean_dn: np.ndarray  # (N,) block mean of the temporal mean image
    variance_dn2: np.ndarray  # (N,) per-pixel temporal variance, block average (unbiased)
    variance_err_dn2: np.ndarray  # (N,) its standard error
    p_value: np.ndarray  # (N,) pure-noise test
    accepted: np.ndarray  # (N,) bool: the block's frame differences fit pure noise
    #: (N,) bool: no scene change the regressors explain (the pure-noise test without the whiteness test, which
    #: also rejects a block whose noise changes within the run)
    still: np.ndarray
    motion_px: float = 0.0  # the frames' rms displacement about their mean (px, :func:`run_displacement`)
    light_pct: float = 0.0  # the light's change from frame to frame taken out (:meth:`LightChange.percent`, %)
    light_rows: bool = False  # that change fitted row by row (:attr:`LightChange.row_pixels`)

    def sigma_dn(self) -> tuple[float, float]:
        """Temporal sigma over all accepted blocks and its standard error (NaN if none)."""
        if not self.accepted.any():
            return float("nan"), float("nan")
        v = self.variance_dn2[self.accepted]
        e = self.variance_err_dn2[self.accepted]
        var = float(v.mean())
        err = float(math.sqrt(np.sum(e**2)) / v.size)
        s = math.sqrt(max(var, 0.0))
        return s, err / (2.0 * max(s, 1e-6))


def _scene_p(residual: np.ndarray, b: int) -> np.ndarray:
    """(N,) p-value that what the scene-change regressors leave of each frame's deviation from the hold mean
    (``residual``, k x N x b*b) is white noise of the same energy in every frame, after its row and column
    means (line noise changing from frame to frame is no scene change): the smaller of Bartlett's test of
    equal energies over the frames (a textured object passing through part of the hold) and a one-sided test
    of the neighbours' correlation (a smooth texture moving under the block all hold long: its deviations are
    smooth, noise is white; calibrated on white noise: ``WHITE_LAG``). A white texture moving under the
    block all hold long passes both: locally it is noise."""
    k = residual.shape[0]
    energy, lag = energy_and_lag(residual, b)
    energy = np.maximum(energy, 1e-12)
    nu = (b - 1) ** 2 - (N_REGRESSORS - 1)  # per frame, after the line means and the other regressors
    stat = nu * (k * np.log(energy.mean(axis=0)) - np.log(energy).sum(axis=0)) / (1.0 + (k + 1) / (3.0 * k * nu))
    mu, sd = _white_lag(k, b)
    return np.minimum(chi2_dist.sf(stat, k - 1), norm_dist.sf((lag / energy.sum(axis=0) - mu) / sd))


def energy_and_lag(residual: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray]:
    """((k, N) energy of each frame's residual after its row and column means in each block, (N,) the sum over
    frames of its products with its right and lower neighbours) for ``residual`` (k, N, b*b)."""
    k = residual.shape[0]
    r = residual.reshape(k, -1, b, b)
    r = r - r.mean(axis=2, keepdims=True) - r.mean(axis=3, keepdims=True) + r.mean(axis=(2, 3), keepdims=True)
    lag = np.sum(r[:, :, 1:, :] * r[:, :, :-1, :], axis=(0, 2, 3)) + np.sum(r[:, :, :, 1:] * r[:, :, :, :-1], axis=(0, 2, 3))
    return np.sum(r * r, axis=(2, 3)), lag


#: block side -> (mean, standard deviation x sqrt(k - 1)) of :func:`_scene_p`'s neighbour correlation on white
#: noise of k frames; 8 x 8 from :func:`white_lag_monte_carlo` (4,096 blocks per k: mean -0.254 at every k from 2 to
#: 64, spread 0.170-0.184 rising slowly with k; the largest is kept, so the test errs towards accepting noise)
WHITE_LAG = {8: (-0.254, 0.184)}


def _white_lag(k: int, b: int) -> tuple[float, float]:
    """Mean and standard deviation of :func:`_scene_p`'s neighbour correlation on white noise of k frames."""
    mean, spread = WHITE_LAG[b] if b in WHITE_LAG else white_lag_monte_carlo(b)
    return mean, spread / math.sqrt(k - 1)


@lru_cache(maxsize=8)
def white_lag_monte_carlo(b: int, k: int = 64) -> tuple[float, float]:
    """(mean, standard deviation x sqrt(k - 1)) of :func:`_scene_p`'s neighbour correlation on white noise of k
    frames of b x b blocks (seeded Monte-Carlo through the same regressors, 4,096 blocks)."""
    x = np.random.default_rng(12345).normal(0.0, 1.0, (k, 64 * b, 64 * b)) + 100.0
    _, d, q, coef = _regression(x, b, np.ones((64 * 64, b * b), dtype=bool))
    energy, lag = energy_and_lag(d - np.einsum("knr,npr->knp", coef, q, optimize=True), b)
    rho = lag / energy.sum(axis=0)
    return float(rho.mean()), float(rho.std() * math.sqrt(k - 1))


def _deviations(x: np.ndarray, b: int, use: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(block pixels of the run mean (N, n), the frames' deviations from it (k, N, n), 0 outside ``use``)."""
    mb = blocks_of(x.mean(axis=0), b)
    return mb, (blocks_of(x, b) - mb[None]) * use[None]


def _regression(x: np.ndarray, b: int, use: np.ndarray, deviations: tuple[np.ndarray, np.ndarray] | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(block pixels of the hold mean (N, n), the frames' deviations from it (k, N, n), the scene-change
    regressors' orthonormal basis (N, n, 4), the deviations' coefficients on it (k, N, 4)) of ``x`` (k x H x W)
    in b x b blocks, pixels outside ``use`` (N, n) left out: an offset, a brightness scaling and sub-pixel motion
    along the mean image's gradients. ``deviations``: :func:`_deviations` of ``x`` when at hand."""
    mean = x.mean(axis=0)
    gy, gx = np.gradient(mean)
    mb, d = _deviations(x, b, use) if deviations is None else deviations
    design = np.stack([np.ones_like(mb), mb - mb.mean(axis=1, keepdims=True), blocks_of(gx, b),
                       blocks_of(gy, b)], axis=2) * use[:, :, None]
    q, _ = np.linalg.qr(design)
    return mb, d, q, np.einsum("knp,npr->knr", d, q, optimize=True)  # batched products: 10x faster than plain einsum


def _row_ramp(b: int) -> np.ndarray:
    """(b*b,) each pixel's row in a b x b block about the block's middle row: with the block's levels, the regressor
    of a brightness that changes along the rows (a rolling shutter's band edge the light's smooth fit missed)."""
    return np.repeat(np.arange(b) - (b - 1) / 2.0, b)


def blocks_of(img: np.ndarray, b: int) -> np.ndarray:
    """(..., N, b*b) blocks of the last two axes, row-major over the block grid (edges cut)."""
    h, w = (img.shape[-2] // b) * b, (img.shape[-1] // b) * b
    lead = img.shape[:-2]
    x = img[..., :h, :w].reshape(*lead, h // b, b, w // b, b)
    x = np.moveaxis(x, -3, -2)
    return x.reshape(*lead, (h // b) * (w // b), b * b)


def run_displacement(x: np.ndarray, b: int, deviations: np.ndarray | None = None,
                     use: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """((k, 2) each frame's global displacement (px, x and y) from the mean of the run ``x`` (k x H x W), its
    standard error (px, per axis)): per b x b block one Lucas-Kanade step (the frame's deviation from the mean
    regressed on the mean's gradients), the median over the blocks textured in both directions (their gradient
    tensor's smaller eigenvalue in the upper half; a moving object's blocks are outvoted), its error from the
    blocks' spread. Linear in a small displacement, whatever its scale. ``deviations``: the frames' deviations
    from the mean in blocks (k, N, b*b) when already at hand; ``use``: (N, b*b) the pixels to use (others 0 in
    ``deviations``)."""
    gy, gx = (blocks_of(g, b) for g in np.gradient(x.mean(axis=0)))
    if deviations is None:
        deviations = blocks_of(x, b) - blocks_of(x.mean(axis=0), b)[None]
    if use is not None:
        gy, gx = gy * use, gx * use
    a11, a22, a12 = np.einsum("np,np->n", gx, gx), np.einsum("np,np->n", gy, gy), np.einsum("np,np->n", gx, gy)
    det = a11 * a22 - a12**2
    low = (a11 + a22) / 2.0 - np.sqrt(((a11 - a22) / 2.0) ** 2 + a12**2)
    well = (low >= np.median(low)) & (low > 0.0) & (det > 0.0)
    if not well.any():
        return np.zeros((x.shape[0], 2)), math.inf
    dev = deviations[:, well]
    h1, h2 = np.einsum("knp,np->kn", dev, gx[well]), np.einsum("knp,np->kn", dev, gy[well])
    a11, a22, a12, det = a11[well], a22[well], a12[well], det[well]
    per_block = np.stack([(a22 * h1 - a12 * h2) / det, (a11 * h2 - a12 * h1) / det], axis=2)  # (k, blocks, 2)
    found = np.median(per_block, axis=1)
    mad = np.median(np.abs(per_block - found[:, None]), axis=1)
    return found, float(1.2533 * 1.4826 * np.sqrt(np.mean(mad**2)) / math.sqrt(per_block.shape[1]))


def motion_rms(displacement: np.ndarray) -> float:
    """The rms (px) of the frames' displacements ``displacement`` (k, 2) about their mean."""
    d = np.asarray(displacement, dtype=np.float64).reshape(-1, 2)
    d = d - d.mean(axis=0)
    return math.sqrt(float(np.mean(np.sum(d * d, axis=1))))


def moved(displacement: np.ndarray, error: float) -> bool:
    """Whether frames at ``displacement`` (k, 2; px) spread by more than ``MOTION_RMS_PX`` rms and more than
    ``MOTION_SIGMAS`` x ``error`` (the displacements' standard error, px per axis: a spread their noise makes)."""
    rms = motion_rms(displacement)
    return rms > MOTION_RMS_PX and rms > MOTION_SIGMAS * error


def displacement_basis(displacement: np.ndarray, error: float = 0.0) -> np.ndarray | None:
    """(k, P) orthonormal basis of a constant and a polynomial of the frames' displacements ``displacement``
    (k, 2; px, any origin): linear from 4 frames, quadratic from ``QUADRATIC_FRAMES``; None when they have not
    :func:`moved` or are too few."""
    d = np.asarray(displacement, dtype=np.float64).reshape(-1, 2)
    k = d.shape[0]
    d = d - d.mean(axis=0)
    if k < 4 or not moved(d, error):
        return None
    cols = [np.ones(k), d[:, 0], d[:, 1]]
    if k >= QUADRATIC_FRAMES:
        cols += [d[:, 0] ** 2, d[:, 1] ** 2, d[:, 0] * d[:, 1]]
    q, _ = np.linalg.qr(np.stack(cols, axis=1))
    return q


@dataclass
class SteadyRun:
    """A run with each pixel's dependence on the camera's displacement removed (:func:`steady_run`)."""

    frames: np.ndarray  # (k, H, W) the run mean plus each frame's residual, scaled to its unmoved energy
    residual: np.ndarray  # (k, H, W) the residuals as fitted: sum of squares / dof is chi-square like
    dof: int  # per-pixel degrees of freedom left (k - 1 without motion)


def steady_run(x: np.ndarray, b: int, displacement: tuple[np.ndarray, float] | None = None) -> SteadyRun | None:
    """The run ``x`` (k x H x W) with each pixel's dependence on the camera's displacement removed, or None when
    the camera did not measurably move. Each pixel's series is regressed on :func:`displacement_basis` of the
    frames' ``displacement`` and its error (default :func:`run_displacement`) if that explains more of the
    deviations than noise would (``MOTION_SIGMAS``). In ``frames`` each frame's residual is scaled by
    sqrt((1 - 1/k) / (1 - its leverage)), so that its deviation from the run mean keeps the expected energy it
    has without motion and statistics of the plain deviations stay unbiased."""
    k = x.shape[0]
    if k < 4:
        return None
    basis = displacement_basis(*(run_displacement(x, b) if displacement is None else displacement))
    if basis is None:
        return None
    coef = np.einsum("kr,khw->rhw", basis, x)  # coef[0]: the constant's
    residual = x - np.einsum("kr,rhw->khw", basis, coef, optimize=True)
    p, n = basis.shape[1], x[0].size
    ratio = (np.sum(coef[1:] ** 2) / (p - 1)) / max(float(np.sum(residual**2)) / (k - p), 1e-300)
    if ratio <= 1.0 + MOTION_SIGMAS * math.sqrt(2.0 / (n * (p - 1)) + 2.0 / (n * (k - p))):
        return None  # the displacement explains no more than noise would (e.g. its own estimate's noise)
    scale = np.sqrt((1.0 - 1.0 / k) / (1.0 - np.sum(basis**2, axis=1)))
    return SteadyRun(x.mean(axis=0) + residual * scale[:, None, None], residual, k - p)


#: largest degree of the light's row profile (a rolling shutter's bands, :func:`light_bands`) and the fewest
#: block rows per degree
LIGHT_DEGREE, ROWS_PER_DEGREE = 12, 3


def row_gains(x: np.ndarray, b: int, view_rows: int, means: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """((k,) offset, (k, V, R) gain) of each frame of the run ``x`` (k x H x W, a column of V views of
    ``view_rows`` rows) against the run mean: a gain per view and row of b x b blocks (R per view) and one offset,
    fitted to the blocks' means (:func:`_gain_fits`; ``means``: those of :func:`_block_means` when at hand) once the
    frame's column offsets are out (:func:`_without_column_offsets`)."""
    means = _block_means(x, b, view_rows) if means is None else means
    offset, slope, _, _ = _gain_fits(_without_column_offsets(means, x.shape[1] // view_rows))
    return offset, 1.0 + slope.reshape(x.shape[0], x.shape[1] // view_rows, view_rows // b)


def _without_column_offsets(means: np.ndarray, views: int) -> np.ndarray:
    """Block means ``means`` (k, V x R, C) less each frame's offset per view and column of blocks beyond the frame's
    mean offset, fitted by least squares jointly with a gain per row of blocks. Temporal column noise (a column's
    offset changing from frame to frame) moves every block of a column alike; the rows' gains, fitted to the
    same columns, take a share of it that is common to rows of alike levels, a smooth profile over the rows that
    read as a rolling shutter's bands (in 9 of 12 holds of a campaign with 1 DN of it, before 2026-11-29)."""
    k, g, c = means.shape
    r = g // views
    m = means.astype(np.float64).reshape(k, views, r, c)  # float32's floor is 1e-45: a black row's 0 / 0
    level = m.mean(axis=0)  # (V, R, C)
    y = m - level
    norm = np.maximum(np.sum(level * level, axis=2), 1e-300)  # (V, R)
    # per view, with the rows' gains eliminated: (R I - sum_r l_r l_r^T / |l_r|^2) u = sum_r (y_r - l_r (l_r.y_r) / |l_r|^2)
    system = r * np.eye(c) - np.einsum("vri,vrj->vij", level / norm[..., None], level)
    along = np.einsum("vrc,kvrc->kvr", level, y) / norm
    rhs = np.sum(y - along[..., None] * level, axis=2)  # (k, V, C)
    u = np.einsum("vij,kvj->kvi", np.linalg.pinv(system, hermitian=True), rhs)
    u = u - u.mean(axis=2, keepdims=True)  # the frame's mean offset stays for the fit's own offset
    return (m - u[:, :, None, :]).reshape(k, g, c)


def _block_means(x: np.ndarray, b: int, view_rows: int) -> np.ndarray:
    """(k, V x R, C) means of the b x b blocks of ``x`` (k x H x W, a column of V views of ``view_rows`` rows), by
    row of blocks (R per view, C per row; the rows and columns beyond whole blocks cut)."""
    k, h, w_ = x.shape[0], x.shape[1], (x.shape[2] // b) * b
    views, r, c = h // view_rows, view_rows // b, w_ // b
    xs = x[:, : views * view_rows, :w_].reshape(k, views, view_rows, w_)[:, :, : r * b]
    return xs.reshape(k, views, r, b, c, b).mean(axis=(3, 5)).reshape(k, views * r, c)


#: A group of blocks darker than this (rms level, DN) shows no gain of the light (its change is within the noise).
MIN_GAIN_LEVEL_DN = 2.0


def _gain_fits(means: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each frame's change against the run mean of block means ``means`` (k, G, n): one offset and a gain per
    group (deviation from 1) by least squares, refitted once without the blocks beyond 4 robust standard deviations
    of the first fit (a moving object); closed form (the offset from the groups' Schur complement, 0 when every
    group is flat). Returns (k,) offsets, (k, G) gains - 1, (k,) the robust residual scale and (k, G) the gains'
    inverse variance per unit residual variance with the offset free (exact for one group). A group too dark to
    show a gain (its blocks' rms level below :data:`MIN_GAIN_LEVEL_DN`: a lens hood, a night sky) takes the
    median gain of the others (until 2026-12-04 a black row of blocks read a gain of 0 / 0)."""
    means = means.astype(np.float64)
    level = means.mean(axis=0)
    y = means - level
    wts = np.ones_like(y)
    for _ in range(2):
        s1, s2, sy = (wts * level).sum(axis=2), (wts * level**2).sum(axis=2), (wts * level * y).sum(axis=2)
        s2 = np.maximum(s2, 1e-300)
        n = wts.sum(axis=(1, 2))
        den = n - (s1**2 / s2).sum(axis=1)
        num = (wts * y).sum(axis=(1, 2)) - (s1 * sy / s2).sum(axis=1)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # a flat view: no offset to fit (0)
            offset = np.where(den > 1e-9 * np.maximum(n, 1.0), num / np.maximum(den, 1e-300), 0.0)
        slope = (sy - s1 * offset[:, None]) / s2
        resid = np.abs(y - offset[:, None, None] - slope[:, :, None] * level)
        scale = 1.4826 * np.median(resid.reshape(y.shape[0], -1), axis=1) + 1e-12
        wts = (resid <= 4.0 * scale[:, None, None]).astype(float)
    spread = s2 - s1**2 / np.maximum(n, 1.0)[:, None]  # the last fit's: the gain's information, the offset free
    dark = np.sqrt(np.mean(level**2, axis=1)) < MIN_GAIN_LEVEL_DN
    if dark.any():
        slope[:, dark] = np.median(slope[:, ~dark], axis=1, keepdims=True) if not dark.all() else 0.0
        spread[:, dark] = 0.0
    return offset, slope, scale, np.maximum(spread, 1e-300)


def _without_motion(series: np.ndarray, motion: np.ndarray | None) -> np.ndarray:
    """``series`` (k, ...) over the frames less what the frames' displacement explains of its deviations from its
    mean (``motion``: :func:`displacement_basis`, None: the camera did not move)."""
    if motion is None:
        return series
    dev = series - series.mean(axis=0)
    return series - np.tensordot(motion, np.tensordot(motion, dev, axes=(0, 0)), axes=(1, 0))


def light_bands(gains: np.ndarray, rows: int, b: int, motion: np.ndarray | None = None) -> tuple[np.ndarray, int] | None:
    """((k, V, rows) smooth gain profile, its degree) of the per-row gains ``gains`` (k, V, R) of
    :func:`row_gains` when they follow the row beyond their scatter, else None: per
    frame and view a Legendre polynomial of the row (to ``LIGHT_DEGREE``, one degree per ``ROWS_PER_DEGREE``
    rows), its degree the highest whose coefficients exceed the gains' scatter about the fit (each view's own) by
    ``MOTION_SIGMAS`` standard errors of chi-square; a white scatter from row to row (temporal row noise) is no
    band. ``motion``: the frames' displacement basis when the camera moved (what it explains is the scene moving
    under the blocks, left out)."""
    gains = _without_motion(gains, motion)
    k, views, r = gains.shape
    free = max(k - (1 if motion is None else motion.shape[1]), 1)  # the frames' degrees of freedom about the mean
    top = min(LIGHT_DEGREE, r // ROWS_PER_DEGREE)
    t = 2.0 * (np.arange(rows) + 0.5) / rows - 1.0
    tb = t[: r * b].reshape(r, b).mean(axis=1)
    q = np.linalg.qr(np.polynomial.legendre.legvander(tb, top))[0]  # orthonormal over the block rows
    coef = np.einsum("rd,kvr->kvd", q, gains)
    dof = max(r - top - 1, 1)
    # each view's scatter of the gains about the fit (a dark or textured view's gains are the noisier)
    scatter = np.maximum(np.sum((gains - np.einsum("rd,kvd->kvr", q, coef)) ** 2, axis=(0, 2)) / (free * dof), 1e-300)
    z2 = coef**2 / scatter[None, :, None]
    d1 = free * views
    limit = 1.0 + MOTION_SIGMAS * math.sqrt(2.0 / d1 + 2.0 / (d1 * dof))
    degree = next((d for d in range(top, 0, -1) if np.sum(z2[..., d]) / d1 > limit), 0)
    if degree == 0:
        return None
    # the profile's coefficients on the Legendre polynomials up to ``degree``, evaluated at every row
    q_deg, tri_deg = np.linalg.qr(np.polynomial.legendre.legvander(tb, degree))
    leg = np.linalg.solve(tri_deg, np.einsum("rd,kvr->kvd", q_deg, gains)[..., None])[..., 0]
    return np.einsum("kvd,rd->kvr", leg, np.polynomial.legendre.legvander(t, degree)), degree


@dataclass
class LightChange:
    """Each frame's light against the run mean (:func:`light_change`): the frame is ``offset + gain x`` the run
    mean, plus its noise."""

    offset: np.ndarray  # (k,) DN
    gain: np.ndarray  # (k, H) each frame's relative brightness of every row
    #: pixels each row's gain was fitted to, one gain per frame and row (0: a smooth profile or one gain per frame)
    row_pixels: int = 0

    def variance_scale(self) -> float:
        """What the noise variance left after :meth:`undo` is multiplied by to be unbiased: a gain fitted per frame
        to each row of W pixels takes 1 / W of the row's noise with it (W / (W - 1); 1 for a smooth profile)."""
        return self.row_pixels / (self.row_pixels - 1.0) if self.row_pixels > 1 else 1.0

    def undo(self, x: np.ndarray) -> np.ndarray:
        """The run ``x`` with the change subtracted (the noise stays each frame's own, not scaled by the gain), each
        frame's deviations from the run mean then weighted per row so that their energies estimate the frames'
        mean noise variance without bias: the run mean's own noise comes in with the gain, and where the noise
        follows the light (shot noise) it correlates with the frame's own; the weight
        sqrt((1 + 2 (g - <g>) / (k - 2)) (k - 1) / (k - 1 + sum (g - <g>)^2 / k)) undoes both to first order
        (k >= 4; fewer frames get the second factor alone)."""
        k = x.shape[0]
        mean = x.mean(axis=0)
        steady = x - (self.offset[:, None, None] + (self.gain[:, :, None] - 1.0) * mean[None])
        dev = self.deviation
        weight = np.broadcast_to((k - 1) / (k - 1 + np.sum(dev**2, axis=0) / k), dev.shape)
        if k >= 4:
            weight = weight * np.maximum(1.0 + 2.0 * dev / (k - 2), 0.0)
        centre = steady.mean(axis=0)
        return centre[None] + (steady - centre[None]) * np.sqrt(weight)[:, :, None]

    @property
    def deviation(self) -> np.ndarray:
        """(k, H) each frame's gain per row less the run's mean gain of that row."""
        return self.gain - self.gain.mean(axis=0)

    def noise_bias(self) -> float:
        """The relative bias of the frames' noise variance that the light's change brings where the noise follows
        the light, to first order without :meth:`undo`'s weights (mean over the rows): 2 sum (g - <g>)^2 / (k (k - 1))."""
        k = self.gain.shape[0]
        return 2.0 * float(np.mean(np.sum(self.deviation**2, axis=0))) / (k * max(k - 1, 1))

    def percent(self) -> float:
        """The change's size: rms over the frames and rows of the gain about its run mean (%)."""
        return 100.0 * float(np.sqrt(np.mean(self.deviation**2)))

    def block_levels(self, level: np.ndarray, b: int, columns: int) -> tuple[np.ndarray, np.ndarray]:
        """((N,), (N,)) the lowest and highest level the frames gave each b x b block of run-mean level ``level``
        (row-major, ``columns`` blocks per row): where a frame's light took it near the clipping limits."""
        rows = level.size // columns
        g = self.gain[:, : rows * b].reshape(self.gain.shape[0], rows, b)
        lo, hi = (np.repeat(f(g, axis=2), columns, axis=1) for f in (np.min, np.max))  # (k, N)
        return ((self.offset[:, None] + lo * level[None]).min(axis=0),
                (self.offset[:, None] + hi * level[None]).max(axis=0))


def row_gain(a: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """(..., H) each row's least-squares gain of ``a`` (..., H, W) on the same row of ``ref`` (broadcast to it; 0
    where that row of ``ref`` is 0). A rolling shutter exposes a row at one time, so one gain per row follows the
    light whatever its waveform."""
    norm = np.einsum("...hw,...hw->...h", ref, ref)
    return np.einsum("...hw,...hw->...h", a, ref) / np.maximum(norm, np.finfo(norm.dtype).tiny)


def _row_light(x: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """(k, H) each frame's gain of every row of the run ``x`` (k x H x W) against the run mean, the frame's
    ``offset`` (k,) taken off first (:func:`row_gain`)."""
    return row_gain(x - offset[:, None, None], x.mean(axis=0))


def _follows_rows(residual: np.ndarray, rows: int) -> bool:
    """Whether ``residual`` (k, H: per-row gains less the smooth profile, views of ``rows`` rows) is correlated
    from row to row beyond ``MOTION_SIGMAS`` standard errors: the bands' shape the smooth profile missed, not
    the gains' noise or temporal row noise, which are white from row to row."""
    r = residual.reshape(residual.shape[0], -1, rows)
    lag = float(np.sum(r[..., 1:] * r[..., :-1])) / max(float(np.sum(r[..., 1:] ** 2)), 1e-300)
    return lag * math.sqrt(r[..., 1:].size) > MOTION_SIGMAS


def light_change(x: np.ndarray, b: int, view_rows: int | None = None,
                 motion: np.ndarray | None = None, row_light: bool = False) -> LightChange | None:
    """Each frame's light change against the mean of the run ``x`` (k x H x W), or None under steady light: bands
    that follow the row (a rolling shutter under lamps on the mains, :func:`light_bands` per view of ``view_rows``
    rows, default the whole image), else a global change (one offset and gain per frame for the whole image, its
    standard error from the fit's scatter) when the gains spread by more than ``FLICKER_MIN`` and ``MOTION_SIGMAS``
    standard errors. Both are fitted to the b x b blocks' means (:func:`_gain_fits`). ``motion``: the frames' displacement basis
    (:func:`displacement_basis`) when the camera moved: the scene moving under the blocks changes their means too,
    and the light is what the displacement does not explain. ``row_light``: bands that the smooth profile cannot
    follow (:func:`_follows_rows`) are fitted row by row instead (:func:`_row_light`) where that change is within
    ``ROW_LIGHT_BIAS``; it takes temporal row noise out with the light, so the lab, which reads row noise, keeps the
    smooth profile."""
    k = x.shape[0]
    rows = x.shape[1] if view_rows is None else view_rows
    if rows < b or x.shape[1] % rows:
        raise ValueError(f"view_rows {view_rows} must divide the image height {x.shape[1]} and hold a {b}-pixel block")
    means = _block_means(x, b, rows)
    offset, gains = row_gains(x, b, rows, means)
    bands = light_bands(gains, rows, b, motion)
    if bands is not None:
        smooth = bands[0].reshape(k, x.shape[1])
        if row_light:
            per_row = LightChange(_without_motion(offset, motion), _without_motion(_row_light(x, offset), motion),
                                  x.shape[2])
            if _follows_rows(per_row.gain - smooth, rows) and per_row.noise_bias() <= ROW_LIGHT_BIAS:
                return per_row
        return LightChange(_without_motion(offset, motion), smooth)
    offset, slope, scale, information = _gain_fits(means.reshape(k, 1, -1))
    err = float(np.sqrt(np.mean(scale**2 / information[:, 0])))
    offset, flat = _without_motion(offset, motion), _without_motion(1.0 + slope[:, 0], motion)
    spread = float(np.std(flat)) * (1.0 if motion is None else math.sqrt((k - 1) / max(k - motion.shape[1], 1)))
    if spread <= FLICKER_MIN or spread <= MOTION_SIGMAS * err:
        return None
    return LightChange(offset, np.repeat(flat[:, None], x.shape[1], axis=1))


def light_and_motion(x: np.ndarray, b: int, view_rows: int | None = None, use: np.ndarray | None = None,
                     row_light: bool = False) -> tuple[LightChange | None, np.ndarray, tuple[np.ndarray, float],
                                                       tuple[np.ndarray, np.ndarray] | None]:
    """(the light's change (:func:`light_change`), the run ``x`` with it taken out, the frames' displacement and
    its error (:func:`run_displacement` on those frames, over the (N, b*b) pixels ``use``), with ``use`` their
    :func:`_deviations`): when the camera moved, the light is fitted again from what the displacement does not
    explain (the scene moving under the blocks changes their means too). ``row_light``: see :func:`light_change`."""
    light = light_change(x, b, view_rows, row_light=row_light)
    steady = x if light is None else light.undo(x)
    blocks = None if use is None else _deviations(steady, b, use)
    displacement = run_displacement(steady, b, None if blocks is None else blocks[1], use)
    motion = displacement_basis(*displacement)
    if light is not None and motion is not None:
        light = light_change(x, b, view_rows, motion, row_light)
        steady = x if light is None else light.undo(x)
        blocks = None if use is None else _deviations(steady, b, use)
    return light, steady, displacement, blocks


def block_temporal(stack: np.ndarray, block: int = 8, p_value: float = P_VALUE,
                   exclude: np.ndarray | None = None, whiteness: bool = False,
                   view_rows: int | None = None, row_light: bool = False) -> BlockTemporal:
    """Temporal statistics of a static run ``stack`` (k >= 2 frames, k x H x W, DN).

    ``exclude``: (N, block * block) pixels left out of the test and the variance (e.g. blinking pixels,
    noise that is not a scene change but would correlate with the brightness regressor). ``whiteness``: the
    pure-noise test also asks what the regressors leave to be white and of equal energy in every frame
    (:func:`_scene_p`: an object moving under the block; about twice the time, so the lab's, not the live
    monitor's, whose median over patches keeps such blocks from the frame). ``view_rows``: the frames are a
    column of views of this many rows each (the live monitor's patches), whose light is fitted apart
    (:func:`light_and_motion`). ``row_light``: bands a smooth profile cannot follow fitted row by row
    (:func:`light_change`; the live monitor's)."""
    x = np.asarray(stack, dtype=np.float64)
    if x.ndim != 3 or x.shape[0] < 2:
        raise ValueError(f"a static run needs k >= 2 frames of one size (k x H x W), got shape {x.shape}")
    k = x.shape[0]
    if x.shape[1] < block or x.shape[2] < block:
        raise ValueError(f"frames of {x.shape[2]}x{x.shape[1]} are smaller than one {block}x{block} block")
    n_blocks = (x.shape[1] // block) * (x.shape[2] // block)
    use = np.ones((n_blocks, block * block), dtype=bool) if exclude is None else ~np.asarray(exclude, dtype=bool)
    if use.shape != (n_blocks, block * block):
        raise ValueError(f"exclude must have shape {(n_blocks, block * block)} (blocks x pixels), got {use.shape}")
    light, x, displacement, blocks = light_and_motion(x, block, view_rows, use, row_light)
    mb, d, q, coef = _regression(x, block, use, blocks)
    explained = np.sum(coef**2, axis=(0, 2))
    nreg = N_REGRESSORS
    if light is not None:  # what the light's fit left may change the brightness along the block's rows too
        ramp = mb * _row_ramp(block) * use  # made orthonormal to the other regressors (one Gram-Schmidt step)
        ramp -= np.einsum("npr,nr->np", q, np.einsum("npr,np->nr", q, ramp))
        ramp /= np.maximum(np.linalg.norm(ramp, axis=1, keepdims=True), 1e-12)
        explained = explained + np.sum(np.einsum("knp,np->kn", d, ramp) ** 2, axis=0)
        nreg += 1
    total = np.sum(d * d, axis=(0, 2))
    m = np.maximum(use.sum(axis=1), nreg + 2)  # pixels used per block
    d1, d2 = nreg * (k - 1), (k - 1) * (m - nreg)
    ratio = (explained / d1) / np.maximum((total - explained) / d2, 1e-12)
    p = f_dist.sf(ratio, d1, d2)
    still = p > p_value
    if whiteness:
        p = np.minimum(p, _scene_p(d - np.einsum("knr,npr->knp", coef, q, optimize=True), block))
    steady = steady_run(x, block, displacement)
    if k < 4 and (moved(*displacement) or (light is not None and light.noise_bias() > LIGHT_BIAS)):
        p = np.zeros_like(p)  # too few frames to take the camera's motion or the light's out: no static run
        still[:] = False
    if steady is None:
        per_pixel, dof = np.sum(d * d, axis=0) / (k - 1), k - 1  # (N, n), zero where excluded
    else:
        r = blocks_of(steady.residual, block) * use[None]
        per_pixel, dof = np.sum(r * r, axis=0) / steady.dof, steady.dof
    per_pixel = per_pixel * (1.0 if light is None else light.variance_scale())
    var = per_pixel.sum(axis=1) / m
    spread = np.sqrt(np.maximum(np.sum(use * (per_pixel - var[:, None]) ** 2, axis=1) / (m - 1), 0.0))
    gauss = var * np.sqrt(2.0 / (dof * m))
    err = np.maximum(spread / np.sqrt(m), gauss)
    grid = (x.shape[1] // block, x.shape[2] // block)
    return BlockTemporal(block, grid, k, mb.mean(axis=1), var, err, p, p > p_value, still, motion_rms(displacement[0]),
                         0.0 if light is None else light.percent(), light is not None and light.row_pixels > 0)
