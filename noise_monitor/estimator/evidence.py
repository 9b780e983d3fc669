"""Physics evidence of scene texture in a patch: how far its fine-scale content departs from white noise.

The noise the monitor measures (PN, DCSN, RN, PRNU/DSNU) is independent from pixel to pixel. Its power
spectrum is flat, also where its amplitude varies with the intensity (amplitude-modulated white noise is
white), while a scene's spectrum falls with frequency, peaks at a grating's period or points along its
edges. Each statistic below is zero in expectation for white noise of any level (calibrated by
Monte-Carlo per patch size, :func:`white_reference`), whatever photo the texture came from, and grows
with the scene's share of the fine-scale power: the inputs of the confidence head that qualify the
measurement (``networks.ImageNoiseNet``). They never see the stated metadata.

Statistics (periodogram of the plane-detrended, Hann-windowed patch, high band |f| >= 0.25 cycles/px):
  0 flatness: log(arithmetic / geometric mean power) (white: Euler's constant; any structure raises it)
  1 slope: log power at 0.25-0.35 over >= 0.40 cycles/px (a scene's power falls with frequency)
  2 peak: log(max / mean power) (a grating's line)
  3 anisotropy: log(max / min power) over four orientation sectors (oriented texture, edges)
  4 binning: log of twice the 2x2-binned patch's Immerkaer RMS over the patch's (white noise halves)
  5 block spread: log(mean / 10th percentile) of 8x8-block Immerkaer energies (texture in some blocks)
"""
from __future__ import annotations

from functools import cache

import numpy as np
import scipy.fft

from .residuals import BLOCK, block_energies, immerkaer, quantiles

#: Number of evidence statistics per patch (see the module docstring).
N_EVIDENCE = 6
#: Frequency bands (cycles/px): the high band, its lower and upper sub-bands.
HIGH_BAND = 0.25
LOW_SUB, HIGH_SUB = 0.35, 0.40
#: Patches per FFT chunk (memory).
_CHUNK = 1024


