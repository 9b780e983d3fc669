"""`noise-monitor profile from-emva DATASHEET --out PROFILE`: a camera profile from EMVA 1288 figures."""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from .datasheet import load_datasheet
from .emva import TOLERANCE, profile_from_datasheet, round_trip


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="profile_command", required=True, metavar="SUBCOMMAND")
    p = sub.add_parser("from-emva", help="profile from an EMVA 1288 datasheet YAML (format: "
                                         "config/datasheets/example_cmos_emva.yaml)",
                       description="Write a profile whose noise model reproduces the datasheet's figures and print "
                                   "the round trip (each figure predicted back from the profile).")
    p.add_argument("datasheet", help="datasheet YAML")
    p.add_argument("--out", required=True, metavar="PROFILE.yaml", help="profile to write")
    p.add_argument("--json", metavar="PATH", help="also write the mapping, notes and round trip as JSON")


def print_round_trip(rows: list[dict[str, Any]], given: str = "datasheet") -> None:
    """Table of the figures: given, predicted by the profile's model, relative error."""
    print(f"  {'figure':36s} {given:>12s} {'profile':>12s} {'error':>8s}")
    for r in rows:
        got = "n/a" if r["predicted"] is None else f"{r['predicted']:12.5g}"
        err = "n/a" if r["rel_error"] is None else f"{100 * r['rel_error']:+7.2f}%"
        flag = "" if r["ok"] else f"  (outside {TOLERANCE:.0%})"
        print(f"  {r['field']:36s} {r['datasheet']:12.5g} {got:>12s} {err:>8s}{flag}")


def run(args: argparse.Namespace) -> int:
    ds = load_datasheet(args.datasheet)
    result = profile_from_datasheet(ds)
    rows = round_trip(ds, result.profile)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(result.to_yaml(ds))
    print(f"wrote {out} (profile {result.profile.name!r}); round trip of the datasheet's figures:")
    print_round_trip(rows)
    for n in result.notes:
        print(f"  note: {n}")
    if args.json:
        Path(args.json).write_text(json.dumps({"datasheet": ds.as_dict(), "profile": str(out),
                                               "derived": result.derived, "notes": result.notes,
                                               "round_trip": rows}, indent=2))
    return 0
