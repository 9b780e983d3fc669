"""`noise-monitor simulate-bag`: write a synthetic field campaign bag with a ground-truth sidecar."""
from __future__ import annotations

import argparse
import json
from datetime import UTC, datetime
from pathlib import Path

from noise_monitor.estimator.user_images import load_image_set
from noise_monitor.physics import load_plugin_file

from .campaign import MIN_PHOTO_SIDE, PHOTO_SHARE
from .scenarios import SCENARIOS
from .simulate import (
    LAMP_MEAN_FRAMES,
    LINE_TIME_S,
    MAINS_HZ,
    PWM_DUTY,
    START_NS,
    FieldConditions,
    load_truth,
    simulate_bag,
    truth_path,
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("out", help="output bag: NAME.mcap (one MCAP file) or a folder name (rosbag2 directory)")
    parser.add_argument("--profile", required=True,
                        help="camera profile YAML or bundled name (icx285, ev76c661, generic)")
    parser.add_argument("--scenario", required=True, choices=sorted(SCENARIOS), metavar="NAME",
                        help="; ".join(f"{k}: {v.description}" for k, v in SCENARIOS.items()).replace("%", "%%"))
    parser.add_argument("--effect", action="append", default=[], metavar="NAME=VALUE",
                        help="switch on a registered effect (repeatable): NAME, NAME=VALUE or NAME:param=v,param=v; "
                             "a fixed pattern (PRNU, DSNU, line offsets, hot pixels) is drawn from its seed parameter, "
                             "0 unless given (NAME:param=v,seed=S): bags differing only in --seed share one sensor")
    parser.add_argument("--effect-plugin", action="append", default=[], metavar="FILE", help="load effects from FILE")
    parser.add_argument("--replace-builtin-effects", action="store_true",
                        help="let --effect-plugin effects replace built-in effects of the same name (else an error)")
    parser.add_argument("--frames", type=int, default=60, help="number of images (default 60)")
    parser.add_argument("--width", type=int, default=320, help="image width in pixels (default 320)")
    parser.add_argument("--height", type=int, default=256, help="image height in pixels (default 256)")
    parser.add_argument("--fps", type=float, default=5.0, help="frame rate of the stamps (Hz)")
    parser.add_argument("--hold", type=float, default=1.0, metavar="SECONDS",
                        help="metadata (gain, exposure, temperature) update period; 0 = every frame (the campaign "
                             "and ptc scenarios follow their own plans)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (scene, noise); same seed, same bag")
    parser.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap")
    parser.add_argument("--namespace", default="/camera", help="topic namespace (default /camera)")
    parser.add_argument("--hardware-id", help="camera id in the metadata messages (default: the profile name)")
    parser.add_argument("--start", metavar="UTC", help="first frame's time, ISO 8601 (default 2023-11-14T22:13:20Z)")
    parser.add_argument("--json", metavar="PATH", help="write a summary JSON (bag, truth file, episodes)")
    parser.add_argument("--images", nargs="+", type=Path, default=None, metavar="PATH",
                        help="campaign scenarios: photo panels from your own clean scenes (files or directories of "
                             "PNG / JPEG / TIFF / BMP / PGM / NPY images) instead of the bundled photographs")
    parser.add_argument("--image-downsample", type=int, default=2,
                        help="area-downsample --images by this factor first (1-4; default 2)")
    add_photo_share_argument(parser)
    parser.add_argument("--moving-objects", type=int, default=0, metavar="N",
                        help="campaign scenarios: N objects with a smooth texture crossing the view at 2-8 px per "
                             "frame (people, vehicles passing a parked camera; default 0)")
    add_field_arguments(parser)


def add_photo_share_argument(parser: argparse.ArgumentParser) -> None:
    """``--photo-share``: the share of a campaign world's panels that are photographs (``simulate_bag``'s ``photo_share``)."""
    parser.add_argument("--photo-share", type=float, default=PHOTO_SHARE, metavar="F",
                        help=f"campaign scenarios: the share of the world's panels that are photographs (--images or "
                             f"the bundled ones), the others procedural textures (0-1; default {PHOTO_SHARE:g}; 1: "
                             f"the scenes alone, besides a few small flat chart patches)")


def add_field_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the recording's field conditions (``simulate_bag`` keywords, :func:`field_keywords`)."""
    parser.add_argument("--vibration", type=float, default=0.0, metavar="PX",
                        help="campaign scenarios: the camera vibrates, its view displaced every frame by PX rms per "
                             "axis, independently (a parked robot with its motors running; default 0)")
    parser.add_argument("--vibration-hz", type=float, default=0.0, metavar="HZ",
                        help="with --vibration: the camera vibrates sinusoidally at HZ during each exposure, so "
                             "exposures of about half a period or more smear the view (motion blur changing from "
                             "frame to frame; default 0: each frame frozen at one displacement)")
    parser.add_argument("--wobble", action="store_true",
                        help="with --vibration-hz: a rolling shutter (--line-us per row) reads the vibrating view row "
                             "by row, each row displaced along its own stretch of the path (rolling-shutter wobble)")
    parser.add_argument("--flicker", type=float, default=0.0, metavar="PCT",
                        help="lights that flicker: the scene's brightness scaled every frame by 1 + PCT %% rms, "
                             "independently (default 0)")
    parser.add_argument("--banding", type=float, default=0.0, metavar="PCT",
                        help="lamps on the mains whose light is modulated by PCT %% (0-100), seen through a rolling "
                             "shutter: horizontal bands, deeper at short exposures, rolling from frame to frame "
                             "(default 0)")
    parser.add_argument("--mains-hz", type=float, default=None,
                        help=f"mains frequency of --banding (default {MAINS_HZ:g})")
    parser.add_argument("--line-us", type=float, default=None,
                        help=f"rolling shutter line time of --banding and --wobble in microseconds (default "
                             f"{LINE_TIME_S * 1e6:g})")
    parser.add_argument("--pwm-hz", type=float, default=None,
                        help="with --banding: the lamps are LEDs dimmed by pulse-width modulation at this frequency "
                             "instead of lamps on the mains (square-wave light: sharp-edged bands at short exposures)")
    parser.add_argument("--pwm-duty", type=float, default=None,
                        help=f"fraction of each --pwm-hz period the LEDs are on (default {PWM_DUTY:g})")
    parser.add_argument("--auto-exposure", type=float, default=0.0, metavar="PCT",
                        help="a live driver's auto-exposure hunting under steady light: every frame's exposure, and "
                             "the image's brightness with it, wanders about the scenario's by PCT %% rms (correlated "
                             "from frame to frame; reported in the metadata; default 0)")
    parser.add_argument("--lamp", type=float, default=0.0, metavar="PCT",
                        help="a lamp adding PCT %% to the scene's light, switched on and off at random frames (every "
                             f"{LAMP_MEAN_FRAMES} frames on average): the light steps while the camera may hold still "
                             "(default 0)")


def field_keywords(args: argparse.Namespace) -> FieldConditions:
    """The ``simulate_bag`` keywords of :func:`add_field_arguments`' options (ValueError: options of the banding
    without it)."""
    if not args.banding and (args.mains_hz is not None or args.pwm_hz is not None or args.pwm_duty is not None):
        raise ValueError("--mains-hz, --pwm-hz and --pwm-duty shape the lamps' bands: give --banding PCT too")
    if args.line_us is not None and not (args.banding or args.wobble):
        raise ValueError("--line-us is the rolling shutter's line time of --banding or --wobble: give one of them too")
    if args.wobble and not args.vibration_hz:
        raise ValueError("--wobble reads a vibration at a frequency row by row: give --vibration PX --vibration-hz HZ")
    if args.pwm_hz is not None and args.mains_hz is not None:
        raise ValueError("--pwm-hz dims LEDs instead of lamps on the mains: give one of --pwm-hz and --mains-hz")
    if args.pwm_hz is not None and not args.pwm_hz > 0:  # 0 simulated lamps on the mains without a word
        raise ValueError(f"--pwm-hz must be > 0 Hz, got {args.pwm_hz:g}")
    if args.pwm_duty is not None and args.pwm_hz is None:
        raise ValueError("--pwm-duty is the duty cycle of --pwm-hz: give --pwm-hz HZ too")
    if args.vibration_hz and not args.vibration:
        raise ValueError("--vibration-hz is the frequency of a vibration: give --vibration PX too")
    mains_hz = MAINS_HZ if args.mains_hz is None else args.mains_hz
    line_time_s = LINE_TIME_S if args.line_us is None else args.line_us * 1e-6
    return {"vibration_px": args.vibration, "vibration_hz": args.vibration_hz, "flicker_pct": args.flicker,
            "banding_pct": args.banding, "mains_hz": mains_hz, "line_time_s": line_time_s,
            "pwm_hz": args.pwm_hz or 0.0, "pwm_duty": PWM_DUTY if args.pwm_duty is None else args.pwm_duty,
            "auto_exposure_pct": args.auto_exposure, "wobble": args.wobble, "lamp_pct": args.lamp}


def _start_ns(text: str | None) -> int:
    """ISO 8601 time (UTC unless it names a zone) -> ns since the epoch."""
    if text is None:
        return START_NS
    try:
        t = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise ValueError(f"--start must be an ISO 8601 time like 2026-05-01T08:00:00Z, got {text!r}") from None
    if t.tzinfo is None:
        t = t.replace(tzinfo=UTC)
    return int(round(t.timestamp() * 1e9))


def run(args: argparse.Namespace) -> int:
    for f in args.effect_plugin:
        load_plugin_file(f, override=args.replace_builtin_effects)
    images = load_image_set(args.images, args.image_downsample, MIN_PHOTO_SIDE) if args.images else None
    bag = simulate_bag(args.out, args.profile, args.scenario, effects=args.effect, frames=args.frames,
                       width=args.width, height=args.height, seed=args.seed, storage=args.storage, fps=args.fps,
                       namespace=args.namespace, hold_s=args.hold, progress=True, hardware_id=args.hardware_id,
                       start_ns=_start_ns(args.start), images=images, photo_share=args.photo_share,
                       moving_objects=args.moving_objects,
                       **field_keywords(args))
    truth = load_truth(bag)
    summary = {"bag": str(bag), "truth": str(truth_path(bag)), "frames": len(truth["frames"]),
               "profile": truth["profile"], "scenario": truth["scenario"], "effects": truth["effects"],
               "episodes": truth["episodes"], **({"images": truth["images"]} if "images" in truth else {})}
    print(f"wrote {bag} ({summary['frames']} frames, {truth['profile']}, scenario {truth['scenario']}) "
          f"and {summary['truth']}")
    if summary["frames"] != args.frames:
        print(f"  {summary['frames']} of the {args.frames} frames asked for: the {truth['scenario']} scenario records "
              "whole sets of frames (the rest would make a partial one)")
    for ep in truth["episodes"]:
        print(f"  episode frames {ep['start_index']}-{ep['end_index']}: {'; '.join(ep['corrupted'])} "
              f"(true xi {ep['mean_xi']:+.2f} DN)")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(summary, fh, indent=2)
    return 0