@cache
def _bands(h: int, w: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Hann window and the masks of the rfft2 grid: high band, lower / upper sub-band, sector index."""
    window = np.outer(np.hanning(h), np.hanning(w)).astype(np.float32)
    fy = np.fft.fftfreq(h)[:, None]
    fx = np.fft.rfftfreq(w)[None, :]
    r = np.hypot(fy, fx)
    high = r >= HIGH_BAND
    angle = np.mod(np.arctan2(fy, fx), np.pi)  # orientation of the frequency, 0..pi
    sector = np.floor((angle + np.pi / 8) / (np.pi / 4)).astype(int) % 4
    return window, high, high & (r < LOW_SUB), r >= HIGH_SUB, np.broadcast_to(sector, r.shape)


@cache
def _plane(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """(basis (h*w, 3), its pseudo-inverse (3, h*w)) of a least-squares plane on an h x w patch."""
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    basis = np.stack([np.ones(h * w), (yy.ravel() - yy.mean()) / h, (xx.ravel() - xx.mean()) / w], axis=1)
    return basis.astype(np.float32), np.linalg.pinv(basis).astype(np.float32)


def _detrend(x: np.ndarray) -> np.ndarray:
    """Each patch minus its least-squares plane (float32)."""
    n, h, w = x.shape
    basis, pinv = _plane(h, w)
    flat = x.reshape(n, -1).astype(np.float32)
    return (flat - (flat @ pinv.T) @ basis.T).reshape(n, h, w)


@cache
def _band_means(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """(indices of the high band in the flattened rfft2 grid, (band cells, 6) weights: the means over the
    high band, the lower and upper sub-bands and the four orientation sectors, as one matrix product)."""
    _, high, low_sub, high_sub, sector = _bands(h, w)
    idx = np.flatnonzero(high)
    masks = [high, low_sub, high_sub] + [high & (sector == k) for k in range(4)]
    cols = [m.ravel()[idx].astype(np.float64) for m in masks]
    return idx, np.stack([c / c.sum() for c in cols], axis=1)


def _spectral(x: np.ndarray) -> np.ndarray:
    """Statistics 0-3 of the module docstring, uncalibrated, (N, 4)."""
    n, h, w = x.shape
    window = _bands(h, w)[0]
    idx, weights = _band_means(h, w)
    out = np.empty((n, 4))
    for i in range(0, n, _CHUNK):
        f = scipy.fft.rfft2(_detrend(x[i:i + _CHUNK]) * window)  # float32 (scipy keeps the precision)
        ph = (f.real**2 + f.imag**2).reshape(f.shape[0], -1)[:, idx].astype(np.float64) + 1e-12  # high-band power
        m = ph @ weights  # means: high band, lower / upper sub-band, four sectors
        out[i:i + _CHUNK, 0] = np.log(m[:, 0]) - np.log(ph).mean(axis=1)
        out[i:i + _CHUNK, 1] = np.log(m[:, 1] / m[:, 2])
        out[i:i + _CHUNK, 2] = np.log(ph.max(axis=1) / m[:, 0])
        sec = m[:, 3:]
        out[i:i + _CHUNK, 3] = np.log(sec.max(axis=1) / sec.min(axis=1))
    return out


def high_band_median_power(x: np.ndarray) -> np.ndarray:
    """(N,) median periodogram power over the high band of each plane-detrended, Hann-windowed patch (N, H, W).
    A grating or a few edges occupy few frequency bins and leave the median alone; for white noise it is
    proportional to the variance."""
    n, h, w = x.shape
    window, high = _bands(h, w)[:2]
    idx = np.flatnonzero(high)
    out = np.empty(n)
    for i in range(0, n, _CHUNK):
        f = scipy.fft.rfft2(_detrend(x[i:i + _CHUNK]) * window)
        out[i:i + _CHUNK] = np.median((f.real**2 + f.imag**2).reshape(f.shape[0], -1)[:, idx], axis=1)
    return out


def _spatial(x: np.ndarray, shape: np.ndarray | None, fine: np.ndarray | None = None,
             shaped: np.ndarray | None = None) -> np.ndarray:
    """Statistics 4-5 of the module docstring, uncalibrated, (N, 2); block energies divided by the model's
    sigma shape when given (noise whose level follows the intensity is not texture). ``fine``: the
    patches' Immerkaer residual, ``shaped``: its block energies divided by the shape, if already computed."""
    n, h, w = x.shape
    fine = immerkaer(x) if fine is None else fine
    e1 = np.mean(np.square(fine, dtype=np.float64), axis=(1, 2))
    even = x[:, :h // 2 * 2, :w // 2 * 2]
    binned = (even[:, 0::2, 0::2] + even[:, 1::2, 0::2] + even[:, 0::2, 1::2] + even[:, 1::2, 1::2]) * np.float32(0.25)
    e2 = np.mean(np.square(immerkaer(binned), dtype=np.float64), axis=(1, 2))
    blocks = block_energies(fine / (1.0 if shape is None else shape), BLOCK) if shaped is None else shaped
    spread = np.log(blocks.mean(axis=1) + 1e-9) - np.log(quantiles(blocks, (0.1,))[:, 0] + 1e-9)
    return np.stack([0.5 * np.log((4.0 * e2 + 1e-9) / (e1 + 1e-9)), spread], axis=1)


def _raw(x: np.ndarray, shape: np.ndarray | None = None, fine: np.ndarray | None = None,
         shaped: np.ndarray | None = None) -> np.ndarray:
    return np.concatenate([_spectral(x), _spatial(x, shape, fine, shaped)], axis=1)


@cache
def white_reference(h: int, w: int) -> np.ndarray:
    """Mean of each raw statistic on white noise of an h x w patch (seeded Monte-Carlo, 512 patches);
    the statistics are scale-free, so one level serves every noise level."""
    noise = np.random.default_rng(20241).standard_normal((512, h, w)).astype(np.float32) * 4.0 + 128.0
    return _raw(noise).mean(axis=0)


def texture_evidence(patches: np.ndarray, shape: np.ndarray | None = None, fine: np.ndarray | None = None,
                     shaped: np.ndarray | None = None) -> np.ndarray:
    """(N, N_EVIDENCE) float32: each statistic of the module docstring minus its white-noise mean.
    ``shape``: the model's per-pixel sigma shape (N, H, W) (``features.compact_inputs``), or None;
    ``fine`` (the patches' Immerkaer residual) and ``shaped`` (its block energies divided by ``shape``):
    computed here unless given (the measurement's features share them)."""
    x = np.asarray(patches, dtype=np.float32)
    if x.ndim != 3 or min(x.shape[1:]) < 2 * BLOCK:
        raise ValueError(f"texture evidence needs (N, H, W) patches of at least {2 * BLOCK} px, got {x.shape}")
    return (_raw(x, shape, fine, shaped) - white_reference(*x.shape[1:])).astype(np.float32)


