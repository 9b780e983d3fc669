"""`noise-monitor scenes`: clean images of the scenes a camera saw, from the static holds of its recording.

A frame continues a hold when the camera stands still and its gain and exposure stay (``monitor.temporal.StillCamera``,
the rule of the node's temporal measurement without its temperature limit: a drifting temperature changes the
noise, not the scene). The temporal mean of a hold of N frames is the scene with its
temporal noise cut by sqrt(N) (fixed-pattern noise stays): written as an 8-bit PNG per hold of at least
``--min-frames`` frames (the first ``--max-frames`` of it), ready for ``evaluate --images`` and ``simulate-bag
--images`` / ``evaluate-stream --images``: the estimator measured on the user's own scenes.
"""
from __future__ import annotations

import argparse
import json
import math
import shlex
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from noise_monitor.monitor.period import skip_category
from noise_monitor.monitor.temporal import StillCamera

from .reader import BagReader


@dataclass
class Hold:
    """The frames of one static hold: their running sum and sum of squares (DN), first and last bag index."""

    first: int
    last: int
    frames: int
    total: np.ndarray
    squares: np.ndarray
    gain_db: float
    exposure_time_s: float

    def mean(self) -> np.ndarray:
        return self.total / self.frames

    def noise_left_dn(self) -> float:
        """The noise left in the scene's PNG: the RMS over pixels of the frames' temporal noise over sqrt(N), with the
        PNG's 8-bit rounding (1/12 DN^2). Until 2026-12-04 the median over pixels without the rounding: with few
        frames of 8-bit images the per-pixel spread is quantised (5 frames: 0.71 DN against 0.81 measured)."""
        var = np.maximum(self.squares / self.frames - self.mean() ** 2, 0.0) * self.frames / (self.frames - 1)
        return float(np.sqrt(np.mean(var) / self.frames + 1.0 / 12.0))


def static_holds(bag: Path, profile: str | Path | None, min_frames: int, max_frames: int,
                 skipped: Counter[str] | None = None) -> Iterator[Hold]:
    """The bag's static holds of at least ``min_frames`` usable frames (each summed over its first ``max_frames``);
    ``skipped``: counts the unusable frames by reason (the first reason of each kind in full)."""
    example: dict[str, str] = {}
    if not 2 <= min_frames <= max_frames:
        raise ValueError(f"need 2 <= --min-frames <= --max-frames, got {min_frames} and {max_frames}")
    still = StillCamera(temperature_tol_c=math.inf)
    hold: Hold | None = None
    reader = BagReader(bag, detect_topics=True)
    try:
        for frame in reader.frames(profile):
            if frame.image_dn is None or frame.metadata is None or frame.skip_reason:
                if skipped is not None:
                    reason = frame.skip_reason or "metadata missing"
                    skipped[example.setdefault(skip_category(reason), reason)] += 1
                continue  # an unusable frame neither breaks nor joins a hold (the motion test bridges it)
            image, m = np.asarray(frame.image_dn, dtype=np.float64), frame.metadata
            if still.continues(image, m) and hold is not None and image.shape == hold.total.shape:
                hold.last = frame.index
                if hold.frames < max_frames:
                    hold.frames += 1
                    hold.total += image
                    hold.squares += image**2
                continue
            still.restart(m)
            if hold is not None and hold.frames >= min_frames:
                yield hold
            hold = Hold(frame.index, frame.index, 1, image.copy(), image**2, m.gain_db, m.exposure_time_s)
    finally:
        reader.close()
    if hold is not None and hold.frames >= min_frames:
        yield hold


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("bag", type=Path, help="a recording (MCAP file or rosbag2 folder)")
    p.add_argument("--out", type=Path, required=True, help="folder for the scenes (one PNG per static hold)")
    p.add_argument("--profile", default=None, help="camera profile (name or YAML) for the metadata the bag lacks")
    p.add_argument("--min-frames", type=int, default=8, help="shortest hold written (frames; default 8)")
    p.add_argument("--max-frames", type=int, default=64, help="frames averaged per hold at most (default 64)")
    p.add_argument("--json", type=Path, default=None, help="write the list of scenes here")


def run(args: argparse.Namespace) -> int:
    args.out.mkdir(parents=True, exist_ok=True)
    scenes = []
    skipped: Counter[str] = Counter()
    for hold in static_holds(args.bag, args.profile, args.min_frames, args.max_frames, skipped):
        name = f"{args.bag.stem}_frames{hold.first:05d}-{hold.last:05d}.png"
        cv2.imwrite(str(args.out / name), np.clip(np.rint(hold.mean()), 0, 255).astype(np.uint8))
        scenes.append({"file": name, "first_index": hold.first, "last_index": hold.last, "frames_averaged": hold.frames,
                       "gain_db": hold.gain_db, "exposure_time_s": hold.exposure_time_s,
                       "noise_left_dn": round(hold.noise_left_dn(), 3)})
        print(f"{name}: {hold.frames} frames averaged, gain {hold.gain_db:.1f} dB, exposure "
              f"{1e3 * hold.exposure_time_s:.1f} ms, temporal noise left ~{hold.noise_left_dn():.2f} DN")
    unusable = "; ".join(f"{n} frame(s): {reason}" for reason, n in skipped.most_common(3))
    if not scenes:
        raise ValueError(f"{args.bag}: no static hold of {args.min_frames} usable frames or more"
                         + (f" (unusable: {unusable})" if unusable else ""))
    if unusable:
        print(f"unusable frames, in no scene: {unusable}")
    print(f"{len(scenes)} scene(s) in {args.out}: noise-monitor evaluate --images {shlex.quote(str(args.out))} "
          "--image-downsample 1 (your camera's pixel scale; the noise left in a scene counts in its floor: 2 halves it)")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(scenes, indent=1))
    return 0
