"""The lab pipeline: measure a bag (or frames), compare with the camera's model, diagnose missing effects,
add effects and refit, write the report and an extended profile."""
from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from types import MappingProxyType
from typing import Any

from tqdm import tqdm

from ..bag.staging import write_text_atomic
from ..physics import CameraProfile, Effect, NoiseModel, load_plugin_file, load_profile
from ..physics.effects import effect_class
from ..physics.metadata import profile_from_mapping
from .compare import (
    Comparison,
    baseline_effects,
    by_condition,
    measurement_scatter,
    region_table,
    rms_error,
    rms_error_raw,
)
from .diagnose import EffectSpec, candidate_names, component_errors, diagnose, diagnosis_line, fit, fitted_reading
from .estimate import estimator_views
from .left import left_by_claims
from .measure import Measurements, SegmentTolerance, measure_frames
from .noise_events import events, set_apart, without_segments
from .signature import plugin_skeleton, scene_or_effect, unexplained


def parse_add_effect(text: str) -> EffectSpec:
    """'NAME' or 'NAME=fit' (fit its fittable parameters), 'NAME=VALUE' (first fittable parameter),
    'NAME:p=v,q=w' (fixed values; 'fit' as a value fits that parameter)."""
    text = text.strip()
    if ":" in text:
        name, _, items = text.partition(":")
        cls = effect_class(name.strip())
        fixed: dict[str, float] = {}
        free: list[str] = []
        for item in filter(None, items.split(",")):
            key, _, val = item.partition("=")
            if val.strip().lower() == "fit":
                free.append(key.strip())
            else:
                fixed[key.strip()] = _number(cls.name, key.strip(), val)
        unknown = sorted((set(fixed) | set(free)) - {p.name for p in cls.params})
        if unknown:
            raise ValueError(f"effect {cls.name!r} has no parameter(s) {', '.join(unknown)}; its parameters: "
                             f"{', '.join(p.name for p in cls.params) or 'none'}")
        fixed_only = sorted(p.name for p in cls.params if p.name in free and not p.fittable)
        if fixed_only:
            raise ValueError(f"effect {cls.name!r}: {', '.join(fixed_only)} cannot be fitted (a fixed parameter, "
                             "e.g. a pattern's seed): give a value")
        cls(**fixed)  # validates values and bounds
        return EffectSpec(cls, fixed, tuple(free))
    name, sep, val = text.partition("=")
    cls = effect_class(name.strip())
    fittable = [p for p in cls.params if p.fittable]
    if not fittable:  # e.g. pn: in every model already, with nothing to fit or set
        raise ValueError(f"effect {cls.name!r} has no fittable parameter: nothing to fit or set "
                         "(the paper's sources pn, dcsn and rn are in every model)")
    if not sep or val.strip().lower() == "fit":
        return EffectSpec.fit_all(cls)
    fixed = {fittable[0].name: _number(cls.name, fittable[0].name, val)}
    cls(**fixed)
    return EffectSpec(cls, fixed, ())


def _number(effect: str, param: str, text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"{effect}.{param}: expected a number or 'fit', got {text!r}") from None


def _frames(source: Any, profile: CameraProfile | None, topics: Mapping[str, str | None],
            bit_depth: int | None) -> tuple[Callable[[], Iterable[Any]], int | None, str]:
    """(a function giving a fresh pass over the frames, their number, a name for the report)."""
    if isinstance(source, (str, Path)):
        from ..bag.reader import open_bag

        with open_bag(source, **topics) as reader:  # unusable bags fail here, before any work
            n = len(reader)

        def passes() -> Iterator[Any]:
            with open_bag(source, **topics) as r:
                yield from r.frames(profile, bit_depth=bit_depth)

        return passes, n, str(source)
    frames = list(source)
    return lambda: frames, len(frames), "frames"


