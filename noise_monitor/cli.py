"""`noise-monitor` command line: one sub-command per module, each with --help.

A command module defines ``add_arguments(parser)`` and ``run(args) -> int``; its one-line help lives in
:data:`COMMANDS`. Only the module of the command being run is imported (``noise-monitor --help`` imports
none), so start-up costs what the command needs and nothing more.
"""
from __future__ import annotations

import argparse
import importlib
import os
import pickle
import signal
import stat
import sys
import threading
from types import ModuleType

from .text import clip

#: command -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "node": ("noise_monitor.node",
             "run the live ROS 2 noise monitor node (image + metadata in, /diagnostics and sigma/xi topics out)"),
    "replay": ("noise_monitor.bag.replay_cmd",
               "replay a bag through the monitor pipeline (as the node would run it) and summarise noise and alarms"),
    "campaign": ("noise_monitor.fleet.campaign_cmd",
                 "replay many bags on Ray or a local process pool, resumable; Parquet, campaign.json, HTML report"),
    "play": ("noise_monitor.bag.play_cmd",
             "publish a bag into live ROS 2 topics (original timing, --rate factor, --loop); no ROS install needed"),
    "simulate-bag": ("noise_monitor.bag.simulate_cmd",
                     "simulate a camera over a scenario and write a rosbag2 bag (MCAP/sqlite3) plus <out>.truth.json"),
    "analyze": ("noise_monitor.lab.analyze_cmd",
                "compare the noise model with the noise measured in a bag, diagnose missing effects, add them, report"),
    "train": ("noise_monitor.estimator.train_cmd",
              "train an estimator variant (full_meta, drne, wo_meta, min_meta, full_meta_paper) on simulated data"),
    "evaluate": ("noise_monitor.estimator.evaluate_cmd",
                 "evaluate estimators on the held-out benchmark (parts a/b/c, peers, metadata sensitivity sweep)"),
    "scenes": ("noise_monitor.bag.scenes_cmd",
               "clean images of the scenes a recording saw: the temporal mean of each static hold, one PNG each "
               "(for evaluate --images)"),
    "evaluate-stream": ("noise_monitor.bag.evaluate_stream_cmd",
                        "the monitor per frame on field-like campaigns of your own scenes (--images), clean and with the "
                        "gain stated wrong: xi error, false alarms, detection"),
    "effects": ("noise_monitor.physics.effects_cmd",
                "list the noise effects (built-in and plug-ins) with their parameters"),
    "profile": ("noise_monitor.profiles.profile_cmd",
                "make camera profiles: from-emva turns an EMVA 1288 datasheet (YAML) or the EMVA reference "
                "implementation's results XML into a profile for the node"),
    "characterize": ("noise_monitor.profiles.characterize_cmd",
                     "characterize a camera from a photon-transfer recording (EMVA 1288): K, dark noise, saturation, "
                     "dark current, DSNU, PRNU, linearity; HTML report, JSON and a profile for the node"),
}
#: Python packages whose absence means an optional part of the installation is missing.
OPTIONAL = {"rclpy": "ROS 2 Jazzy's rclpy (pip install \"ros-jazzy-rclpy[fastrtps]\" ros-jazzy-common-interfaces)"}


def _command_module(name: str) -> ModuleType:
    """Import the module of one command; a missing optional dependency is a one-line error."""
    module = COMMANDS[name][0]
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        root = (exc.name or "").split(".")[0]
        if root in ("noise_monitor", "msg_adapters", ""):
            raise
        need = OPTIONAL.get(root, f"the Python package {root!r}")
        print(f"noise-monitor {name}: error: this command needs {need}, which is not installed", file=sys.stderr)
        raise SystemExit(2) from None


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser; only ``command``'s module is imported to add its arguments."""
    parser = argparse.ArgumentParser(
        prog="noise-monitor",
        description="Camera noise source estimation (PN, DCSN, RN, xi) for ROS 2 images and bags.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (_, text) in COMMANDS.items():
        p = sub.add_parser(name, help=text, description=text)
        if name == command:
            mod = _command_module(name)
            mod.add_arguments(p)
            p.set_defaults(_run=mod.run)
    return parser


class Terminated(BaseException):
    """SIGTERM: unwinds the command like Ctrl-C does, so that its temporary files are removed."""


def _terminate(signum: int, frame: object) -> None:
    raise Terminated()


#: Errors that mean unusable input or settings (plus running out of memory on it): exit 2 with one line.
#: ValueError covers the package's own errors (BagError, MetadataError, EffectError, YamlError, ...);
#: pickle.UnpicklingError is what torch raises for a damaged or unsafe weights file.
USER_ERRORS: tuple[type[BaseException], ...] = (ValueError, OSError, MemoryError, OverflowError,
                                                 pickle.UnpicklingError)


def error_line(exc: BaseException) -> str:
    """An exception as one bounded line (messages of YAML, torch or numpy errors span several lines)."""
    if isinstance(exc, MemoryError):
        detail = " ".join(str(exc).split())
        return "out of memory" + (f" ({clip(detail, 200)})" if detail else "") + "; the input is too large"
    text = " ".join(str(exc).split()) or type(exc).__name__
    return clip(text)


def _stdout_is_pipe() -> bool:
    """Whether standard output is a pipe or socket (where a BrokenPipeError means its reader has gone)."""
    try:
        mode = os.fstat(sys.stdout.fileno()).st_mode
    except (OSError, ValueError):  # no file descriptor (captured output)
        return False
    return stat.S_ISFIFO(mode) or stat.S_ISSOCK(mode)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    command = next((a for a in argv if not a.startswith("-")), None)
    args = build_parser(command if command in COMMANDS else None).parse_args(argv)
    in_main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _terminate) if in_main else None
    try:
        return int(args._run(args) or 0)
    except KeyboardInterrupt:
        print("noise-monitor: interrupted", file=sys.stderr)
        return 130
    except Terminated:
        print("noise-monitor: terminated", file=sys.stderr)
        return 128 + signal.SIGTERM
    except BrokenPipeError as exc:
        if not _stdout_is_pipe():
            print(f"noise-monitor {args.command}: error: {error_line(exc)}", file=sys.stderr)
            return 2
        # the reader of our output left (`noise-monitor effects | head`): stop quietly, as a shell's tools do
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 128 + signal.SIGPIPE
    except USER_ERRORS as exc:
        # user-facing errors (bad input, missing files): one line, non-zero exit
        print(f"noise-monitor {args.command}: error: {error_line(exc)}", file=sys.stderr)
        return 2
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
