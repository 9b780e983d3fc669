"""Per-frame detection on photo campaigns: a stated gain 6 dB below the truth, and the clean xi error.

Issue 15's per-frame target, measured through the shipped runtime (``noise_monitor.bag.replay``, the node's
code and ``config/node.yaml``): campaigns from ``simulate-bag --scenario campaign`` (tuned: scikit-image
photographs) and ``--scenario campaign_heldout`` (held-out: matplotlib / PyWavelets photographs, never tuned
on), ev76c661, 320x256 (``--width``/``--height``) at 10 Hz, several seeds. Each bag is replayed twice: as recorded (true metadata) and
from a copy whose metadata states ``gain_db`` 6 dB below the truth (every frame; nothing else changes).

Definitions (per bag, over the images; frames the monitor skipped in either replay are not counted):
- view: a maximal run of frames with the same true gain and exposure (an auto-exposure step starts one);
- true xi of a frame in the low-gain replay = sigma_model(stated) - sigma_model(true) on the same patches
  (patch selection reads the image only, so both replays choose the same patches; the per-frame model
  medians are compared). The simulator draws the noise from the same model with the true metadata, so the
  true xi of the clean replay is 0 up to the model's own approximation (measured: ``clean xi error``);
- detected within 5 frames: the alarm is on at that frame or at one of the next 4 frames of the same view;
- clean xi error: the per-frame ``xi`` (and ``xi_filtered``) of the clean replay against 0;
- false alarm episode: an alarm episode in the clean replay.

``--single-photo``: besides, for every held-out seed and held-out photograph, a ``campaign_heldout`` bag whose
photo panels all come from that one photograph (its procedural panels and flat chart patches unchanged), the
same figures per photograph: a frame's median over patches of one image's content, where the per-patch
errors sit per image.

Usage: .venv/bin/python bench/bench_stream_detection.py [--seeds 1 2 3] [--heldout-seeds 21 22 23]
       [--frames 100] [--width 320 --height 256] [--params config/node.yaml] [--threads 1] [--single-photo]
       [--json out/stream_detection.json]
Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from noise_monitor.bag.reader import BagReader
from noise_monitor.bag.replay import replay
from noise_monitor.bag.results import FrameTable, alarm_episodes
from noise_monitor.bag.simulate import load_truth, simulate_bag
from noise_monitor.bag.writer import BagWriter
from noise_monitor.estimator.images import MATPLOTLIB_PHOTOS, PYWAVELETS_PHOTOS, matplotlib_photos, pywavelets_photos
from noise_monitor.estimator.user_images import ImageSet

PROFILE = "ev76c661"
GAIN_OFFSET_DB = -6.0
WITHIN = 5  # frames: the frame itself and the next 4 of the same view
MIN_TRUE_XI = 1.0


def stated_gain_copy(src: Path, dst: Path, offset_db: float) -> Path:
    """A copy of a simulated bag whose metadata (DiagnosticArray key ``gain_db``) states ``offset_db`` more."""
    reader = BagReader(src, detect_topics=True)
    meta_topic = reader.metadata_topic
    try:
        with BagWriter(dst) as writer:
            for topic, log_ns, msg in reader.messages(list(reader.topics)):
                if topic == meta_topic:
                    values = msg.status[0].values
                    found = [kv for kv in values if kv.key == "gain_db"]
                    if len(found) != 1:
                        raise ValueError(f"{src}: metadata message without one gain_db value")
                    found[0].value = repr(float(found[0].value) + offset_db)
                writer.write(topic, msg, log_ns)
    finally:
        reader.close()
    return dst


def views(truth: dict[str, Any]) -> np.ndarray:
    """View index per frame: a new view whenever the true gain or exposure changes."""
    out, key, v = [], None, -1
    for r in truth["frames"]:
        k = (r["true_metadata"]["gain_db"], r["true_metadata"]["exposure_time_s"])
        if k != key:
            key, v = k, v + 1
        out.append(v)
    return np.asarray(out)


def detected(alarm: np.ndarray, view: np.ndarray, i: int) -> bool:
    """Alarm on at frame i or at one of the next WITHIN-1 frames of the same view."""
    j = np.arange(i, min(i + WITHIN, alarm.size))
    j = j[view[j] == view[i]]
    return bool(alarm[j].any())


def measure_bag(bag: Path, low: Path, params: str | None, threads: int) -> dict[str, Any]:
    truth = load_truth(bag)
    view = views(truth)
    tables = {}
    for label, path in (("clean", bag), ("low", low)):
        t = FrameTable()
        replay(path, PROFILE, None, config=params, threads=threads, progress=False, table=t)
        tables[label] = t
    clean, lowt = tables["clean"], tables["low"]
    ok_c = clean.column("processed").astype(bool)
    ok_l = lowt.column("processed").astype(bool)
    xi_c = clean.numbers("xi").astype(np.float64)
    xif_c = clean.numbers("xi_filtered").astype(np.float64)
    true_xi = lowt.numbers("sigma_model").astype(np.float64) - clean.numbers("sigma_model").astype(np.float64)
    alarm = lowt.column("alarm").astype(bool)  # as published (a skipped frame reports an active alarm too)
    need = np.flatnonzero(ok_c & ok_l & (np.abs(true_xi) >= MIN_TRUE_XI))
    hits = [detected(alarm, view, int(i)) for i in need]
    at_frame = int(alarm[need].sum())
    xi_l = lowt.numbers("xi").astype(np.float64)
    both = ok_c & ok_l
    return {
        "frames": len(clean), "processed_clean": int(ok_c.sum()), "processed_low": int(ok_l.sum()),
        "views": int(view.max() + 1),
        "clean_xi": xi_c[ok_c].tolist(), "clean_xi_filtered": xif_c[ok_c].tolist(),
        "false_alarm_episodes": len(alarm_episodes(clean)),
        "need": len(need), "hits": int(sum(hits)), "alarmed_at_frame": at_frame,
        "missed_frames": [int(i) for i, h in zip(need, hits) if not h],
        "not_alarmed_at_frame": [int(i) for i in need if not alarm[i]],
        "need_true_xi": [round(float(true_xi[i]), 3) for i in need],
        "low_xi_error": (xi_l[both] - true_xi[both]).tolist(),
        "low_alarm_episodes": len(alarm_episodes(lowt)),
        "view_of_need": [int(view[i]) for i in need],
    }


def summarize(rows: list[dict[str, Any]]) -> dict[str, Any]:
    xi = np.concatenate([r["clean_xi"] for r in rows])
    xif = np.concatenate([r["clean_xi_filtered"] for r in rows])
    err = np.concatenate([r["low_xi_error"] for r in rows])
    need, hits = sum(r["need"] for r in rows), sum(r["hits"] for r in rows)
    at_frame = sum(r["alarmed_at_frame"] for r in rows)
    return {
        "bags": len(rows), "frames": sum(r["frames"] for r in rows),
        "clean_xi_rms": float(np.sqrt(np.mean(xi**2))), "clean_xi_mean": float(xi.mean()),
        "clean_xi_filtered_rms": float(np.sqrt(np.mean(xif**2))),
        "false_alarm_episodes": sum(r["false_alarm_episodes"] for r in rows),
        "need": need, "hits": hits, "detection": hits / need if need else float("nan"),
        "alarmed_at_frame": at_frame, "at_frame": at_frame / need if need else float("nan"),
        "low_xi_error_rms": float(np.sqrt(np.mean(err**2))),
        "views_with_need": sum(len(set(r["view_of_need"])) for r in rows),
    }


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
    ap.add_argument("--json")
    args = ap.parse_args()
    per_bag: dict[str, list[dict[str, Any]]] = {"tuned": [], "held-out": []}
    photos = dict(zip(MATPLOTLIB_PHOTOS + PYWAVELETS_PHOTOS, matplotlib_photos() + pywavelets_photos()))
    with tempfile.TemporaryDirectory() as tmp:
        runs: list[tuple[str, str, int, str | None]] = [
            *(("tuned", "campaign", seed, None) for seed in args.seeds),
            *(("held-out", "campaign_heldout", seed, None) for seed in args.heldout_seeds),
            *((f"photo {name}", "campaign_heldout", seed, name) for name in (photos if args.single_photo else ())
              for seed in args.heldout_seeds)]
        for label, scenario, seed, photo in runs:
            stem = f"{scenario}_{seed}_{photo or 'all'}"
            one_photo = ImageSet((photo,), (photos[photo],), 1) if photo else None
            bag = simulate_bag(Path(tmp) / f"{stem}.mcap", PROFILE, scenario, frames=args.frames,
                               width=args.width, height=args.height, fps=10.0, seed=seed, images=one_photo)
            low = stated_gain_copy(bag, Path(tmp) / f"{stem}_low.mcap", GAIN_OFFSET_DB)
            row = measure_bag(bag, low, args.params, args.threads)
            row["seed"] = seed
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
    print(f"{'gain 6 dB low: xi error RMS (DN)':44s} {t['low_xi_error_rms']:>16.3f} {h['low_xi_error_rms']:>16.3f}")
    for label, s in summary.items():
        if label.startswith("photo "):
            print(f"{label[6:]:32s} clean xi error RMS / mean {s['clean_xi_rms']:.3f} / {s['clean_xi_mean']:+.3f} DN, "
                  f"false alarm episodes {s['false_alarm_episodes']}, gain 6 dB low detected {100 * s['detection']:.1f} % "
                  f"({s['hits']}/{s['need']})")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps({"summary": summary, "bags": per_bag}, indent=1))


if __name__ == "__main__":
    main()