def analyze(
    bag_or_frames: str | Path | Iterable[Any],
    profile: str | Path | CameraProfile | None = None,
    add_effects: Sequence[str] = (),
    plugins: Sequence[str | Path] = (),
    replace_builtins: bool = False,
    report_dir: str | Path | None = None,
    write_profile: str | Path | None = None,
    write_plugin_skeleton: str | Path | None = None,
    candidates: Sequence[str] | None = None,
    tolerance: SegmentTolerance = SegmentTolerance(),
    progress: bool = False,
    estimator: str | None = "full_meta",
    weights: str | Path | None = None,
    device: str = "cpu",
    topics: Mapping[str, str | None] = MappingProxyType({}),
    bit_depth: int | None = None,
) -> dict[str, Any]:
    """Measure, compare, diagnose and (with ``add_effects``) refit; returns the JSON summary. A bag's topics are
    detected as replay detects them, ``topics`` overriding (``image_topic``, ``metadata_topic``, ...: the keywords
    of :func:`noise_monitor.bag.reader.open_bag`); ``bit_depth``: of 16-bit images, default the profile's.

    Keys: ``rms_error_dn`` (the profile's model vs the measured total sigma per cell, net of the
    measurement's own scatter: :func:`.compare.rms_error`), ``rms_error_raw_dn`` (the plain rms of the
    residuals), ``measurement_scatter_dn`` (the rms of the cells' standard errors), ``by_condition``,
    ``candidates`` (ranked best first: ``effect``, ``rank``, ``equivalent_to``, ``indistinguishable``,
    ``significant`` (claimed), ``significant_alone``, ``explained_by`` and ``beyond`` (the claims' forward
    selection: :func:`.diagnose.claim`), ``explained_fraction``, ``params``, ...), ``diagnosis`` (one line:
    :func:`.diagnose.diagnosis_line`), ``unexplained`` (the residual's signature, :func:`.signature.unexplained`; ``significant`` when
    no candidate explains a significant residual), ``left_by_claims`` (what the claimed effects at their claimed values
    leave: chi-square, its p-value, rms errors, the candidates refused beyond them: :func:`.left.left_by_claims`; None
    when nothing is claimed), ``measurement``; with ``add_effects`` also ``added_effects``, ``rms_error_before_dn``,
    ``rms_error_after_dn`` (both net, as ``rms_error_dn``), ``rms_error_before_raw_dn``, ``rms_error_after_raw_dn``,
    ``rms_error_by_component_after_dn`` and ``by_condition_after`` (the extended model, evaluated exactly).
    ``rms_error_by_component_dn``: per measured component, the error its variance mismatch makes in the
    cells' total sigma, net of the scatter (:func:`.diagnose.component_errors`): a weak fixed pattern
    whose error is lost in the total's statistical noise shows in its own component. With
    ``estimator`` (None: skip), ``estimator``: the monitor's xi and sigma_image per model (``before``,
    ``after``) on the same frames (:func:`.estimate.estimator_views`; ``weights``: e.g. fine-tuned ones).
    """
    t0 = time.perf_counter()
    if write_profile and not add_effects:
        raise ValueError("--write-profile needs at least one --add-effect")
    check_outputs(bag_or_frames if isinstance(bag_or_frames, (str, Path)) else None, report_dir=report_dir,
                  files={"--write-profile": write_profile, "--write-plugin-skeleton": write_plugin_skeleton})
    plugin_names = [n for f in plugins for n in load_plugin_file(f, override=replace_builtins)]
    prof = load_profile(profile) if isinstance(profile, (str, Path)) else profile
    specs = [parse_add_effect(a) for a in add_effects]
    names = [s.cls.name for s in specs]
    if len(set(names)) < len(names):
        raise ValueError(f"--add-effect names {', '.join(sorted({n for n in names if names.count(n) > 1}))} twice: "
                         "give each effect once (NAME:p=v,q=fit sets several of its parameters)")
    frames, n, source = _frames(bag_or_frames, prof, topics, bit_depth)
    with tqdm(total=n, desc="measure", unit="frame", disable=not progress) as bar:
        meas = measure_frames(frames(), tolerance=tolerance, progress=bar)
    integer_output = meas.output_step_dn == 1.0
    base = baseline_effects(prof, meas.segments[0].meta, integer_output)
    with tqdm(total=len(meas.segments), desc="model", unit="segment", disable=not progress) as bar:
        comp = Comparison(meas, NoiseModel(base), progress=bar)
    rows = comp.cell_table()
    apart_segments = set_apart(meas, rows)
    apart = events(meas, apart_segments, rows)
    apart_rows = [r for r in rows if r["segment"] in apart_segments.segments]
    if apart_segments.segments:  # a change of the noise inside a hold is no law of the conditions (:mod:`.noise_events`)
        meas = without_segments(meas, apart_segments.segments)
        comp = Comparison(meas, NoiseModel(base))
        rows = comp.cell_table()
    names = list(candidates) if candidates is not None else candidate_names(plugin_names)
    with tqdm(total=len(names), desc="diagnose", unit="effect", disable=not progress) as bar:
        diag = diagnose(comp, names, progress=bar)
    cands = diag.candidates
    out: dict[str, Any] = {
        "source": source,
        "profile": prof.name if prof else None,
        "model_effects": [e.name for e in base],
        "measurement": meas.summary(),
        "set_apart": apart,
        "set_apart_cells": _strip(apart_rows),
        "rms_error_dn": rms_error(rows),
        "rms_error_raw_dn": rms_error_raw(rows),
        "measurement_scatter_dn": measurement_scatter(rows),
        "rms_error_by_component_dn": _rounded(component_errors(rows)),
        "by_condition": {**by_condition(rows), "region": region_table(comp)},
        "candidates": [c.as_dict() for c in cands],
        "diagnosis": diagnosis_line([c.as_dict() for c in cands]),
        "unexplained": unexplained(comp, rows, cands),
        "left_by_claims": left_by_claims(comp, diag),
        "cells": _strip(rows),
    }
    if write_plugin_skeleton:  # when not written, the analysis stands; only the skeleton has nothing to describe
        if scene_or_effect(out["unexplained"]):
            out["plugin_skeleton_not_written"] = (
                "the residual may be the scene's texture, which these data cannot tell from an effect: record a still "
                "camera (several frames of one view) or a flat chart, then write the skeleton from that recording")
        elif out["unexplained"]["residual_significant"]:
            out["plugin_skeleton_written"] = str(_write_skeleton(write_plugin_skeleton, out["unexplained"]))
        else:
            out["plugin_skeleton_not_written"] = ("the residual is within the measurement's uncertainty: there is no "
                                                  "effect to write a plug-in for")
    after_model = None
    if specs:
        res = fit(comp, specs)
        after_effects = comp.replaced(res.effects)
        after_model = NoiseModel(after_effects)
        comp_after = Comparison(meas, after_model)
        rows_after = comp_after.cell_table()
        out.update({
            "added_effects": [
                {"effect": e.name, "params": dict(e.values), "fitted": res.values[e.name],
                 "param_errors": res.errors[e.name], "degenerate": (res.degenerate or {}).get(e.name, []),
                 "param_ranges": {k: list(v) for k, v in (res.ranges or {}).get(e.name, {}).items()},
                 "reading": fitted_reading(res, e)}
                for e in res.effects
            ],
            "rms_error_before_dn": out["rms_error_dn"],
            "rms_error_after_dn": rms_error(rows_after),
            "rms_error_before_raw_dn": out["rms_error_raw_dn"],
            "rms_error_after_raw_dn": rms_error_raw(rows_after),
            "rms_error_by_component_after_dn": _rounded(component_errors(rows_after)),
            "by_condition_after": {**by_condition(rows_after), "region": region_table(comp_after)},
            "cells_after": _strip(rows_after),
        })
        if write_profile:
            out["profile_written"] = str(_write_profile(write_profile, prof, res.effects, meas,
                                                        [str(f) for f in plugins] if plugin_names else []))
    if estimator is not None:
        models = {"before": NoiseModel(base), **({"after": after_model} if after_model is not None else {})}
        views = estimator_views(tqdm(frames(), total=n, desc="estimator", unit="frame", disable=not progress),
                                models, estimator, weights, device)
        out["estimator"] = views
    out["analysis_time_s"] = round(time.perf_counter() - t0, 3)
    if report_dir is not None:
        from .report import write_report

        out["report"] = str(write_report(report_dir, out, comp, cands, after_model))
    return out


