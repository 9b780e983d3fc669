"""The monitor on a real camera's flat fields (the EMVA's reference sets 001 and 002): see README.md for the rules.

    .venv/bin/python experiments/real_sensor_flats/run.py PATH/EMVA1288_ReferenceSet_001_CCD_12Bit --out out/real_ccd
    .venv/bin/python experiments/real_sensor_flats/run.py PATH/EMVA1288_ReferenceSet_002_CMOS_08Bit --out out/real_cmos \
        --exposure-unit us --sensor-type cmos --assume-undetermined
    ... --total-prnu     # the profile with the EMVA totals of PRNU / DSNU instead of the pixel-scale figures
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
from collections.abc import Iterable
from pathlib import Path

import cv2
import numpy as np

from noise_monitor.bag.replay import replay
from noise_monitor.bag.results import FrameTable, alarm_episodes
from noise_monitor.bag.stream_eval import MIN_TRUE_XI, detected, stated_gain_copy
from noise_monitor.cli import main as cli
from noise_monitor.physics import load_profile
from noise_monitor.profiles.characterize import datasheet_from_result
from noise_monitor.profiles.emva import profile_from_datasheet
from noise_monitor.profiles.emva_images import (
    EXPOSURE_UNITS,
    find_descriptor,
    flat_blocks,
    parse_descriptor,
    write_flats_bag,
)

TEMPERATURE_C = 30.0
#: the camera ran at 0 dB, the bottom of the gain range: the wrong metadata states more (6 dB unless --gain-offset-db)
GAIN_OFFSET_DB = 6.0


def frames(descriptor: Path, unit: str = "ns", left_out: Iterable[int] = ()) -> list[tuple[float, float, Path, int]]:
    """(exposure s, photons, image, level) of the flat fields in the flats bag's order, less the sets left out of it
    (by descriptor line)."""
    return [(b.exposure * EXPOSURE_UNITS[unit], b.photons or 0.0, f, level)
            for level, b in enumerate(flat_blocks(parse_descriptor(descriptor))) if b.line not in left_out
            for f in b.files]


def pair_noise(rows: list[tuple[float, float, Path, int]], scale: float) -> dict[int, float]:
    """Temporal noise per level from its first two frames' difference image (8-bit DN: codes x ``scale``)."""
    out = {}
    for level in sorted({r[3] for r in rows}):
        files = [r[2] for r in rows if r[3] == level][:2]
        a, b = (cv2.imread(str(f), cv2.IMREAD_UNCHANGED).astype(np.float64) for f in files)
        out[level] = float(np.sqrt(np.var(a - b) / 2.0)) * scale
    return out


