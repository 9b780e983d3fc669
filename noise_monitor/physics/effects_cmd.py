"""`noise-monitor effects`: list the registered noise effects and their parameters."""
from __future__ import annotations

import argparse
import json

from .effects import Effect, available, load_plugin_file


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--effect-plugin", action="append", default=[], metavar="FILE", help="load effects from FILE")
    parser.add_argument("--replace-builtin-effects", action="store_true",
                        help="let --effect-plugin effects replace built-in effects of the same name (else an error)")
    parser.add_argument("--json", metavar="PATH", help="also write the list as JSON")


def run(args: argparse.Namespace) -> int:
    for f in args.effect_plugin:
        load_plugin_file(f, override=args.replace_builtin_effects)
    listing = {}
    for name, cls in sorted(available().items()):
        kind = "temporal" if cls.temporal else "fixed-pattern"
        if cls.temporal_share is not Effect.temporal_share:
            kind = "temporal+fixed"
        shape = cls.structure + (", by position" if cls.spatial else "")
        print(f"{name:18s} {cls.distribution:12s} {kind:14s} {shape:18s} {cls.description}")
        for p in cls.params:
            fit = "fittable" if p.fittable else "fixed"
            print(f"    {p.name} [{p.unit}] default {p.default:g}, bounds {p.bounds[0]:g}..{p.bounds[1]:g}, {fit}")
        listing[name] = {
            "distribution": cls.distribution,
            "temporal": cls.temporal,
            "temporal_and_fixed": cls.temporal_share is not Effect.temporal_share,
            "structure": cls.structure,
            "spatial": cls.spatial,
            "description": cls.description,
            "params": {p.name: {"unit": p.unit, "default": p.default, "bounds": list(p.bounds), "fittable": p.fittable}
                       for p in cls.params},
        }
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(listing, fh, indent=2)
    return 0
