"""Benchmark of the lab on field-like campaigns: floor, ranking and error cut per hidden library effect.

Bags: `simulate-bag --scenario campaign` (the variant the lab was developed on) and
`campaign_heldout` (other photographs, textures, holds, pans, exposure and temperature laws; never
tuned on), EV76C661, 120 frames 320x256 at 10 Hz, one hidden effect per bag at a field-realistic
strength (plus a clean bag). Each bag is analysed with `--add-effect NAME=fit` for its hidden effect.
Prints per bag: rms_error_dn (net of the measurement's scatter) and the raw rms, the best candidate, the true effect's rank (candidates the data
cannot tell apart share one: "1st (equivalent: exposure_error)") and significance, the candidates claimed (and those significant alone but not beyond them), the fitted values (with the range that fits as well for a
parameter the data do not identify) and the error cut (net and raw; and in the measured component whose error the fit cuts most: a weak
fixed pattern's error shows there), the signed net mean-square error and its standard error; then the summary
(clean floor, ranks, median and minimum cut) per variant.

Usage: .venv/bin/python bench/bench_lab_campaign.py [--variants campaign campaign_heldout]
       [--frames 120] [--width 320] [--height 256] [--seed 11] [--effects ...] [--skip-clean] [--json out.json]
Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import tempfile
import time
from pathlib import Path

import torch

from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.lab import analyze

PROFILE = "ev76c661"
#: hidden effect -> spec at a field-realistic strength (column/row offsets of 0.45 DN: the issue's
#: "column FPN of 15 e- at 24 dB", fitted there at 0.43 DN)
EFFECTS = {
    "prnu": "prnu=1",
    "dsnu": "dsnu=0.3",
    "column_offsets": "column_offsets=0.45",
    "row_offsets": "row_offsets=0.45",
    "quantization": "quantization=6",
    "hot_pixels": "hot_pixels:fraction=0.001,dark_multiplier=1000",
    "extra_read_noise": "extra_read_noise=10",
    "dark_current_law": "dark_current_law=2",
    "gain_error": "gain_error=1.1",
}


def net_mse(cells: list[dict]) -> tuple[float, float]:
    """(mean(residual^2 - se^2) over cells, signed, in DN^2; its standard error, sqrt(sum 2 se^4) / n):
    rms_error_dn is the square root of the first clipped at 0, so a figure below its standard error's
    square root is within the measurement's noise."""
    r = [c["residual_dn"] for c in cells]
    se = [c["measured_sigma_err_dn"] for c in cells]
    n = max(len(r), 1)
    return (sum(a * a - e * e for a, e in zip(r, se)) / n, (2.0 * sum(e**4 for e in se)) ** 0.5 / n)


def _pct(x: float) -> str:
    return "n/a" if math.isnan(x) else f"{100 * x:.0f} %"


def _cut(before: float, after: float) -> float:
    """Relative error cut (NaN when there was no error to cut)."""
    return round(1.0 - after / before, 4) if before > 0 else float("nan")


def ordinal(rank: int, equivalent: list[str]) -> str:
    """'1st', '2nd (equivalent: exposure_error)', ..."""
    suffix = {1: "st", 2: "nd", 3: "rd"}.get(rank if rank < 20 else rank % 10, "th")
    return f"{rank}{suffix}" + (f" (equivalent: {', '.join(equivalent)})" if equivalent else "")


def _ranges(ranges: dict[str, list[float]]) -> str:
    """Degenerate parameters' ranges that fit as well (empty when every parameter is identified)."""
    return "".join(f" ({k} not identified: {lo:.4g} to {hi:.4g} fit as well)" for k, (lo, hi) in ranges.items())


