"""`noise-monitor evaluate-stream`: the monitor per frame on field-like campaigns of your own scenes, clean and with
the gain stated wrong (issue 15's per-frame targets; see :mod:`.stream_eval`)."""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from noise_monitor.estimator.user_images import load_image_set

from .campaign import MIN_PHOTO_SIDE, PHOTO_SHARE
from .scenarios import SCENARIOS
from .simulate_cmd import add_field_arguments, add_photo_share_argument, field_keywords
from .stream_eval import (
    GAIN_OFFSET_DB,
    NOT_DUE_XI,
    TARGET_CLEAN_XI_DN,
    TARGET_DETECTION,
    WITHIN,
    evaluate_stream,
)

CAMPAIGNS = sorted(name for name, s in SCENARIOS.items() if s.campaign)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--images", nargs="+", type=Path, default=None, metavar="PATH",
                   help="your own clean scenes for the campaigns' photo panels (files or directories of PNG / JPEG / "
                        "TIFF / BMP / PGM / NPY images; default: the scenario's bundled photographs)")
    p.add_argument("--image-downsample", type=int, default=2, help="area-downsample --images first (1-4; default 2)")
    add_photo_share_argument(p)
    p.add_argument("--profile", default="ev76c661", help="camera profile (name or YAML; default ev76c661)")
    p.add_argument("--scenario", default="campaign_heldout", choices=CAMPAIGNS)
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2], help="one campaign per seed (default 1 2)")
    p.add_argument("--frames", type=int, default=100)
    p.add_argument("--width", type=int, default=320)
    p.add_argument("--height", type=int, default=256)
    p.add_argument("--fps", type=float, default=10.0)
    p.add_argument("--gain-offset-db", type=float, default=GAIN_OFFSET_DB,
                   help="what the wrong metadata states beyond the true gain (dB; default -6)")
    p.add_argument("--params", type=Path, default=None, help="node parameters YAML (default: the shipped ones)")
    p.add_argument("--threads", type=int, default=1)
    add_field_arguments(p)
    p.add_argument("--keep-bags", type=Path, default=None, metavar="DIR", help="write the bags here and keep them")
    p.add_argument("--json", type=Path, default=None, help="write the per-bag figures and the summary here")


def run(args: argparse.Namespace) -> int:
    if args.threads < 1:
        raise ValueError(f"--threads must be >= 1, got {args.threads}")
    images = load_image_set(args.images, args.image_downsample, MIN_PHOTO_SIDE) if args.images else None
    result = evaluate_stream(args.profile, args.seeds, images, args.scenario, args.frames, args.width, args.height,
                             args.fps, args.gain_offset_db, args.params, args.threads, args.keep_bags,
                             field_keywords(args), args.photo_share)
    for r in result["bags"]:
        print(f"seed {r['seed']}: {r['processed_clean']} / {r['frames']} frames processed clean, {r['processed_offset']} "
              f"with the gain stated {args.gain_offset_db:+g} dB; {r['views']} views; false-alarm episodes "
              f"{r['false_alarm_episodes']}; detected {r['hits']} / {r['need']}")
    s = result["summary"]
    det = ("no frame was due an alarm" if not s["need"] else f"{100 * s['detection']:.1f} % ({s['hits']} / {s['need']}; "
           f"95 % lower bound {100 * s['detection_lower_95']:.0f} %)")
    offset_err = (f"{s['offset_xi_error_rms']:.3f} DN" if math.isfinite(s["offset_xi_error_rms"]) else
                  f"none: no frame processed with the gain stated {args.gain_offset_db:+g} dB (the monitor skips a stated "
                  f"gain outside the profile's range as invalid metadata)")
    scenes = ", ".join(images.names) if images else f"the {args.scenario} scenario's photographs"
    if args.photo_share != PHOTO_SHARE:
        scenes += f" ({100 * args.photo_share:g} % of the panels)"
    print(f"over {s['bags']} campaign(s) of {scenes}:\n"
          f"  clean: xi error RMS {s['clean_xi_rms']:.3f} DN (target <= {TARGET_CLEAN_XI_DN}), mean "
          f"{s['clean_xi_mean']:+.3f} DN; xi_filtered {s['clean_xi_filtered_rms']:.3f} DN; false-alarm episodes "
          f"{s['false_alarm_episodes']} (target 0)\n"
          f"  gain stated {args.gain_offset_db:+g} dB: frames with true |xi| >= 1 DN detected within {WITHIN} frames "
          f"{det} (target >= {100 * TARGET_DETECTION:.0f} %); alarm on at {s['alarm_not_due']} of the {s['not_due']} frames "
          f"with true |xi| < {NOT_DUE_XI} DN; xi error RMS {offset_err}\n"
          f"  {'meets' if s['meets_targets'] else 'does NOT meet'} issue 15's per-frame targets")
    if args.json:  # standard JSON: a figure without frames is null (was NaN)
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(_finite(result), indent=1, allow_nan=False))
    return 0


def _finite(obj: Any) -> Any:
    """``obj`` with every non-finite float replaced by None."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj
