"""The stated black level (pedestal) against the image: pixels far below it contradict it.

A camera's pedestal keeps its noise below black, so with the right black level taken off an image reads at most a
few dark-noise sigmas below zero; a black level stated above the camera's leaves its dark pixels far below zero
(raw zeros under a stated pedestal). The image cannot contradict a black level stated too low (the lab's
``black_level`` effect finds that one).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: a pixel this many dark-noise sigmas (+ 1 DN of rounding) below the stated black level is not noise (8 sigmas:
#: a dark noise twice the model's stays below it on all but ~3e-5 of the pixels)
BLACK_SIGMAS = 8.0
#: ... and the statement is contradicted when more than this share of the frame's pixels are (dead pixels: fewer)
CONTRADICTED_FRACTION = 0.002
#: the image's quantile whose level bounds the camera's black level from above (its darkest pixels)
DARK_QUANTILE = 0.001
#: ... allowing that many dark-noise sigmas above it
BOUND_SIGMAS = 3.5


#: who stated a black level, for people
STATED_BY = {"parameter": "node parameter black_level_dn", "metadata": "the camera's metadata",
              "profile": "camera profile"}
_FIX = {"parameter": "set the parameter to the camera's",
        "metadata": "check the conversion of the driver's value (profile driver_black_level_dn) or override it "
                    "(node parameter black_level_dn)",
        "profile": "state the camera's (profile black_level_dn, node parameter black_level_dn)"}


@dataclass(frozen=True)
class BlackLevelCheck:
    """Pixels below the stated black level: their share (%) beyond noise, and what the image bounds the camera's
    black level to when they contradict the statement."""

    black_level_dn: float
    below_pct: float
    limit_dn: float  # how far below the stated black level a pixel counts (DN)
    upper_dn: float | None  # the camera's black level is at most this (None: not contradicted)
    source: str = "profile"  # who stated it: "parameter", "metadata" (per frame) or "profile"

    @property
    def contradicted(self) -> bool:
        return self.upper_dn is not None

    def message(self) -> str:
        return (f"{self.below_pct:.2g} % of the pixels read more than {self.limit_dn:.1f} DN below the stated black "
                f"level of {self.black_level_dn:g} DN ({STATED_BY[self.source]}): the camera's is lower (at most "
                f"{self.upper_dn:.1f} DN); {_FIX[self.source]}")


def check_black_level(image_dn: np.ndarray, black_level_dn: float, sigma_dark_dn: float,
                      source: str = "profile") -> BlackLevelCheck | None:
    """The check of a frame (``image_dn`` with the stated ``black_level_dn`` taken off) given the model's dark noise
    (DN: every source but the signal's shot noise) and who stated it; None without a stated black level."""
    if black_level_dn <= 0.0:
        return None
    limit = BLACK_SIGMAS * sigma_dark_dn + 1.0
    below = int(np.count_nonzero(image_dn < -limit))
    share = below / image_dn.size
    upper = None
    if share > CONTRADICTED_FRACTION:
        flat = image_dn.ravel()
        k = int(DARK_QUANTILE * flat.size)
        dark = float(np.partition(flat, k)[k])
        upper = min(max(black_level_dn + dark + BOUND_SIGMAS * sigma_dark_dn + 0.5, 0.0), black_level_dn)
    return BlackLevelCheck(black_level_dn, 100.0 * share, limit, upper, source)
