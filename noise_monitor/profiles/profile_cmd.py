"""`noise-monitor profile from-emva DATASHEET --out PROFILE`: a camera profile from EMVA 1288 figures (a datasheet
YAML, or the reference implementation's results XML with the conditions it does not hold)."""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from .datasheet import Datasheet, DatasheetError, load_datasheet
from .emva import TOLERANCE, profile_from_datasheet, round_trip
from .emva_images import EXPOSURE_UNITS
from .emva_xml import datasheet_from_results

#: Options of a results XML (each the keyword of datasheet_from_results of its name) and whether it is required.
XML_OPTIONS = {"--sensor-type": True, "--bit-depth": True, "--pixel-size-um": True, "--temperature-c": True,
               "--dsnu-exposure-s": False, "--doubling-temperature-k": False, "--dark-offset-dn": False,
               "--exposure-unit": False, "--dark-current-e-per-s": False, "--name": False}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="profile_command", required=True, metavar="SUBCOMMAND")
    p = sub.add_parser("from-emva", help="profile from an EMVA 1288 datasheet YAML (format: "
                                         "config/datasheets/example_cmos_emva.yaml) or the emva1288 results XML",
                       description="Write a profile whose noise model reproduces the datasheet's figures and print "
                                   "the round trip (each figure predicted back from the profile).")
    p.add_argument("datasheet", help="datasheet YAML, or the results XML of the EMVA's reference implementation "
                                     "(emva1288: Emva1288(descriptor).xml())")
    p.add_argument("--out", required=True, metavar="PROFILE.yaml", help="profile to write")
    p.add_argument("--json", metavar="PATH", help="also write the mapping, notes and round trip as JSON")
    x = p.add_argument_group("a results XML (what it does not hold; required ones marked)")
    x.add_argument("--sensor-type", choices=("ccd", "cmos"), help="required")
    x.add_argument("--bit-depth", type=int, help="required: the ADC bits of the measurement's DN")
    x.add_argument("--pixel-size-um", type=float, help="required")
    x.add_argument("--temperature-c", type=float, help="required: the sensor temperature of the measurement")
    x.add_argument("--dsnu-exposure-s", type=float, help="the exposure of the dark spatial set (DSNU1288's); "
                                                          "without it the DSNU stays out of the profile")
    x.add_argument("--doubling-temperature-k", type=float, help="the dark current's doubling temperature")
    x.add_argument("--dark-offset-dn", type=float, help="mu_y.dark at zero exposure, the black level (native DN)")
    x.add_argument("--exposure-unit", choices=tuple(EXPOSURE_UNITS),
                   help="the unit of the descriptor's exposure times (the format's own and default: ns)")
    x.add_argument("--dark-current-e-per-s", type=float,
                   help="instead of the XML's u_I_mean where that is negative or missing (0: immeasurably small)")
    x.add_argument("--name", help="the profile's name (default: the XML's file name)")


def print_round_trip(rows: list[dict[str, Any]], given: str = "datasheet") -> None:
    """Table of the figures: given, predicted by the profile's model, relative error."""
    print(f"  {'figure':36s} {given:>12s} {'profile':>12s} {'error':>8s}")
    for r in rows:
        got = "n/a" if r["predicted"] is None else f"{r['predicted']:12.5g}"
        err = "n/a" if r["rel_error"] is None else f"{100 * r['rel_error']:+7.2f}%"
        flag = "" if r["ok"] else f"  (outside {TOLERANCE:.0%})"
        print(f"  {r['field']:36s} {r['datasheet']:12.5g} {got:>12s} {err:>8s}{flag}")


def _datasheet(args: argparse.Namespace) -> tuple[Datasheet, list[str]]:
    """The datasheet of a YAML or a results XML, and the XML's notes."""
    given = {flag: getattr(args, flag[2:].replace("-", "_")) for flag in XML_OPTIONS}
    if Path(args.datasheet).suffix.lower() != ".xml":
        named = [flag for flag, value in given.items() if value is not None]
        if named:
            raise DatasheetError(f"{', '.join(named)}: for a results XML only (a datasheet YAML states its figures)")
        return load_datasheet(args.datasheet), []
    missing = [flag for flag, required in XML_OPTIONS.items() if required and given[flag] is None]
    if missing:
        raise DatasheetError(f"{args.datasheet}: a results XML does not hold the measurement's conditions: give "
                             f"{', '.join(missing)}")
    return datasheet_from_results(args.datasheet, **{flag[2:].replace("-", "_"): value
                                                     for flag, value in given.items() if value is not None})


def run(args: argparse.Namespace) -> int:
    ds, xml_notes = _datasheet(args)
    result = profile_from_datasheet(ds)
    rows = round_trip(ds, result.profile)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(result.to_yaml(ds))
    print(f"wrote {out} (profile {result.profile.name!r}); round trip of the datasheet's figures:")
    print_round_trip(rows)
    for n in xml_notes + result.notes:
        print(f"  note: {n}")
    if args.json:
        Path(args.json).write_text(json.dumps({"datasheet": ds.as_dict(), "profile": str(out),
                                               "derived": result.derived, "notes": xml_notes + result.notes,
                                               "round_trip": rows}, indent=2))
    return 0
