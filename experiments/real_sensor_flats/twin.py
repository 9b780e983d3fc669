"""A simulated twin of run.py's real flat-field bag, to tell the real noise's part in xi from the estimator's own.

    .venv/bin/python experiments/real_sensor_flats/twin.py PATH/EMVA1288_ReferenceSet_001_CCD_12Bit --out out/real_ccd

(after run.py with the same --out). Each twin frame: its level's smooth mean image (the pair's mean less its pixel
scale: a 31x31 box mean, the light's shading kept), a white PRNU of the profile's pixel-scale figure, Gaussian
temporal noise of the pair's variance and the dark offset, rounded to 12-bit codes; the same metadata. Both bags are
replayed with run.py's profile; printed: xi and sigma_image / sigma_model over the 5-70 % window, real and twin.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import numpy as np
from run import TEMPERATURE_C, frames
from scipy.ndimage import uniform_filter

from noise_monitor.bag.messages import image_msg, metadata_msg
from noise_monitor.bag.replay import replay
from noise_monitor.bag.results import FrameTable
from noise_monitor.bag.writer import BagWriter
from noise_monitor.physics import load_profile
from noise_monitor.profiles.emva_images import find_descriptor


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("dataset", type=Path)
    p.add_argument("--out", type=Path, required=True, help="run.py's output folder")
    p.add_argument("--seed", type=int, default=3)
    args = p.parse_args()
    descriptor = find_descriptor(args.dataset)
    if descriptor is None:
        raise SystemExit(f"{args.dataset}: no EMVA descriptor")
    rows = frames(descriptor)
    char = json.loads((args.out / "char" / "characterize.json").read_text())
    offset = char["figures"]["black_level_dn"]["value"]  # 12-bit codes
    profile_path = args.out / "char" / "profile.yaml"
    profile = load_profile(profile_path)
    rng = np.random.default_rng(args.seed)
    pairs: dict[int, list[Path]] = {}
    for row in rows:
        pairs.setdefault(row[3], []).append(row[2])
    first = cv2.imread(str(rows[0][2]), cv2.IMREAD_UNCHANGED)
    prnu = 1.0 + char["figures"]["prnu_hpf_pct"]["value"] / 100.0 * rng.standard_normal(first.shape)
    twin = args.out / "twin.mcap"
    twin.unlink(missing_ok=True)
    with BagWriter(twin) as w:
        for i, (exposure, _, _, level) in enumerate(rows):
            a, b = (cv2.imread(str(f), cv2.IMREAD_UNCHANGED).astype(np.float64) for f in pairs[level][:2])
            smooth = uniform_filter((a + b) / 2.0, 31, mode="reflect") - offset
            img = offset + smooth * prnu + np.sqrt(np.var(a - b) / 2.0) * rng.standard_normal(a.shape)
            stamp = 1_700_000_000_000_000_000 + i * 100_000_000
            meta = profile.metadata(gain_db=0.0, exposure_time_s=exposure, sensor_temperature_c=TEMPERATURE_C)
            w.write("/camera/metadata", metadata_msg(meta, stamp, "twin"), stamp)
            w.write("/camera/image_raw", image_msg(np.clip(np.rint(img), 0, 4095).astype(np.uint16), stamp), stamp)
    window = np.array([r["in_window"] for r in json.loads((args.out / "summary.json").read_text())["per_frame"]])
    for label, bag in (("real", args.out / "flats.mcap"), ("twin", twin)):
        t = FrameTable()
        replay(bag, profile_path, None, progress=False, table=t)
        m = window & t.column("processed").astype(bool)
        xi = t.numbers("xi").astype(float)[m]
        ratio = (t.numbers("sigma_image").astype(float) / t.numbers("sigma_model").astype(float))[m]
        print(f"{label}: xi RMS {np.sqrt(np.mean(xi**2)):.4f} DN, mean {xi.mean():+.4f} DN, sigma_image / sigma_model "
              f"{ratio.mean():.4f} over {m.sum()} frames")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
