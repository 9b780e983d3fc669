"""`noise-monitor characterize BAG_OR_EMVA_SET --out DIR`: EMVA 1288 figures, report and profile from a recording
(a bag, or an EMVA 1288 image set: its descriptor file and images)."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from .characterize import DARK_TOLERANCE, characterize, datasheet_from_result, read_recording
from .emva import TOLERANCE, dark_current_e_per_s, profile_from_datasheet, round_trip
from .emva_images import EXPOSURE_UNITS, find_descriptor, read_image_set, write_flats_bag
from .profile_cmd import print_round_trip
from .report import plots, write_html


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", help="recording: a bag of flat fields over an exposure series with dark frames (lens "
                                    "cap) at the exposures, optionally at several temperatures (simulate-bag --scenario "
                                    "ptc); or an EMVA 1288 image set: its descriptor file (EMVA1288_Data.txt) or the "
                                    "folder holding it")
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder: report.html, PNG plots, "
                                                                    "characterize.json, profile.yaml")
    parser.add_argument("--json", metavar="PATH", help="also write the figures JSON here")
    parser.add_argument("--name", help="profile name (default: the bag's name)")
    parser.add_argument("--bit-depth", type=int, help="ADC bits of the images (default: metadata, else 8 for 8-bit "
                                                      "images and, in 16-bit words, the fewest bits holding the "
                                                      "largest code)")
    parser.add_argument("--sensor-type", choices=("ccd", "cmos"), help="for the profile when the metadata lacks it")
    parser.add_argument("--pixel-size-um", type=float, help="for the profile when the metadata lacks it")
    parser.add_argument("--dark-tolerance", type=float, default=DARK_TOLERANCE,
                        help=f"sets within this fraction of the range above the dark level (the line of the lower "
                             f"sets at the exposures recorded twice, else the darkest set) are dark "
                             f"(default {DARK_TOLERANCE})")
    parser.add_argument("--exposure-unit", choices=tuple(EXPOSURE_UNITS), default="ns",
                        help="EMVA image set: the unit of the descriptor's exposure times (default ns, the format's)")
    parser.add_argument("--temperature-c", type=float, help="EMVA image set: the sensor temperature during the "
                                                            "measurement (the format has none; needed for a profile)")
    parser.add_argument("--dark-bounds", action="store_true",
                        help="write the profile where the recording cannot determine the temporal dark noise (below "
                             "the ADC step: EMVA 1288's 0.49 DN bound, an upper bound) or the dark current (0); both "
                             "said in the profile")
    parser.add_argument("--flats-bag", metavar="BAG", help="EMVA image set: also write its flat fields as a bag with "
                                                        "the new profile's metadata, to replay through the monitor "
                                                        "(noise-monitor replay BAG --profile OUT/profile.yaml)")
    parser.add_argument("--image-topic", help="override the auto-detected image topic")
    parser.add_argument("--metadata-topic", help="override the auto-detected metadata topic")
    parser.add_argument("--temperature-topic", help="override the auto-detected Temperature topic")


def dark_current_rows(result: dict, profile) -> list[dict]:
    """The measured dark current at every temperature beside the profile's model."""
    rows = []
    for temp, v in result["figures"]["dark_current_e_per_s"].items():
        if temp == "unknown" or not v["value"]:
            continue
        got = dark_current_e_per_s(profile, float(temp))
        err = (got - v["value"]) / v["value"]
        rows.append({"field": f"measured dark_current_e_per_s@{temp}C", "datasheet": v["value"], "predicted": got,
                     "rel_error": float(err), "ok": bool(abs(err) <= TOLERANCE)})
    return rows


