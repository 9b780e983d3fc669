"""Cross-check `noise-monitor characterize` against the emva1288 reference implementation (PyPI `emva1288`).

emva1288 is not a dependency: install it in its own environment and point --emva-python at it::

    python -m venv /tmp/emva && /tmp/emva/bin/pip install "numpy<2" emva1288==1.0.2
    .venv/bin/python -m noise_monitor.cli simulate-bag out/ptc.mcap --profile PROFILE --scenario ptc --frames 200
    .venv/bin/python bench/emva1288_crosscheck.py out/ptc.mcap --emva-python /tmp/emva/bin/python
    .venv/bin/python bench/emva1288_crosscheck.py DATASET/EMVA1288_Data.txt    # an EMVA 1288 image set

A bag's sets (native integer codes) go to an .npz; the other interpreter runs emva1288's Data1288 and
Results1288 on them (temporal: one dark and one bright pair per exposure at the base temperature;
spatial: the largest bright set and the dark set of its exposure). Photon counts are then proportional to the
exposure (constant irradiance, arbitrary scale): figures in electrons do not depend on that scale, those in
photons do (not compared). An EMVA image set (its descriptor file) is read by each implementation itself, and its
photon counts make the figures in photons comparable. Printed: emva1288, characterize and, for a simulated bag,
the simulator's truth side by side.
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
          ("LE", "linearity_error_pct", "linearity_error_pct"))
#: compared on EMVA image sets only (calibrated photon counts)
PHOTON_FIELDS = (("QE", "quantum_efficiency", None), ("R", "responsivity_dn_per_p", None),
                 ("u_p_sat", "saturation_capacity_p", None), ("u_p_min", "sensitivity_threshold_p", None))


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
    print(json.dumps(_results(Results1288(data.data, loglevel=logging.ERROR))))


def process_descriptor(path: str) -> None:
    """Runs in the emva1288 environment: its own parser and loader on an EMVA image set; results as JSON."""
    import logging

    from emva1288 import process as emva

    parser = emva.ParseEmvaDescriptorFile(path, loglevel=logging.ERROR)
    data = emva.Data1288(emva.LoadImageData(parser.images, loglevel=logging.ERROR).data, loglevel=logging.ERROR)
    print(json.dumps(_results(emva.Results1288(data.data, loglevel=logging.ERROR))))


def _results(res) -> dict:
    out = {}
    for name, _, _ in FIELDS + PHOTON_FIELDS:
        try:  # LE: the larger deviation of the two, as characterize reports it
            out[name] = float(max(res.LE_min, res.LE_max, key=abs) if name == "LE" else getattr(res, name))
        except Exception as exc:  # report what the reference implementation cannot compute
            out[name] = f"error: {type(exc).__name__}: {exc}"
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("bag", nargs="?", help="a bag, or an EMVA 1288 image set (descriptor file or its folder)")
    p.add_argument("--exposure-unit", default="ns", help="an EMVA image set's exposure unit (default ns)")
    p.add_argument("--emva-python", default="/tmp/emva/bin/python", help="interpreter with emva1288 installed")
    p.add_argument("--process", metavar="NPZ", help=argparse.SUPPRESS)
    p.add_argument("--process-descriptor", metavar="FILE", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.process:
        process(args.process)
        return 0
    if args.process_descriptor:
        process_descriptor(args.process_descriptor)
        return 0
    from noise_monitor.profiles.characterize import characterize
    from noise_monitor.profiles.emva_images import find_descriptor, read_image_set

    descriptor = find_descriptor(args.bag)
    fields = FIELDS + (PHOTON_FIELDS if descriptor else ())
    with tempfile.TemporaryDirectory() as tmp:
        if descriptor:
            ours = characterize(read_image_set(descriptor, exposure_unit=args.exposure_unit))
            call = ["--process-descriptor", str(descriptor)]
        else:
            npz = Path(tmp) / "sets.npz"
            ours = export(args.bag, npz)
            call = ["--process", str(npz)]
        run = subprocess.run([args.emva_python, __file__, *call], capture_output=True, text=True)
        if run.returncode != 0:
            print(run.stderr, file=sys.stderr)
            return 1
        ref = json.loads(run.stdout.strip().splitlines()[-1])
    truth_file = Path(args.bag + ".truth.json")
    truth = json.loads(truth_file.read_text())["emva"] if truth_file.is_file() else {}
    temp = ours["conditions"]["temperature_c"]
    temp = "unknown" if temp is None else f"{temp:g}"
    print(f"{'figure':24s} {'emva1288':>12s} {'characterize':>14s} {'difference':>11s} {'truth':>12s}")
    for ref_name, our_name, truth_name in fields:
        mine = ours["figures"][our_name]
        mine = mine.get(temp, {}).get("value") if our_name == "dark_current_e_per_s" else mine["value"]
        t = truth.get(truth_name) if truth_name else None
        t = t[temp] if isinstance(t, dict) else t
        r = ref[ref_name]
        diff = f"{100 * (mine - r) / abs(r):+10.2f}%" if isinstance(r, float) and mine is not None and r else ""
        r = f"{r:12.5g}" if isinstance(r, float) else r
        m = "not determined" if mine is None else f"{mine:14.5g}"
        print(f"{our_name:24s} {r:>12s} {m:>14s} {diff:>11s} {'' if t is None else f'{t:12.5g}'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