def component_change_text(summary: dict[str, Any]) -> str:
    """The per-component errors before -> after ``--add-effect`` for people (the components with an error)."""
    before, after = summary["rms_error_by_component_dn"], summary["rms_error_by_component_after_dn"]
    changed = [c for c in before if max(before[c], after.get(c, 0.0)) > 0.0]
    return "; ".join(f"{c} {before[c]:.4f} -> {after.get(c, 0.0):.4f} DN" for c in changed) or "no component error"


def _rounded(values: dict[str, float]) -> dict[str, float]:
    return {k: round(v, 6) for k, v in values.items()}


def _strip(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [{k: (round(v, 6) if isinstance(v, float) else v) for k, v in r.items()} for r in rows]


def _write_profile(path: str | Path, prof: CameraProfile | None, effects: list[Effect], meas: Measurements,
                   plugins: Sequence[str] = ()) -> Path:
    """The profile with the added effects (fitted values) appended to its effect set; a comment names the plug-in
    files its effects may come from (a profile does not load them: --effect-plugin does)."""
    if prof is None:
        meta = meas.segments[0].meta.as_dict()
        values = {k: v for k, v in meta.items() if k not in ("gain_db", "exposure_time_s", "sensor_temperature_c")}
        prof = profile_from_mapping({"name": "analyzed", **values})
    new = CameraProfile(prof.name, dict(prof.values), {**dict(prof.effects), **{e.name: dict(e.values) for e in effects}})
    p = Path(path)
    head = "".join(f"# effects from the plug-in file {f}: load it with --effect-plugin {f}\n" for f in plugins)
    write_text_atomic(p, head + new.to_yaml())
    load_profile(p)  # the written profile must load again
    return p


def _write_skeleton(path: str | Path, sig: dict[str, Any]) -> Path:
    """A plug-in file prefilled from the residual's signature (it must import and register)."""
    p = Path(path)
    write_text_atomic(p, plugin_skeleton(sig, p.name))
    return p


def write_json(path: str | Path, summary: dict[str, Any]) -> Path:
    p = Path(path)
    write_text_atomic(p, json.dumps(summary, indent=1, default=float))
    return p


def check_outputs(bag: str | Path | None, report_dir: str | Path | None = None,
                  files: dict[str, str | Path | None] | None = None) -> None:
    """ValueError before any work for outputs that cannot be written: a report folder that is a file, an output
    file that is a folder or whose folder is a file, an output that is the input bag (it would be overwritten)."""
    from ..bag.staging import input_files, refuse_overwriting_inputs

    named = {flag: Path(f) for flag, f in (files or {}).items() if f}
    for flag, f in named.items():
        if f.is_dir():
            raise ValueError(f"{flag} {f} is a folder: name the file to write")
        parent = next((q for q in f.absolute().parents if q.exists()), None)
        if parent is not None and not parent.is_dir():
            raise ValueError(f"{flag} {f}: {parent} is a file, not a folder")
    outputs = list(named.values())
    if report_dir is not None:
        folder = Path(report_dir)
        if folder.exists() and not folder.is_dir():
            raise ValueError(f"--report {folder} is a file: name a folder for report.html and summary.json")
        outputs += [folder / "report.html", folder / "summary.json"]
    if bag is not None:
        refuse_overwriting_inputs(outputs, input_files(bag))
