"""Per-frame detection on photo campaigns: a stated gain 6 dB below the truth, and the clean xi error.

Issue 15's per-frame target, measured through the shipped runtime (``noise_monitor.bag.replay``, the node's
code and ``config/node.yaml``): campaigns from ``simulate-bag --scenario campaign`` (tuned: scikit-image
photographs) and ``--scenario campaign_heldout`` (held-out: matplotlib / PyWavelets photographs, never tuned
on), ev76c661, 320x256 (``--width``/``--height``) at 10 Hz, several seeds. Each bag is replayed twice: as recorded (true metadata) and
from a copy whose metadata states ``gain_db`` 6 dB below the truth (every frame; nothing else changes).

Definitions and the per-bag figures: :mod:`noise_monitor.bag.stream_eval` (for one set of campaigns, also the command
``noise-monitor evaluate-stream``); this bench runs the tuned and held-out sets side by side.

``--single-photo``: besides, for every held-out seed and held-out photograph, a ``campaign_heldout`` bag whose
photo panels all come from that one photograph (its procedural panels and flat chart patches unchanged), the
same figures per photograph: a frame's median over patches of one image's content, where the per-patch
errors sit per image.

Usage: .venv/bin/python bench/bench_stream_detection.py [--seeds 1 2 3] [--heldout-seeds 21 22 23]
       [--frames 100] [--width 320 --height 256] [--params config/node.yaml] [--threads 1] [--single-photo]
       [--vibration PX] [--flicker PCT] [--banding PCT [--mains-hz HZ] [--line-us US]] [--lamp PCT]
       [--json out/stream_detection.json]
Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from noise_monitor.bag.simulate_cmd import add_field_arguments, field_keywords
from noise_monitor.bag.stream_eval import evaluate_stream, summarize
from noise_monitor.estimator.images import MATPLOTLIB_PHOTOS, PYWAVELETS_PHOTOS, matplotlib_photos, pywavelets_photos
from noise_monitor.estimator.user_images import ImageSet

PROFILE = "ev76c661"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3], help="tuned campaign seeds")
    ap.add_argument("--heldout-seeds", type=int, nargs="+", default=[21, 22, 23], help="held-out campaign seeds")
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=256)
    ap.add_argument("--params", help="node params YAML (default config/node.yaml)")
    ap.add_argument("--threads", type=int, default=1, help="torch threads")
    ap.add_argument("--single-photo", action="store_true",
                    help="also held-out campaigns whose photo panels come from one photograph each")
    add_field_arguments(ap)  # the recording's conditions, as simulate-bag's: --vibration, --flicker, --banding ...
    ap.add_argument("--json")
    args = ap.parse_args()
    per_bag: dict[str, list[dict[str, Any]]] = {"tuned": [], "held-out": []}
    photos = dict(zip(MATPLOTLIB_PHOTOS + PYWAVELETS_PHOTOS, matplotlib_photos() + pywavelets_photos()))
    runs: list[tuple[str, str, int, str | None]] = [
        *(("tuned", "campaign", seed, None) for seed in args.seeds),
        *(("held-out", "campaign_heldout", seed, None) for seed in args.heldout_seeds),
        *((f"photo {name}", "campaign_heldout", seed, name) for name in (photos if args.single_photo else ())
          for seed in args.heldout_seeds)]
    for label, scenario, seed, photo in runs:
        one_photo = ImageSet((photo,), (photos[photo],), 1) if photo else None
        row = evaluate_stream(PROFILE, [seed], one_photo, scenario, args.frames, args.width, args.height,
                              params=args.params, threads=args.threads, field=field_keywords(args))["bags"][0]
        per_bag.setdefault(label, []).append(row)
        print(f"{label:8s} seed {seed:3d}: clean xi RMS {np.sqrt(np.mean(np.square(row['clean_xi']))):.3f} DN, "
              f"false alarm episodes {row['false_alarm_episodes']}, detected {row['hits']}/{row['need']} "
              f"(missed frames {row['missed_frames']}), alarm on at the frame {row['alarmed_at_frame']} (not at "
              f"{row['not_alarmed_at_frame']}); true |xi| of these frames "
              f"{min(map(abs, row['need_true_xi']), default=float('nan')):.2f}.."
              f"{max(map(abs, row['need_true_xi']), default=float('nan')):.2f} DN", flush=True)
    summary = {k: summarize(v) for k, v in per_bag.items()}
    t, h = summary["tuned"], summary["held-out"]
    print(f"\n{'':44s} {'tuned':>16s} {'held-out':>16s}")
    print(f"{'bags x frames':44s} {t['bags']:>9d} x {args.frames:<4d} {h['bags']:>9d} x {args.frames:<4d}")
    print(f"{'clean: xi error RMS / mean (DN)':44s} {t['clean_xi_rms']:>7.3f} / {t['clean_xi_mean']:+.3f} "
          f"{h['clean_xi_rms']:>7.3f} / {h['clean_xi_mean']:+.3f}")
    print(f"{'clean: xi_filtered error RMS (DN)':44s} {t['clean_xi_filtered_rms']:>16.3f} {h['clean_xi_filtered_rms']:>16.3f}")
    print(f"{'clean: false alarm episodes':44s} {t['false_alarm_episodes']:>16d} {h['false_alarm_episodes']:>16d}")
    for s in (t, h):
        s["det_text"] = f"{100 * s['detection']:.1f} % ({s['hits']}/{s['need']})"
    print(f"{'gain 6 dB low: |true xi|>=1 detected in 5 fr.':44s} {t['det_text']:>16s} {h['det_text']:>16s}")
    for s in (t, h):
        s["at_text"] = f"{100 * s['at_frame']:.1f} % ({s['alarmed_at_frame']}/{s['need']})"
    print(f"{'  ... alarm on at the frame itself':44s} {t['at_text']:>16s} {h['at_text']:>16s}")
    print(f"{'gain 6 dB low: views with such frames':44s} {t['views_with_need']:>16d} {h['views_with_need']:>16d}")
    print(f"{'gain 6 dB low: xi error RMS (DN)':44s} {t['offset_xi_error_rms']:>16.3f} {h['offset_xi_error_rms']:>16.3f}")
    for s in (t, h):
        s["not_due_text"] = f"{s['alarm_not_due']} / {s['not_due']}"
    print(f"{'gain 6 dB low: alarm on, true |xi| < 0.5 DN':44s} {t['not_due_text']:>16s} {h['not_due_text']:>16s}")
    for label, s in summary.items():
        if label.startswith("photo "):
            print(f"{label[6:]:32s} clean xi error RMS / mean {s['clean_xi_rms']:.3f} / {s['clean_xi_mean']:+.3f} DN, "
                  f"false alarm episodes {s['false_alarm_episodes']}, gain 6 dB low detected {100 * s['detection']:.1f} % "
                  f"({s['hits']}/{s['need']}), alarm on at {s['alarm_not_due']} of {s['not_due']} frames not due")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps({"summary": summary, "bags": per_bag}, indent=1))


if __name__ == "__main__":
    main()
