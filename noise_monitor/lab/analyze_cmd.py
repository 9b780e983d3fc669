"""`noise-monitor analyze`: model vs measurement on a bag, ranked missing effects, add-and-refit, report."""
from __future__ import annotations

import argparse

from ..bag.input_options import add_input_arguments, topic_overrides
from .analyze import analyze, check_outputs, component_change_text, write_json
from .left import left_text
from .measure import field_conditions_text, scene_in_single_views_text, scene_in_views_text
from .noise_events import events_text
from .shape import fixed_shape_text
from .signature import scene_or_effect


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", help="rosbag2 folder (MCAP or sqlite3), a bare .mcap / .db3 file or a ROS 1 .bag")
    parser.add_argument("--profile", help="camera profile: bundled name (icx285, ev76c661, generic) or YAML path; "
                                          "optional if the bag's metadata carries every field")
    add_input_arguments(parser)
    parser.add_argument("--add-effect", action="append", default=[], metavar="NAME[=VALUE|fit]",
                        help="add an effect to the model and refit: NAME or NAME=fit fits its parameters, "
                             "NAME=VALUE fixes the first one, NAME:p=v,q=fit mixes (repeatable)")
    parser.add_argument("--effect-plugin", action="append", default=[], metavar="FILE",
                        help="Python file defining Effect subclasses (candidates and --add-effect names)")
    parser.add_argument("--replace-builtin-effects", action="store_true",
                        help="let --effect-plugin effects replace built-in effects of the same name (else an error)")
    parser.add_argument("--report", metavar="DIR", help="write report.html (self-contained) and summary.json here")
    parser.add_argument("--json", metavar="PATH", help="write the JSON summary to PATH")
    parser.add_argument("--write-profile", metavar="OUT.yaml",
                        help="save the profile extended with the added (fitted) effects")
    parser.add_argument("--write-plugin-skeleton", metavar="PATH.py",
                        help="write an effect plug-in prefilled from the residual's signature (distribution, "
                             "temporal flag, structure, position, fitted law) for you to complete")
    parser.add_argument("--no-estimator", action="store_true",
                        help="skip the estimator's view (the monitor's xi and sigma_image on the same frames)")
    parser.add_argument("--weights", metavar="PT", help="estimator weights for that view (e.g. fine-tuned with "
                                                        "`noise-monitor train --profile`); default: bundled")
    parser.add_argument("--device", default="cpu", help="estimator device: cpu, cuda or auto")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    check_outputs(args.bag, files={"--json": args.json})
    summary = analyze(
        args.bag,
        profile=args.profile,
        add_effects=args.add_effect,
        plugins=args.effect_plugin,
        replace_builtins=args.replace_builtin_effects,
        report_dir=args.report,
        write_profile=args.write_profile,
        write_plugin_skeleton=args.write_plugin_skeleton,
        progress=not args.quiet,
        estimator=None if args.no_estimator else "full_meta",
        weights=args.weights,
        device=args.device,
        topics=topic_overrides(args),
        bit_depth=args.bit_depth,
    )
    apart = sum(ev["frames"] for ev in summary["set_apart"])
    print(f"rms error (model vs measured total sigma, net of the measurement's scatter): {summary['rms_error_dn']:.4f} DN "
          f"(raw {summary['rms_error_raw_dn']:.4f} DN, measurement scatter {summary['measurement_scatter_dn']:.4f} DN) "
          f"over {summary['measurement']['cells']} cells, {summary['measurement']['frames_used'] - apart} frames"
          + (f" ({apart} more set apart, below)" if apart else ""))
    m = summary["measurement"]
    for reason, n in m["frames_skipped"].items():
        print(f"  {n} frame(s) not measured: {reason}")
    for what, why in m["not_measured"].items():
        print(f"  not measured ({what}): {why}")
    print(f"  {fixed_shape_text(m['fixed_pattern_shape'])}")
    print(f"  field conditions: {field_conditions_text(m['field_conditions'])}")
    for line in events_text(m["noise_changes"], summary["set_apart"]):
        print(f"  {line}")
    if m["scene_in_partner_views"]:
        print(f"  {scene_in_views_text(m['scene_in_partner_views'])}")
    if scene := scene_in_single_views_text(m["scene_in_single_views"]):
        print(f"  {scene}")
    top = summary["candidates"][:5]
    width = max([18, *(len(c["effect"]) for c in top)])  # a plug-in's long name keeps the columns aligned
    for c in top:
        mark = "*" if c["significant"] else "~" if c["significant_alone"] else " "
        params = ", ".join(_param_text(k, v, c["param_ranges"].get(k)) for k, v in c["params"].items())
        if c["significant"] and c["beyond"] and c["beyond"]["effect"] == c["effect"]:  # refitted beyond (or with) the
            # others: those values (a member of a group claimed whole shares its lead's refit: its fit alone)
            ranges = c["beyond"]["param_ranges"]
            params = (", ".join(_param_text(k, v, ranges.get(k)) for k, v in c["claimed_params"].items())
                      + f"  (alone: {params})")
        same = f"  (indistinguishable from {', '.join(c['equivalent_to'])})" if c["equivalent_to"] else ""
        print(f" {mark} {c['rank']:2d} {c['effect']:{width}s} explained {c['explained_fraction']:6.1%}  {params}{same}")
    print(summary["diagnosis"])
    refits: dict[tuple[int, str], list[str]] = {}  # one per group (a group parted beyond the claims: per member)
    for c in summary["candidates"]:
        if c["beyond"]:
            refits.setdefault((c["rank"], c["beyond"]["reading"]), []).append(c["effect"])
    for c in summary["candidates"]:
        if c["beyond"] and (names := refits.pop((c["rank"], c["beyond"]["reading"]), None)):
            print(f"{'*' if c['beyond']['significant'] else '~'} {', '.join(names)}: {c['beyond']['reading']}")
    shown = next((c["rank"] for c in summary["candidates"] if c["significant"] and c["equivalent_to"]), None)
    for rank, text in dict.fromkeys((c["rank"], c["indistinguishable"]) for c in top if c["equivalent_to"]):
        if rank != shown:
            print(f"rank {rank}, alternatives these data cannot tell apart: {text}")
    for c in top:
        if c["contradicted"]:
            print(f"x {c['effect']}: not claimed, {c['contradicted']}")
    if summary["left_by_claims"]:
        for line in left_text(summary["left_by_claims"], summary["rms_error_dn"]):
            print(line)
    un = summary["unexplained"]
    if un["significant"]:
        print(f"unexplained: {un['reading']}")
    elif scene_or_effect(un):
        print(f"not established (an effect or the scene): {un['reading']}")
    if "plugin_skeleton_written" in summary:
        print(f"plug-in skeleton: {summary['plugin_skeleton_written']}")
    if "plugin_skeleton_not_written" in summary:
        print(f"no plug-in skeleton written: {summary['plugin_skeleton_not_written']}")
    for added in summary.get("added_effects", []):  # the values the profile gets (fitted ones with their error)
        print(f"added {added['effect']}: " + ", ".join(_added_text(k, v, added) for k, v in added["params"].items()))
    if "rms_error_after_dn" in summary:
        print(f"rms error before {summary['rms_error_before_dn']:.4f} DN, after {summary['rms_error_after_dn']:.4f} DN "
              f"(raw {summary['rms_error_before_raw_dn']:.4f} -> {summary['rms_error_after_raw_dn']:.4f} DN)")
        print(f"  by component: {component_change_text(summary)}")
    for name, view in summary.get("estimator", {}).items():
        xi = view["xi_dn"]
        if xi["mean"] is not None:
            print(f"estimator ({name}): xi mean {xi['mean']:+.3f} DN (p5 {xi['p5']:+.3f}, p95 {xi['p95']:+.3f}), "
                  f"mean |xi| {view['mean_abs_xi_dn']:.3f} DN over {view['frames']} frames")
    if "profile_written" in summary:
        print(f"extended profile: {summary['profile_written']}")
    if "report" in summary:
        print(f"report: {summary['report']}")
    if args.json:
        write_json(args.json, summary)
    return 0


def _added_text(name: str, value: float, added: dict) -> str:
    """An added effect's parameter: fitted ('fitted +- error', or the range fitting as well) or held ('fixed')."""
    if name not in added["fitted"]:
        return f"{name}={value:.4g} (fixed)"
    span = added["param_ranges"].get(name)
    if span is not None:
        return _param_text(name, value, span)
    return f"{name}={value:.4g} +- {added['param_errors'].get(name, float('nan')):.2g} (fitted)"


def _param_text(name: str, value: float, fits_as_well: list[float] | None) -> str:
    """'name=value', with the range that fits as well when the data do not identify the parameter."""
    text = f"{name}={value:.4g}"
    return text if fits_as_well is None else f"{text} (not identified: {fits_as_well[0]:.4g} to {fits_as_well[1]:.4g} fit as well)"