def run(args: argparse.Namespace) -> int:
    if args.bit_depth is not None and not 1 <= args.bit_depth <= 16:
        raise ValueError(f"--bit-depth must be in 1..16, got {args.bit_depth}")
    if not 0 < args.dark_tolerance < 1:
        raise ValueError(f"--dark-tolerance must be in (0, 1), got {args.dark_tolerance}")
    descriptor = find_descriptor(args.bag)
    if descriptor is not None:
        rec = read_image_set(descriptor, exposure_unit=args.exposure_unit, temperature_c=args.temperature_c)
        if args.bit_depth not in (None, rec.bit_depth):
            raise ValueError(f"--bit-depth {args.bit_depth}: the EMVA descriptor {descriptor} states {rec.bit_depth} bits")
    else:
        if args.temperature_c is not None or args.flats_bag:
            raise ValueError("--temperature-c and --flats-bag are for EMVA image sets (a bag's metadata gives the "
                             "temperature; a bag is replayed as it is)")
        rec = read_recording(args.bag, bit_depth=args.bit_depth, image_topic=args.image_topic,
                             metadata_topic=args.metadata_topic, temperature_topic=args.temperature_topic)
    result = characterize(rec, dark_tolerance=args.dark_tolerance)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    name = args.name or (descriptor.parent.name if descriptor else Path(args.bag.rstrip("/")).name.split(".")[0])
    ds, notes = datasheet_from_result(result, name, args.sensor_type, args.pixel_size_um, bounds=args.dark_bounds)
    result["notes"] += notes
    profile = rows = profile_file = None
    if ds is not None:
        made = profile_from_datasheet(ds)
        profile, rows = made.profile, round_trip(ds, made.profile) + dark_current_rows(result, made.profile)
        profile_file = out / "profile.yaml"
        profile_file.write_text(made.to_yaml(ds, source=f"the photon-transfer recording {args.bag} "
                                                        "(noise-monitor characterize)"))
        result["notes"] += made.notes
        result["profile"] = {"path": str(profile_file), "round_trip": rows}
    if args.flats_bag and descriptor is not None:
        if profile is None:
            raise ValueError("--flats-bag needs the profile, which was not written: " + "; ".join(notes))
        frames, left_out = write_flats_bag(descriptor, args.flats_bag, profile, args.exposure_unit,
                                           25.0 if args.temperature_c is None else args.temperature_c)
        result["notes"].append(f"flat fields as a bag: {args.flats_bag} ({frames} frames; noise-monitor replay "
                               f"{args.flats_bag} --profile {profile_file})")
        result["notes"] += [f"left out of the bag: {descriptor.name} line {line} ({reason})"
                            for line, reason in left_out.items()]
    files = plots(result, out, profile)
    report = write_html(result, out, files, args.bag, rows, str(profile_file) if profile_file else None)
    text = json.dumps(result, indent=2)
    (out / "characterize.json").write_text(text)
    if args.json:
        Path(args.json).write_text(text)
    f = result["figures"]
    print(f"{args.bag}: {result['conditions']['frames']} frames, {result['conditions']['flat_sets']} flat and "
          f"{result['conditions']['dark_sets']} dark sets")
    for key in ("system_gain_dn_per_e", "temporal_dark_noise_e", "read_noise_e", "saturation_capacity_e",
                "doubling_temperature_k", "dsnu_e", "dsnu_hpf_e", "prnu_pct", "prnu_hpf_pct", "linearity_error_pct", *(
                    ("quantum_efficiency", "responsivity_dn_per_p", "saturation_capacity_p", "sensitivity_threshold_p",
                     "dynamic_range_db") if f["quantum_efficiency"]["value"] is not None else ())):
        v = f[key]
        val = "not determined" if v["value"] is None else f"{v['value']:.5g}" + (
            f" +- {v['stderr']:.2g}" if v["stderr"] is not None else "")
        print(f"  {key:24s} {val} {v['unit']}")
    for temp, v in f["dark_current_e_per_s"].items():
        spread = f" +- {v['stderr']:.2g}" if v["stderr"] is not None else " (standard error unknown)"
        print(f"  dark current at {temp} degC: {v['value']:.4g}{spread} e-/s")
    for n in result["notes"]:
        print(f"  note: {n}")
    if rows:
        print(f"profile {profile_file}; its model predicts back the figures it was made from (the temporal dark "
              "noise at the DSNU's exposure, the dark-current law fitted over the temperatures: not the lines above) "
              "and the measured dark currents:")
        print_round_trip(rows, given="made from")
    print(f"report {report}")
    return 0
