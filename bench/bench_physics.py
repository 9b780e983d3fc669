"""Physics core benchmark: simulation throughput (MP/s) and analytic predictions per second.

Run: .venv/bin/python bench/bench_physics.py   (prints one table; figures go into README)
"""
from __future__ import annotations

import time

import numpy as np

from noise_monitor.physics import NoiseModel, load_profile

ALL_EFFECTS = ["prnu", "dsnu", "row_offsets", "column_offsets", "quantization=8", "hot_pixels",
               "extra_read_noise", "dark_current_law", "gain_error=1.1", "exposure_error", "temperature_error"]


def _time(fn, repeat: int) -> float:
    fn()  # warm-up (tables, patterns, torch import)
    t0 = time.perf_counter()
    for _ in range(repeat):
        fn()
    return (time.perf_counter() - t0) / repeat


def main() -> None:
    rng = np.random.default_rng(0)
    meta = load_profile("ev76c661").metadata(gain_db=12.0, exposure_time_s=0.01, sensor_temperature_c=40.0)
    frame = np.clip(rng.normal(128.0, 60.0, (1024, 1280)), 0, 255).astype(np.float32)
    mp = frame.size / 1e6
    rows = []
    for label, model in (("paper (pn, dcsn, rn)", NoiseModel()), ("all 14 effects", NoiseModel(extra=ALL_EFFECTS))):
        for path, kw in (("per-source (default)", {}), ("fast, total only", {"per_source": False}),
                         ("sequential protocol", {"mode": "sequential"})):
            dt = _time(lambda: model.simulate(frame, meta, rng, **kw), 5)
            rows.append((f"simulate 1280x1024, {label}, {path}", f"{mp / dt:8.1f} MP/s", f"{dt * 1e3:8.1f} ms/frame"))
    model = NoiseModel()
    metas = [meta.replace(gain_db=float(g)) for g in np.linspace(0.0, 24.0, 20)]
    dt = _time(lambda: [NoiseModel().tables(m) for m in metas], 1) / len(metas)
    rows.append(("analytic tables per new metadata (joint)", f"{1 / dt:8.1f} /s", f"{dt * 1e3:8.1f} ms"))
    dt = _time(lambda: [NoiseModel().tables(m, "sequential") for m in metas[:5]], 1) / 5
    rows.append(("analytic tables per new metadata (sequential)", f"{1 / dt:8.1f} /s", f"{dt * 1e3:8.1f} ms"))
    levels = rng.uniform(0, 255, 100_000)
    dt = _time(lambda: model.predict(levels, meta), 10)
    rows.append(("predict, mean intensities (cached tables)", f"{levels.size / dt / 1e6:8.2f} M/s", ""))
    patches = rng.uniform(0, 255, (64, 64, 64)).astype(np.float32)
    dt = _time(lambda: model.predict(patches, meta), 10)
    rows.append(("predict, 64x64 intensity maps (cached tables)", f"{patches.shape[0] / dt:8.0f} maps/s", ""))
    width = max(len(r[0]) for r in rows)
    print(f"{'benchmark':{width}s}  {'throughput':>14s}  {'time':>14s}")
    for name, a, b in rows:
        print(f"{name:{width}s}  {a:>14s}  {b:>14s}")


if __name__ == "__main__":
    main()
