"""`noise-monitor` command line: one sub-command per module, each with --help.

A command module defines ``HELP`` (one line), ``add_arguments(parser)`` and ``run(args) -> int``.
"""
from __future__ import annotations

import argparse
import importlib
import sys

COMMANDS: dict[str, str] = {
    "node": "noise_monitor.node",
    "replay": "noise_monitor.bag.replay_cmd",
    "play": "noise_monitor.bag.play_cmd",
    "simulate-bag": "noise_monitor.bag.simulate_cmd",
    "analyze": "noise_monitor.lab.analyze_cmd",
    "train": "noise_monitor.estimator.train_cmd",
    "evaluate": "noise_monitor.estimator.evaluate_cmd",
    "effects": "noise_monitor.physics.effects_cmd",
}


def _available() -> dict[str, object]:
    mods = {}
    for name, module in COMMANDS.items():
        try:
            mods[name] = importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if exc.name and module.startswith(exc.name):
                continue  # command not part of this build
            raise
    return mods


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="noise-monitor",
        description="Camera noise source estimation (PN, DCSN, RN, xi) for ROS 2 images and bags.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, mod in _available().items():
        p = sub.add_parser(name, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except KeyboardInterrupt:
        print("noise-monitor: interrupted", file=sys.stderr)
        return 130
    except (ValueError, FileNotFoundError, OSError) as exc:
        # user-facing errors (bad input, missing files): one line, non-zero exit
        print(f"noise-monitor {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