def make_profile(char: dict, out: Path, name: str, args: argparse.Namespace) -> Path:
    """The profile `characterize` wrote, or (``--total-prnu``, ``--assume-undetermined``) one made from its figures
    with the EMVA totals of PRNU / DSNU, and EMVA's bounds where the set determines neither dark noise nor current
    (`characterize --dark-bounds`)."""
    written = out / "char" / "profile.yaml"
    if written.is_file() and not args.total_prnu:
        return written
    f = dict(char["figures"])
    if args.total_prnu:
        f["prnu_hpf_pct"], f["dsnu_hpf_e"] = f["prnu_pct"], f["dsnu_e"]
    ds, notes = datasheet_from_result({**char, "figures": f}, name, args.sensor_type, args.pixel_size_um,
                                      bounds=args.assume_undetermined)
    if ds is None:
        raise SystemExit("; ".join(notes))
    made = profile_from_datasheet(ds)
    path = out / "profile.yaml"
    path.write_text(made.to_yaml(ds, source=f"{name}, run.py's assumptions: {vars(args)}"))
    return path


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("dataset", type=Path)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--exposure-unit", default="ns", choices=tuple(EXPOSURE_UNITS))
    p.add_argument("--sensor-type", default="ccd", choices=("ccd", "cmos"))
    p.add_argument("--pixel-size-um", type=float, default=7.4)
    p.add_argument("--assume-undetermined", action="store_true",
                   help="sigma_d at EMVA's 0.49 DN bound and a dark current of 0 where the set determines neither")
    p.add_argument("--total-prnu", action="store_true", help="the profile with the EMVA totals of PRNU and DSNU")
    p.add_argument("--gain-offset-db", type=float, default=GAIN_OFFSET_DB,
                   help="how much more gain the wrong-metadata copy states (the cameras ran at 0 dB: > 0)")
    args = p.parse_args()
    if args.gain_offset_db <= 0:
        p.error("--gain-offset-db must be > 0: the cameras ran at 0 dB, the bottom of the gain range")
    args.out.mkdir(parents=True, exist_ok=True)
    descriptor = find_descriptor(args.dataset)
    if descriptor is None:
        raise SystemExit(f"{args.dataset}: no EMVA descriptor")
    with contextlib.redirect_stdout(io.StringIO()):
        assert cli(["characterize", str(descriptor), "--out", str(args.out / "char"), "--sensor-type", args.sensor_type,
                    "--pixel-size-um", str(args.pixel_size_um), "--temperature-c", str(TEMPERATURE_C),
                    "--exposure-unit", args.exposure_unit]) == 0
    char = json.loads((args.out / "char" / "characterize.json").read_text())
    sat_dn8 = char["points"]["ptc"]["saturation_dn"]
    scale = 255.0 / (2 ** char["conditions"]["bit_depth"] - 1)
    profile_path = make_profile(char, args.out, descriptor.parent.name, args)
    profile = load_profile(profile_path)
    clean, wrong = args.out / "flats.mcap", args.out / f"flats_gain_plus{args.gain_offset_db:g}db.mcap"
    for f in (clean, wrong):
        f.unlink(missing_ok=True)
    written, left_out = write_flats_bag(descriptor, clean, profile, args.exposure_unit, TEMPERATURE_C)
    rows = frames(descriptor, args.exposure_unit, left_out)  # the bag's frames, in its order
    assert written == len(rows), (written, len(rows), left_out)
    stated_gain_copy(clean, wrong, args.gain_offset_db)
    tables = {}
    for label, bag in (("clean", clean), ("wrong", wrong)):
        t = FrameTable()
        replay(bag, profile_path, None, progress=False, table=t)
        tables[label] = t
    c, w = tables["clean"], tables["wrong"]
    ok = c.column("processed").astype(bool)
    both = ok & w.column("processed").astype(bool)
    xi = c.numbers("xi").astype(float)
    true_xi = w.numbers("sigma_model").astype(float) - c.numbers("sigma_model").astype(float)
    xi_w = w.numbers("xi").astype(float)
    level = np.array([r[3] for r in rows])
    # the frame's signal above black (8-bit DN) from the image itself, for the 5-70 % window
    signal = np.array([cv2.imread(str(r[2]), cv2.IMREAD_UNCHANGED).mean() * scale for r in rows])
    signal -= (char["figures"]["black_level_dn"]["value"] or 0.0) * scale
    window = ok & (signal >= 0.05 * sat_dn8) & (signal <= 0.70 * sat_dn8)
    need = np.flatnonzero(window & both & (np.abs(true_xi) >= MIN_TRUE_XI))
    alarm = w.column("alarm").astype(bool)
    hits = [detected(alarm, level, int(i)) for i in need]
    noise = pair_noise(rows, scale)
    spatial = level == level.max()
    sig_t = c.numbers("sigma_temporal").astype(float)
    frames_t = c.numbers("temporal_frames").astype(float)
    after10 = np.flatnonzero(spatial)[9:]  # from the spatial set's 10th frame on
    summary = {
        "frames": len(rows), "left_out": {f"line {k}": v for k, v in left_out.items()}, "processed": int(ok.sum()), "in_window": int(window.sum()),
        "saturation_dn8": sat_dn8,
        "clean_xi_rms": float(np.sqrt(np.mean(xi[window] ** 2))), "clean_xi_mean": float(np.mean(xi[window])),
        "clean_alarm_episodes": len(alarm_episodes(c)),
        "gain_offset_db": args.gain_offset_db, "need": len(need), "hits": int(sum(hits)), "detection": float(np.mean(hits)) if hits else float("nan"),
        "true_xi_of_need": [round(float(true_xi[i]), 2) for i in need],
        "missed": [{"index": int(i), "level": int(level[i]), "true_xi": round(float(true_xi[i]), 3),
                    "xi": round(float(xi_w[i]), 3)} for i, hit in zip(need, hits) if not hit],
        "true_xi_wrong_gain_range": [float(np.nanmin(true_xi[window & both])), float(np.nanmax(true_xi[window & both]))],
        "wrong_gain_xi_error_rms": float(np.sqrt(np.mean((xi_w - true_xi)[window & both] ** 2))),
        "profile_prnu_pct": load_profile(profile_path).effects.get("prnu", {}).get("sigma_pct"),
        "wrong_gain_alarm_episodes": len(alarm_episodes(w)),
        "temporal_truth_dn": noise[int(level.max())],
        "sigma_temporal_after_10": [float(sig_t[i]) for i in after10[:5]],
        "temporal_frames_after_10": [float(frames_t[i]) for i in after10[:5]],
        "per_frame": [{"index": i, "level": int(level[i]), "signal_dn": round(float(signal[i]), 2),
                       "sigma_image": float(c.numbers("sigma_image")[i]), "sigma_model": float(c.numbers("sigma_model")[i]),
                       "xi": float(xi[i]), "processed": bool(ok[i]), "in_window": bool(window[i]),
                       "sigma_temporal": float(sig_t[i]), "temporal_frames": float(frames_t[i]),
                       "true_xi_wrong_gain": float(true_xi[i]), "xi_wrong_gain": float(xi_w[i]),
                       "alarm_wrong_gain": bool(alarm[i]),
                       "pair_noise_dn": noise[int(level[i])]} for i in range(len(rows))],
    }
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1))
    print(json.dumps({k: v for k, v in summary.items() if k != "per_frame"}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
