"""Does the estimator under-read flat content because of the input's rounding? (the lead left by twin.py)

    .venv/bin/python experiments/real_sensor_flats/flat_rounding.py

Flat 64 px patches (30 and 128 DN) with Gaussian noise of 0.5-5 DN, each read three ways: unrounded, rounded to 8-bit
codes (an 8-bit camera), rounded to 1/16 DN (a 12-bit camera on the 8-bit scale, as the real CCD's bag); random
metadata per patch (the reading does not follow it: issue 15's leakage test). Printed: the mean relative error of
sigma_image against each patch's own noise, with its standard error, 300 patches per cell (seeded).
"""
from __future__ import annotations

import numpy as np

from noise_monitor.estimator import load
from noise_monitor.physics import sample_metadata

STEPS = {"unrounded": None, "8-bit codes": 1.0, "1/16 DN": 1 / 16}


def main() -> None:
    est = load("full_meta", device="cpu", threads=1)
    rng = np.random.default_rng(5)
    metas = [sample_metadata(rng) for _ in range(300)]
    print("level  sigma  " + "  ".join(f"{k:>16s}" for k in STEPS))
    for level in (30.0, 128.0):
        for sigma in (0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 5.0):
            cells = []
            for step in STEPS.values():
                img = level + rng.normal(size=(300, 64, 64)) * sigma
                if step:
                    img = np.rint(img / step) * step
                truth = (img - level).reshape(300, -1).std(axis=1)
                rel = np.asarray(est.predict(img.astype(np.float32), metas)["sigma_image"], float) / truth - 1.0
                cells.append(f"{100 * rel.mean():+6.2f} +- {100 * rel.std() / np.sqrt(rel.size):.2f} %")
            print(f"{level:5.0f}  {sigma:5.2f}  " + "  ".join(f"{c:>16s}" for c in cells), flush=True)


if __name__ == "__main__":
    main()
