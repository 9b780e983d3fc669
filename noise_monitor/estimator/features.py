"""Inputs of the compact image-noise network, computed identically in training and inference.

The stated metadata's *scale* never reaches the measurement: residuals are divided by the model's
per-pixel sigma normalised to unit RMS over the patch (its shape: how the noise varies with the
intensity, which a gain error leaves unchanged) times a reference scale measured from the image alone
(:func:`reference_sigma`), and the network predicts ``log(sigma_image / reference)``. Hence
sigma_image does not follow the stated gain (test_estimator.py measures the leakage).
"""
from __future__ import annotations

from functools import cache

import numpy as np

from .bound import noise_upper_bound
from .evidence import high_band_median_power, texture_evidence
from .physics_prior import SIGMA_MAP_FLOOR, box_smooth, predict_from_tables
from .residuals import BLOCK, block_energies, block_means, immerkaer, laplacian, quantiles

#: Floor of the reference scale and of sigma_model (DN).
SIGMA_MODEL_FLOOR = 0.05
#: Block size and quantiles of the block-wise residual energy (texture-robust noise cues).
BLOCK_QUANTILES = (0.1, 0.25, 0.5)
#: Quantile of the block energies of the Immerkaer residual that sets the reference scale (tuned on
#: crops of the training photographs: 0.05-0.25 and 4 / 8 px blocks, Immerkaer and Laplacian compared).
REFERENCE_QUANTILE = 0.05
#: Variance of the 4-neighbour Laplacian of unit white noise (16 + 4 x 1).
LAPLACIAN_GAIN = 20.0
#: Scalar inputs of the compact net: log reference scale, source fractions (3), log residual energy
#: ratios (2), log block-energy quantiles of both residuals (6) (see :func:`compact_inputs`).
N_SCALARS = 12
#: Scalars of the optional shape-trend input (:func:`shape_trend`).
N_SHAPE_TREND = 2
#: Quantile of the shaped block energies within each intensity half (:func:`shape_trend`).
TREND_QUANTILE = 0.25
#: Scalars of the optional spectral input (:func:`spectral_scale`).
N_SPECTRAL = 1


def sigma_shape(sigma_map: np.ndarray) -> np.ndarray:
    """The model's per-pixel sigma (N, H, W), floored, normalised to unit RMS over each patch: how the noise varies
    with the intensity, which a gain error leaves unchanged."""
    floored = np.maximum(sigma_map, SIGMA_MAP_FLOOR)
    return floored / np.sqrt(np.mean(np.square(floored), axis=(1, 2), keepdims=True))


def block_energy_quantiles(resid: np.ndarray, block: int = BLOCK) -> np.ndarray:
    """log of low quantiles of the mean squared residual per ``block`` x ``block`` block (N, Q).

    Texture raises the energy of some blocks; the flattest blocks carry the noise alone, so low
    quantiles measure noise where the whole-patch energy would read texture as noise.
    """
    return np.log(quantiles(block_energies(resid, block), BLOCK_QUANTILES) + 1e-6)


@cache
def unit_noise_quantile(h: int, w: int) -> float:
    """The ``REFERENCE_QUANTILE`` of the Immerkaer block energies of unit white noise on an h x w patch
    (the order statistic's bias in :func:`reference_sigma`; seeded Monte-Carlo over 256 patches)."""
    noise = np.random.default_rng(20240).standard_normal((256, h, w)).astype(np.float32)
    return float(quantiles(block_energies(immerkaer(noise)), (REFERENCE_QUANTILE,)).mean())


def reference_sigma(noisy: np.ndarray, shape: np.ndarray, shaped_energies: np.ndarray | None = None) -> np.ndarray:
    """Noise scale (DN) from the image alone: a low quantile of the block energies of the Immerkaer
    residual divided by the model's sigma shape (``shaped_energies``, computed here if None), corrected by
    its value on white noise."""
    n, h, w = noisy.shape
    if shaped_energies is None:
        shaped_energies = block_energies(immerkaer(noisy) / shape)
    q = quantiles(shaped_energies, (REFERENCE_QUANTILE,))[:, 0]
    return np.maximum(np.sqrt(q / unit_noise_quantile(h, w)), SIGMA_MODEL_FLOOR)


def shape_trend(shaped_energies: np.ndarray, smooth: np.ndarray) -> np.ndarray:
    """How the noise's intensity dependence departs from the stated shape's (N, N_SHAPE_TREND): the log ratio of
    a low quantile of the shaped block energies in the brighter half of the blocks to that in the darker
    half, and the log ratio of the halves' median intensities. About 0 where the stated shape is the
    noise's; positive where the noise grows faster with intensity than stated (an unstated PRNU); texture
    in one half moves it too, so it is an input to learn from, not a correction.
    """
    inten = block_means(smooth)
    order = np.argsort(inten, axis=1, kind="stable")
    energies, inten = np.take_along_axis(shaped_energies, order, 1), np.take_along_axis(inten, order, 1)
    half = energies.shape[1] // 2
    dark, bright = (quantiles(e, (TREND_QUANTILE,))[:, 0] for e in (energies[:, :half], energies[:, half:]))
    span = np.log((np.median(inten[:, half:], axis=1) + 1.0) / (np.median(inten[:, :half], axis=1) + 1.0))
    return np.stack([np.log((bright + 1e-6) / (dark + 1e-6)), span], axis=1)


