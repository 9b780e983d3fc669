"""Per hold of a bag: the measured temporal noise minus the model's (camera profile + the given true effects), in DN^2,
with its standard error, and the pooled excess over the holds in standard errors (the lab's measurement and model, as
the code on the path has them: run it with another source tree on PYTHONPATH for a before / after).

    .venv/bin/python experiments/lab_several_effects/temporal_excess.py BAG PROFILE [EFFECT:param=value,...]
"""
from __future__ import annotations

import sys

import numpy as np
import torch

from noise_monitor.bag.reader import open_bag
from noise_monitor.lab.compare import Comparison, baseline_effects
from noise_monitor.lab.measure import measure_frames
from noise_monitor.physics import NoiseModel, load_profile
from noise_monitor.physics.effects import effect_class


def main(bag: str, profile: str, truth: list[str]) -> None:
    torch.set_num_threads(1)
    prof = load_profile(profile)
    with open_bag(bag) as reader:
        frames = list(reader.frames(prof))
    meas = measure_frames(frames)
    extra = []
    for spec in truth:
        name, _, kv = spec.partition(":")
        extra.append(effect_class(name)(**{k: float(v) for k, v in (x.split("=") for x in kv.split(",") if x)}))
    comp = Comparison(meas, NoiseModel(baseline_effects(prof, meas.segments[0].meta, True) + extra))
    temps = {f.index: f.metadata.sensor_temperature_c for f in frames if f.metadata is not None}
    excess, weight = [], []
    for sb in comp.segments:
        seg = sb.seg
        d = np.asarray(seg.values["temporal"])[sb.rep] - np.asarray(sb.clip_aware["temporal"])
        se = float(d.std(ddof=1) / np.sqrt(d.size))
        t = [temps[i] for i in seg.frames]
        print(f"hold {seg.index:3d}: {len(t):2d} frames, {min(t):5.1f}-{max(t):5.1f} degC, "
              f"{1e3 * seg.meta.exposure_time_s:7.2f} ms, {seg.meta.gain_db:4.1f} dB: temporal excess "
              f"{d.mean():+8.4f} +- {se:.4f} DN^2")
        excess.append(float(d.mean()))
        weight.append(se**-2)
    w = np.array(weight)
    mean, err = float(np.sum(w * np.array(excess)) / w.sum()), float(w.sum() ** -0.5)
    print(f"pooled excess {mean:+.5f} +- {err:.5f} DN^2, z = {mean / err:+.2f}")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], sys.argv[3:])
