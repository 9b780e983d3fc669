"""Cross-check `noise-monitor characterize` against the emva1288 reference implementation (PyPI `emva1288`).

emva1288 is not a dependency: install it in its own environment and point --emva-python at it::

    python -m venv /tmp/emva && /tmp/emva/bin/pip install emva1288==1.0.2
    .venv/bin/python -m noise_monitor.cli simulate-bag out/ptc.mcap --profile PROFILE --scenario ptc --frames 200
    .venv/bin/python bench/emva1288_crosscheck.py out/ptc.mcap --emva-python /tmp/emva/bin/python

The bag's sets (native integer codes) go to an .npz; the other interpreter runs emva1288's Data1288 and
Results1288 on them (temporal: one dark and one bright pair per exposure at the base temperature;
spatial: the largest bright set and the dark set of its exposure). Printed: emva1288, characterize and
the simulator's truth side by side. Photon counts are proportional to the exposure (constant
irradiance, arbitrary scale): figures in electrons do not depend on that scale, QE does (not compared).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

FIELDS = (("K", "system_gain_dn_per_e", "system_gain_dn_per_e"),
          ("sigma_d", "temporal_dark_noise_e", "temporal_dark_noise_e"),
          ("u_e_sat", "saturation_capacity_e", "saturation_capacity_e"),
          ("DSNU1288", "dsnu_e", "dsnu_e"),
          ("PRNU1288", "prnu_pct", "prnu_pct"),
          ("u_I_mean", "dark_current_e_per_s", "dark_current_e_per_s"),
          ("LE_max", "linearity_error_pct", "linearity_error_pct"))


def export(bag: str, npz: Path) -> dict:
    """Native-code images of the recording's sets at the base temperature; the characterize result."""
    import noise_monitor.profiles.characterize as ch
    from noise_monitor.profiles.characterize import characterize, read_recording

    images: dict[int, list[np.ndarray]] = {}
    orig = ch.FrameSet.compute

    def capture(self):  # keep the pixels of every set (8-bit scale) before compute() frees them
        images[id(self)] = list(self.images)
        orig(self)

    ch.FrameSet.compute = capture
    try:
        rec = read_recording(bag)
    finally:
        ch.FrameSet.compute = orig
    result = characterize(rec)
    temp = result["conditions"]["temperature_c"]
    scale = (2**rec.bit_depth - 1) / 255.0
    sets = [s for s in rec.sets if s.temperature_c == temp and s.gain_db == result["conditions"]["gain_db"]]
    keep = {f"{s.kind}_{s.exposure_time_s!r}_{s.size}": np.rint(np.stack(images[id(s)]) * scale).astype(np.int64)
            for s in sets}
    np.savez_compressed(npz, **keep)
    return result


def process(npz: str) -> None:
    """Runs in the emva1288 environment: print its results as JSON."""
    import logging

    from emva1288.process.data import Data1288
    from emva1288.process.results import Results1288
    from emva1288.process.routines import get_int_imgs

    arrays = np.load(npz)
    sets = []
    for key in arrays.files:
        kind, t, n = key.split("_")
        sets.append((kind, float(t), int(n), arrays[key]))
    flats = [s for s in sets if s[0] == "flat"]
    t_max = max(s[1] for s in flats)
    spatial_bright = max(flats, key=lambda s: s[2])
    temporal: dict = {}
    for kind, t, _, imgs in sets:
        texp = t * 1e9  # emva1288 works in ns
        photons = 0.0 if kind == "dark" else 1000.0 * t / t_max  # proportional to exposure (arbitrary scale)
        d = get_int_imgs(list(imgs[:2]))
        temporal.setdefault(texp, {})[photons] = {"sum": np.sum(d["sum"]), "pvar": np.sum(d["pvar"]),
                                                  "dmean": d["dmean"]}
    temporal = {t: v for t, v in temporal.items() if 0.0 in v and len(v) > 1}
    t_sp = spatial_bright[1]
    dark_sp = [s for s in sets if s[0] == "dark" and s[1] == t_sp]
    if not dark_sp:
        raise SystemExit("no dark set at the spatial set's exposure")
    spatial = {t_sp * 1e9: {0.0: get_int_imgs(list(max(dark_sp, key=lambda s: s[2])[3])),
                            1000.0 * t_sp / t_max: get_int_imgs(list(spatial_bright[3]))}}
    h, w = spatial_bright[3].shape[1:]
    data = Data1288({"temporal": temporal, "spatial": spatial, "width": w, "height": h}, loglevel=logging.ERROR)
    res = Results1288(data.data, loglevel=logging.ERROR)
    out = {}
    for name, _, _ in FIELDS:
        try:
            out[name] = float(getattr(res, name))
        except Exception as exc:  # report what the reference implementation cannot compute
            out[name] = f"error: {type(exc).__name__}: {exc}"
    print(json.dumps(out))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("bag", nargs="?")
    p.add_argument("--emva-python", default="/tmp/emva/bin/python", help="interpreter with emva1288 installed")
    p.add_argument("--process", metavar="NPZ", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.process:
        process(args.process)
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        npz = Path(tmp) / "sets.npz"
        ours = export(args.bag, npz)
        run = subprocess.run([args.emva_python, __file__, "--process", str(npz)], capture_output=True, text=True)
        if run.returncode != 0:
            print(run.stderr, file=sys.stderr)
            return 1
        ref = json.loads(run.stdout.strip().splitlines()[-1])
    truth_file = Path(args.bag + ".truth.json")
    truth = json.loads(truth_file.read_text())["emva"] if truth_file.is_file() else {}
    temp = f"{ours['conditions']['temperature_c']:g}"
    print(f"{'figure':24s} {'emva1288':>12s} {'characterize':>14s} {'truth':>12s}")
    for ref_name, our_name, truth_name in FIELDS:
        mine = ours["figures"][our_name]
        mine = mine[temp]["value"] if our_name == "dark_current_e_per_s" else mine["value"]
        t = truth.get(truth_name)
        t = t[temp] if isinstance(t, dict) else t
        r = ref[ref_name]
        r = f"{r:12.5g}" if isinstance(r, float) else r
        print(f"{our_name:24s} {r:>12s} {mine:14.5g} {'' if t is None else f'{t:12.5g}'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