@cache
def unit_noise_spectral_median(h: int, w: int) -> float:
    """The high-band median periodogram power of unit white noise on an h x w patch (seeded Monte-Carlo, 256
    patches): the calibration of :func:`spectral_scale`."""
    noise = np.random.default_rng(20242).standard_normal((256, h, w)).astype(np.float32)
    return float(high_band_median_power(noise).mean())


def spectral_scale(noisy: np.ndarray, shape: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """(N, N_SPECTRAL): log of a line-robust noise scale over the reference scale: the median of the high-band
    periodogram (|f| >= 0.25 cycles/px, ``evidence.high_band_median_power``) of the patch divided by the model's
    sigma shape, calibrated on white noise. A pixel-scale grating, which the reference and the residual maps read
    as noise, fills a few frequency bins and leaves it alone; texture spread over the band raises it like the
    reference. About 0 on white noise of the reference's level."""
    n, h, w = noisy.shape
    sigma = np.sqrt(high_band_median_power(noisy / shape) / unit_noise_spectral_median(h, w))
    return np.log(np.maximum(sigma, SIGMA_MODEL_FLOOR) / ref)[:, None]


def compact_inputs(noisy: np.ndarray, tables: np.ndarray, group_of: np.ndarray,
                   evidence: bool = False, upper: bool = False, trend: bool = False,
                   spectral: bool = False) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """(maps (N, 3, H, W), scalars (N, N_SCALARS), physics prediction + ``reference``) for noisy patches in DN.

    maps: the residual to the 5x5 box filter and the Laplacian / sqrt(20) (unit variance on white
    noise; a linear ramp leaves none), both divided by the model's sigma shape (unit RMS per patch)
    and the image's reference scale (:func:`reference_sigma`), and the intensity / 255 - 0.5.
    scalars: log reference, the paper's three sources' shares of their summed variance (3), per residual the log mean
    square and its block quantiles (2 x 4). No metadata scale: see the module docstring.
    ``evidence``: also the texture evidence of the confidence head (``evidence.texture_evidence``).
    ``upper``: also ``phys["upper"]``, the image-only upper bound of the noise (``bound.noise_upper_bound``).
    ``trend``: append the :func:`shape_trend` scalars (networks with ``CompactConfig.shape_trend``).
    ``spectral``: then the :func:`spectral_scale` scalar (networks with ``CompactConfig.spectral``).
    """
    smooth = box_smooth(noisy)
    phys = predict_from_tables(smooth, tables, group_of, with_map=True)
    shape = sigma_shape(phys.pop("sigma_map"))
    fine = immerkaer(noisy)  # shared by the reference and the texture evidence
    shaped = block_energies(fine / shape)
    ref = reference_sigma(noisy, shape, shaped)
    norm = shape * ref.astype(np.float32)[:, None, None]
    maps = np.empty((noisy.shape[0], 3) + noisy.shape[1:], dtype=np.float32)  # filled in place
    resid = np.divide(np.subtract(noisy, smooth, out=maps[:, 0]), norm, out=maps[:, 0])
    lap = np.divide(laplacian(noisy), np.sqrt(LAPLACIAN_GAIN, dtype=np.float32) * norm, out=maps[:, 1])
    np.subtract(np.divide(noisy, np.float32(255.0), out=maps[:, 2]), np.float32(0.5), out=maps[:, 2])
    # the paper's sources' shares of their own sum: an effect the stated model adds (``extra``) stays out of the
    # network's inputs, as in all its training data (issue 15 item 3: the stated model kept out of the measurement)
    var = np.stack([phys[s] ** 2 for s in ("pn", "dcsn", "rn")], axis=1)
    paper = np.maximum(np.sqrt(var.sum(axis=1)), SIGMA_MODEL_FLOOR)
    shares = var / paper[:, None] ** 2
    energy = [np.log(np.mean(np.square(r), axis=(1, 2)).astype(np.float64) + 1e-6)[:, None] for r in (resid, lap)]
    scalars = np.concatenate([np.log(ref)[:, None], shares, energy[0], block_energy_quantiles(resid),
                              energy[1], block_energy_quantiles(lap)]
                             + ([shape_trend(shaped, smooth)] if trend else [])
                             + ([spectral_scale(noisy, shape, ref)] if spectral else []), axis=1).astype(np.float32)
    phys["reference"] = ref
    if upper:
        phys["upper"] = noise_upper_bound(noisy, shaped)
    if evidence:
        phys["evidence"] = texture_evidence(noisy, shape, fine, shaped)
    return maps, scalars, phys
