"""The fixed pattern's shape: its kurtosis from four views of each sensor pixel at four camera poses.

A Gaussian fixed pattern (PRNU, DSNU, line offsets) and a sparse one (a few pixels far off: hot or random
telegraph pixels below the outlier threshold) can have the same variance; their kurtosis tells them apart.
The lab's measurement (:mod:`.measure`) has, per block, the plane-fit residual of a hold's mean and of the
same sensor block seen from other camera poses; scene texture and temporal noise differ between views and
cancel in expectation, a fixed pattern does not (:class:`FixedShape`).
"""
from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np


class View(Protocol):
    """One hold's view of the blocks: plane-fit residuals of its mean (N, b*b), their white variance (N,) and
    the camera's pose (px)."""

    residual: np.ndarray
    white: np.ndarray
    pose: np.ndarray


class Moments(Protocol):
    """A segment's per-block fourth moments (see :func:`fourth_moments`; None: none measured)."""

    fixed_fourth: np.ndarray | None
    fixed_square: np.ndarray | None


#: a fixed pattern is sparse (a few pixels far off) when its kurtosis exceeds a Gaussian's by SHAPE_Z standard
#: errors (the larger of the spread over blocks and the jackknife over segments), is at least SHAPE_KURTOSIS,
#: and its second moment is SHAPE_SQUARE_Z standard errors above 0 (the pattern exists); both z-scores need
#: SHAPE_MIN_SEGMENTS segments with four views
SHAPE_Z = 5.0
SHAPE_KURTOSIS = 6.0
SHAPE_SQUARE_Z = 3.0
SHAPE_MIN_SEGMENTS = 4


@dataclass(frozen=True)
class FixedShape:
    """The fixed pattern's kurtosis over the segments with four views (:func:`fixed_shape`).

    Per block, with this hold's plane-fit residual A and three partner views B, C, D at mutually distinct
    poses (each pair far enough apart that the scene moved), scene and temporal noise differ between the views
    and cancel in expectation: mean(A B C D) is the fixed pattern's fourth moment E[P^4], and the product of
    two cross energies over different pixels (A B at one pixel, C D at another) is E[P^2]^2. Their ratio,
    pooled over blocks (weighted by the inverse product of the four views' white variances), is the
    kurtosis: 3 for a Gaussian pattern (PRNU, DSNU, line offsets) at any level, ~1/f for a fraction f of
    pixels far off. ``excess_z`` tests E[P^4] - 3 E[P^2]^2 > 0, ``square_z`` E[P^2]^2 > 0."""

    kurtosis: float
    kurtosis_err: float
    excess_z: float
    square_z: float
    segments: int
    blocks: int

    @property
    def sparse(self) -> bool:
        """Whether the pattern is significantly heavier-tailed than a Gaussian one (see SHAPE_Z)."""
        return (self.segments >= SHAPE_MIN_SEGMENTS and self.square_z >= SHAPE_SQUARE_Z
                and self.excess_z >= SHAPE_Z and self.kurtosis >= SHAPE_KURTOSIS)

    def summary(self) -> dict[str, Any]:
        return {"kurtosis": round(self.kurtosis, 3), "kurtosis_err": round(self.kurtosis_err, 3),
                "excess_z": round(self.excess_z, 2), "square_z": round(self.square_z, 2),
                "segments": self.segments, "blocks": self.blocks, "sparse": self.sparse}


def fixed_shape_text(shape: dict[str, Any]) -> str:
    """One line for people from :meth:`FixedShape.summary` (or its ``not_measured`` entry)."""
    if "not_measured" in shape:
        return f"fixed pattern shape not measured: {shape['not_measured']}"
    if shape["square_z"] < SHAPE_SQUARE_Z:  # no pattern: its kurtosis, a ratio over ~0, says nothing
        return (f"fixed pattern shape: no fixed pattern beyond the measurement's noise over {shape['segments']} holds "
                f"seen from four poses (its second moment {shape['square_z']:.1f} standard errors above 0)")
    if shape["sparse"]:
        verdict = "sparse: a few pixels far off (a Gaussian pattern, e.g. PRNU, has 3)"
    else:
        verdict = "consistent with a Gaussian pattern (3)"
    return (f"fixed pattern shape: kurtosis {shape['kurtosis']:.1f} +- {shape['kurtosis_err']:.1f} over "
            f"{shape['segments']} holds seen from four poses, {verdict}")


