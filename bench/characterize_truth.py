"""How well `characterize` recovers a simulated camera: the truth-recovery table of docs/profiles.md.

For each datasheet: `profile from-emva`, `simulate-bag --scenario ptc` per seed, `characterize`; prints the
largest |relative error| over the seeds per EMVA figure (the truth is the bag's sidecar ``emva``).

    .venv/bin/python bench/characterize_truth.py --seeds 11 12 13 --frames 200 \
        config/datasheets/example_cmos_emva.yaml out/noisy_emva.yaml
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import tempfile
from pathlib import Path

from noise_monitor.bag.simulate import load_truth
from noise_monitor.cli import main as _cli

FIELDS = ("system_gain_dn_per_e", "temporal_dark_noise_e", "read_noise_e", "saturation_capacity_e",
          "dark_current_e_per_s", "doubling_temperature_k", "dsnu_e", "prnu_pct")


def cli(argv: list[str]) -> int:
    """A noise-monitor command with its report kept off the screen."""
    with contextlib.redirect_stdout(io.StringIO()):
        return _cli(argv)


def errors(result: dict, truth: dict) -> dict[str, float]:
    """Relative error per figure (the largest over the temperatures for the dark current)."""
    out = {}
    for f in FIELDS:
        got, want = result["figures"][f], truth[f]
        if f == "dark_current_e_per_s":
            out[f] = max(abs(got[t]["value"] / want[t] - 1.0) for t in want)
        else:
            out[f] = abs(got["value"] / want - 1.0)
    out["linearity_error_pct (abs, %)"] = abs(result["figures"]["linearity_error_pct"]["value"]) / 100.0
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("datasheets", nargs="+")
    p.add_argument("--seeds", type=int, nargs="+", default=[11, 12, 13])
    p.add_argument("--frames", type=int, default=200)
    p.add_argument("--width", type=int, default=320)
    p.add_argument("--height", type=int, default=256)
    args = p.parse_args()
    table: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for ds in args.datasheets:
            name = Path(ds).stem
            prof = Path(tmp) / f"{name}.yaml"
            assert cli(["profile", "from-emva", ds, "--out", str(prof)]) == 0
            worst: dict[str, float] = {}
            for seed in args.seeds:
                bag = Path(tmp) / f"{name}_{seed}.mcap"
                assert cli(["simulate-bag", str(bag), "--profile", str(prof), "--scenario", "ptc", "--frames",
                            str(args.frames), "--width", str(args.width), "--height", str(args.height),
                            "--seed", str(seed)]) == 0
                js = Path(tmp) / f"{name}_{seed}.json"
                assert cli(["characterize", str(bag), "--out", str(Path(tmp) / f"c_{name}_{seed}"),
                            "--json", str(js)]) == 0
                for k, v in errors(json.loads(js.read_text()), load_truth(bag)["emva"]).items():
                    worst[k] = max(worst.get(k, 0.0), v)
            table[name] = worst
    names = list(table)
    print(f"\nlargest |relative error| over seeds {args.seeds} ({args.frames} frames, {args.width}x{args.height})")
    print(f"{'figure':34s}" + "".join(f"{n:>26s}" for n in names))
    for k in table[names[0]]:
        print(f"{k:34s}" + "".join(f"{100 * table[n][k]:25.2f}%" for n in names))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