def run_bag(tmp: Path, scenario: str, effect: str | None, args: argparse.Namespace) -> dict:
    name = f"{scenario}-{effect or 'clean'}"
    bag = simulate_bag(tmp / f"{name}.mcap", PROFILE, scenario, effects=[EFFECTS[effect]] if effect else [],
                       frames=args.frames, width=args.width, height=args.height, fps=10.0, seed=args.seed)
    t = time.perf_counter()
    s = analyze(bag, PROFILE, add_effects=[f"{effect}=fit"] if effect else [], estimator=None)
    wall = time.perf_counter() - t
    names = [c["effect"] for c in s["candidates"]]
    claimed = [c["effect"] for c in s["candidates"] if c["significant"]]
    row = {"bag": name, "effect": effect, "spec": EFFECTS.get(effect), "analysis_s": round(wall, 1),
           "rms_error_dn": round(s["rms_error_dn"], 4), "rms_error_raw_dn": round(s["rms_error_raw_dn"], 4),
           "measurement_scatter_dn": round(s["measurement_scatter_dn"], 4), "best": names[0], "claimed": claimed,
           "explained_by": {c["effect"]: c["explained_by"] for c in s["candidates"] if c.get("explained_by")},
           "cells": s["measurement"]["cells"], "not_measured": s["measurement"]["not_measured"],
           # what the claims leave: more than the measurement's scatter (None: nothing claimed)
           "left_significant": s["left_by_claims"] and s["left_by_claims"]["significant"]}
    row["net_mse_dn2"], row["net_mse_se_dn2"] = (round(x, 5) for x in net_mse(s["cells"]))
    groups: dict[int, list[str]] = {}
    for c in s["candidates"]:
        if c["equivalent_to"]:
            groups.setdefault(c["rank"], []).append(c["effect"])
    row["equivalent_groups"] = list(groups.values())  # every group of candidates the data cannot tell apart
    if effect:
        cand = s["candidates"][names.index(effect)]
        added = s["added_effects"][0]
        row.update(rank=cand["rank"], equivalent_to=cand["equivalent_to"], significant=cand["significant"],
                   fitted=added["fitted"], fits_as_well=added["param_ranges"],
                   rms_error_after_dn=round(s["rms_error_after_dn"], 4),
                   rms_error_after_raw_dn=round(s["rms_error_after_raw_dn"], 4),
                   cut=_cut(s["rms_error_before_dn"], s["rms_error_after_dn"]),
                   cut_raw=_cut(s["rms_error_before_raw_dn"], s["rms_error_after_raw_dn"]))
        row["net_mse_after_dn2"], row["net_mse_after_se_dn2"] = (round(x, 5) for x in net_mse(s["cells_after"]))
        # the component whose error the fit cuts most (a weak fixed pattern's error shows there)
        before, after = s["rms_error_by_component_dn"], s["rms_error_by_component_after_dn"]
        own = max(before, key=lambda c: before[c] - after.get(c, 0.0))
        row.update(own_component=own, own_before_dn=round(before[own], 4), own_after_dn=round(after.get(own, 0.0), 4),
                   own_cut=_cut(before[own], after.get(own, 0.0)))
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variants", nargs="+", default=["campaign", "campaign_heldout"])
    ap.add_argument("--effects", nargs="+", default=list(EFFECTS))
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=256)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--skip-clean", action="store_true", help="leave out the clean bag (no floor in the summary)")
    ap.add_argument("--json", help="write the results here")
    args = ap.parse_args()
    torch.set_num_threads(1)
    results: dict[str, list[dict]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for scenario in args.variants:
            rows = results.setdefault(scenario, [])
            for effect in ([] if args.skip_clean else [None]) + list(args.effects):
                row = run_bag(Path(tmp), scenario, effect, args)
                rows.append(row)
                if effect:
                    print(f"{row['bag']:40s} rms (net) {row['rms_error_dn']:.3f} -> {row['rms_error_after_dn']:.3f} DN "
                          f"(cut {_pct(row['cut'])}; its own component {row['own_component']} {row['own_before_dn']:.4f} -> "
                          f"{row['own_after_dn']:.4f} DN, cut {_pct(row['own_cut'])}), raw {row['rms_error_raw_dn']:.3f} -> "
                          f"{row['rms_error_after_raw_dn']:.3f} DN (cut {_pct(row['cut_raw'])}), scatter "
                          f"{row['measurement_scatter_dn']:.3f} DN, net mse {row['net_mse_dn2']:+.4f} +- {row['net_mse_se_dn2']:.4f} -> "
                          f"{row['net_mse_after_dn2']:+.4f} +- {row['net_mse_after_se_dn2']:.4f} DN^2, rank {ordinal(row['rank'], row['equivalent_to'])}, "
                          f"significant {row['significant']}, claimed {row['claimed'] or 'nothing'} "
                          f"(significant alone, explained by the claimed: {row['explained_by'] or 'none'}), "
                          f"fitted {row['fitted']}{_ranges(row['fits_as_well'])}, best {row['best']}, groups {row['equivalent_groups'] or 'none'}, "
                          f"{row['analysis_s']:.0f} s", flush=True)
                else:
                    print(f"{row['bag']:40s} rms (net) {row['rms_error_dn']:.3f} DN, raw {row['rms_error_raw_dn']:.3f} DN, "
                          f"scatter {row['measurement_scatter_dn']:.3f} DN, net mse {row['net_mse_dn2']:+.4f} +- "
                          f"{row['net_mse_se_dn2']:.4f} DN^2, claimed {row['claimed'] or 'nothing'} (explained by the claimed: "
                          f"{row['explained_by'] or 'none'}), "
                          f"groups {row['equivalent_groups'] or 'none'}, {row['cells']} cells, {row['analysis_s']:.0f} s",
                          flush=True)
            hidden = [r for r in rows if r["effect"]]
            if hidden and not args.skip_clean:
                cuts = [r["cut"] for r in hidden if not math.isnan(r["cut"])]
                raw = [r["cut_raw"] for r in hidden]
                none = [r["effect"] for r in hidden if math.isnan(r["cut"])]
                print(f"== {scenario}: clean floor {rows[0]['rms_error_dn']:.3f} DN net, {rows[0]['rms_error_raw_dn']:.3f} DN raw (claimed: "
                      f"{rows[0]['claimed'] or 'nothing'}); ranked first {sum(r['rank'] == 1 for r in hidden)} of "
                      f"{len(hidden)}; significant {sum(r['significant'] for r in hidden)}; error cut median "
                      f"{_pct(statistics.median(cuts) if cuts else math.nan)}, min {_pct(min(cuts, default=math.nan))}"
                      f"{f' (undefined for {none}: no net error before)' if none else ''} (raw: median "
                      f"{_pct(statistics.median(raw))}, min {_pct(min(raw))}; in the effect's own component: median "
                      f"{_pct(statistics.median([r['own_cut'] for r in hidden]))}, min "
                      f"{_pct(min(r['own_cut'] for r in hidden))}); the claims leave more than the scatter on "
                      f"{sum(bool(r['left_significant']) for r in rows)} of "
                      f"{sum(r['left_significant'] is not None for r in rows)} bags with claims", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