def fixed_shape(segments: Iterable[Moments]) -> FixedShape | None:
    """The fixed pattern's kurtosis (:class:`FixedShape`), None without a segment with four views. Standard
    errors: the larger of the spread over blocks (delta method) and the jackknife over segments (blocks of
    one segment share views, segments share the pattern)."""
    per = [(s.fixed_fourth, s.fixed_square) for s in segments
           if s.fixed_fourth is not None and s.fixed_square is not None and np.any(s.fixed_square != 0.0)]
    if not per:
        return None
    n4 = np.concatenate([a for a, _ in per])
    d4 = np.concatenate([b for _, b in per])
    used = (n4 != 0.0) | (d4 != 0.0)
    n4, d4 = n4[used], d4[used]
    nb, m = int(n4.size), len(per)
    seg_n4 = np.array([float(a.sum()) for a, _ in per])
    seg_d4 = np.array([float(b.sum()) for _, b in per])

    def jackknife(values: np.ndarray) -> float:
        """Jackknife standard error over segments of a statistic's leave-one-out values."""
        return math.sqrt((m - 1) / m * float(np.sum((values - values.mean()) ** 2))) if m >= 2 else math.inf

    def total_se(block: np.ndarray, seg: np.ndarray) -> float:
        """Standard error of a sum over blocks: the larger of the delta method's and the jackknife's."""
        return max(math.sqrt(float(block.var()) * nb), jackknife(seg.sum() - seg))

    d_total = float(d4.sum())
    kurt = float(n4.sum()) / d_total if d_total != 0.0 else math.nan
    if d_total != 0.0 and np.all(seg_d4.sum() - seg_d4 != 0.0):
        kurt_err = max(math.sqrt(float((n4 - kurt * d4).var()) * nb) / abs(d_total),
                       jackknife((seg_n4.sum() - seg_n4) / (seg_d4.sum() - seg_d4)))
    else:
        kurt_err = math.inf
    ex_se, sq_se = total_se(n4 - 3.0 * d4, seg_n4 - 3.0 * seg_d4), total_se(d4, seg_d4)
    return FixedShape(kurt, kurt_err, float((n4 - 3.0 * d4).sum()) / ex_se if ex_se > 0 else 0.0,
                      d_total / sq_se if sq_se > 0 else 0.0, m, nb)


def fourth_moments(f: View, cands: Sequence[View], valid: np.ndarray, min_shift_px: float,
                   min_var: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Per block of ``f``, the fixed pattern's fourth moment and squared second moment from four views
    (:class:`FixedShape`): over the triples of partners at mutually distinct poses (``min_shift_px`` apart)
    where the block is flat in all four views (``valid`` (N, P): weight of each partner view per block), mean(A
    B C D) and the mean over pixel pairs i != j of A_i B_i C_j D_j (each of the three pairings), weighted by the
    inverse product of the views' white variances (floored at ``min_var`` each). None without such a triple."""
    far = [[float(np.hypot(*(g.pose - h.pose))) >= min_shift_px for h in cands] for g in cands]
    triples = [t for t in itertools.combinations(range(len(cands)), 3)
               if far[t[0]][t[1]] and far[t[0]][t[2]] and far[t[1]][t[2]]]
    if not triples:
        return None
    a = f.residual
    npix = a.shape[1]
    x = [g.residual for g in cands]
    cross = [np.einsum("ij,ij->i", a, xj) for xj in x]  # (N,) per partner: sum_i A_i X_i
    ax = [a * xj for xj in x]
    dots: dict[tuple[int, int], np.ndarray] = {}

    def dot(p: int, q: int) -> np.ndarray:
        """sum_i X_p,i X_q,i per block (cached)."""
        if (p, q) not in dots:
            dots[p, q] = np.einsum("ij,ij->i", x[p], x[q])
        return dots[p, q]

    by_pair: dict[tuple[int, int], list[int]] = {}
    for j, k, m in triples:  # grouped by the last two partners: their product is formed once
        by_pair.setdefault((k, m), []).append(j)
    fourth = np.zeros(a.shape[0])
    square = np.zeros(a.shape[0])
    for (k, m), js in by_pair.items():
        xkm = x[k] * x[m]
        dkm = xkm.sum(axis=1)
        for j in js:
            ok = valid[:, j] * valid[:, k] * valid[:, m]
            w = ok / np.maximum(f.white * cands[j].white * cands[k].white * cands[m].white, min_var**4)
            s4 = np.einsum("ij,ij->i", ax[j], xkm)
            pairs = cross[j] * dkm + cross[k] * dot(j, m) + cross[m] * dot(j, k)
            fourth += w * s4 / npix
            square += w * (pairs - 3.0 * s4) / (3.0 * npix * (npix - 1))
    return fourth, square
