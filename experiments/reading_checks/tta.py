"""The threshold oracle and oracle head of ``bench/estimator_ceiling.py`` with the reading averaged over flips.

Test-time augmentation: sigma_image read on the 8 flips / rotations of each patch (the noise is the same
in law, the network's error on a texture may not be), averaged in variance; the predicted error likewise,
``measurable`` recomputed from it with the shipped limits. ``TTA=1`` is the shipped reading, ``TTA=8`` all
eight transforms. Run from the repository root; the options are estimator_ceiling.py's.

Usage: TTA=8 .venv/bin/python experiments/reading_checks/tta.py --sets photos --thresholds
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
import estimator_ceiling  # noqa: E402

from noise_monitor.estimator.inference import is_measurable  # noqa: E402

TRANSFORMS = (lambda x: x, lambda x: x[:, ::-1], lambda x: x[:, :, ::-1], lambda x: x[:, ::-1, ::-1])


def transforms(n: int) -> list:
    """The first ``n`` of the 8 dihedral transforms of a (N, H, W) batch."""
    both = [*TRANSFORMS, *(lambda x, t=t: t(x.transpose(0, 2, 1)) for t in TRANSFORMS)]
    return both[:n]


class Averaged:
    """An estimator whose sigma_image (and its predicted error) is the RMS over ``n`` transforms of the patch."""

    def __init__(self, est, n: int) -> None:
        self.est, self.n = est, n

    def predict(self, patches: np.ndarray, metas) -> dict:
        outs = [self.est.predict(np.ascontiguousarray(t(np.asarray(patches))), metas) for t in transforms(self.n)]
        out = dict(outs[0])
        s = np.stack([np.asarray(o["sigma_image"], float) for o in outs])
        e = np.stack([np.asarray(o["sigma_image_error"], float) for o in outs])
        out["sigma_image"] = np.sqrt(np.mean(s**2, axis=0))
        out["xi"] = np.asarray(out["sigma_model"], float) - out["sigma_image"]
        out["sigma_image_error"] = np.sqrt(np.mean(e**2, axis=0))
        out["measurable"] = is_measurable(out["sigma_image_error"], out["sigma_image_error"] / np.maximum(out["sigma_image"], 1e-6))
        print(f"   [{self.n} transforms] readings' spread over the transforms: median {np.median(s.std(axis=0)):.3f} DN")
        return out


if __name__ == "__main__":
    shipped = estimator_ceiling.estimator
    estimator_ceiling.estimator = lambda args: Averaged(shipped(args), int(os.environ.get("TTA", "8")))
    estimator_ceiling.main()
