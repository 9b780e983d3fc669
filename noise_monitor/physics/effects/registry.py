"""Effect registry: built-ins, plug-ins from Python files and the ``noise_monitor.effects`` entry points."""
from __future__ import annotations

import difflib
import functools
import importlib.util
import inspect
import math
import sys
from collections.abc import Callable, Iterable, Mapping
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

from ...text import clip
from .base import DISTRIBUTIONS, STRUCTURES, Distribution, Effect, EffectError, Param
from .builtin import BUILTIN_EFFECTS

ENTRY_POINT_GROUP = "noise_monitor.effects"
_REGISTRY: dict[str, type[Effect]] = {cls.name: cls for cls in BUILTIN_EFFECTS}
_BUILTIN_NAMES = frozenset(_REGISTRY)
_entry_points_loaded = False
#: Command-line flag that lets a plug-in replace a built-in effect (named in the error).
OVERRIDE_FLAG = "--replace-builtin-effects"


def _contained(fn: Callable[..., Any], effect: str) -> Callable[..., Any]:
    """``fn`` with ``sys.exit()`` turned into an EffectError (a plug-in must not end the program)."""

    @functools.wraps(fn)
    def call(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except SystemExit as exc:
            raise EffectError(f"effect {effect!r} called sys.exit({clip(repr(exc.code), 80)}) in "
                              f"{fn.__name__}(); a plug-in must raise an exception instead") from None

    call.__nm_contained__ = True  # type: ignore[attr-defined]
    return call


def _contain_exits(cls: type[Effect]) -> None:
    """Guard the methods a plug-in class defines itself against ``sys.exit``."""
    for name, fn in list(vars(cls).items()):
        if inspect.isfunction(fn) and not getattr(fn, "__nm_contained__", False):
            setattr(cls, name, _contained(fn, cls.name))


def register(cls: type[Effect], override: bool = False) -> type[Effect]:
    """Register an Effect subclass under its ``name`` (usable as a class decorator).

    A plug-in named like a built-in effect (e.g. ``rn``) is refused unless ``override`` is true (the
    command-line flag :data:`OVERRIDE_FLAG`); plug-in methods cannot end the program with ``sys.exit``.
    """
    if not (inspect.isclass(cls) and issubclass(cls, Effect)) or not isinstance(cls.name, str) or not cls.name:
        raise EffectError(f"{clip(repr(cls), 200)} is not an Effect subclass with a name")
    if not isinstance(cls.distribution, Distribution):
        raise EffectError(f"effect {clip(cls.name, 200)!r}: unknown distribution {clip(repr(cls.distribution), 80)}; "
                          f"choose from {', '.join(DISTRIBUTIONS)}")
    if cls.structure not in STRUCTURES:
        raise EffectError(f"effect {clip(cls.name, 200)!r}: unknown structure {clip(repr(cls.structure), 80)}; "
                          f"choose from {', '.join(STRUCTURES)}")
    _check_params(cls)
    builtin = cls in BUILTIN_EFFECTS
    if cls.name in _BUILTIN_NAMES and not builtin and not override:
        raise EffectError(f"plug-in effect {cls.name!r} ({cls.__module__}.{cls.__qualname__}) has the name of a "
                          f"built-in effect; rename it, or pass {OVERRIDE_FLAG} to replace the built-in")
    if not builtin:
        _contain_exits(cls)
    _REGISTRY[cls.name] = cls
    return cls


def _check_params(cls: type[Effect]) -> None:
    """An effect's ``params``: a tuple of :class:`Param` with distinct names, finite bounds lo <= hi and the
    default inside them (a plug-in's mistake named when it loads, not as a traceback while fitting)."""
    where = f"effect {clip(cls.name, 200)!r}"
    if not isinstance(cls.params, (tuple, list)) or not all(isinstance(p, Param) for p in cls.params):
        raise EffectError(f"{where}: params must be a tuple of Param(name, unit, default, (lo, hi)), got "
                          f"{clip(repr(cls.params), 120)}")
    names = [p.name for p in cls.params]
    if len(set(names)) < len(names) or not all(isinstance(n, str) and n.isidentifier() for n in names):
        raise EffectError(f"{where}: parameter names must be distinct identifiers, got {clip(repr(names), 120)}")
    for p in cls.params:
        try:
            lo, hi = (float(b) for b in p.bounds)
            default = float(p.default)
        except (TypeError, ValueError):
            raise EffectError(f"{where}: parameter {p.name!r} needs a numeric default and bounds (lo, hi), got "
                              f"{clip(repr(p.default), 40)} and {clip(repr(p.bounds), 80)}") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo <= default <= hi):
            raise EffectError(f"{where}: parameter {p.name!r} default {default:g} is outside its bounds "
                              f"[{lo:g}, {hi:g}]" if math.isfinite(lo) and math.isfinite(hi) and lo <= hi else
                              f"{where}: parameter {p.name!r} bounds {clip(repr(p.bounds), 80)} are not finite "
                              "with lo <= hi")


def _load_entry_points() -> None:
    global _entry_points_loaded
    if _entry_points_loaded:
        return
    _entry_points_loaded = True
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        try:
            register(ep.load())
        except Exception as exc:  # a broken third-party plug-in must not break the tool
            print(f"noise_monitor: ignoring effect entry point {ep.name!r}: {exc}", file=sys.stderr)


def load_plugin_file(path: str | Path, override: bool = False) -> list[str]:
    """Import a Python file and register every Effect subclass it defines; returns their names.

    ``override``: its effects may replace built-in effects of the same name (see :func:`register`)."""
    p = Path(path)
    if not p.is_file():
        raise EffectError(f"effect plug-in file {p} does not exist")
    spec = importlib.util.spec_from_file_location(f"noise_monitor_plugin_{p.stem}", p)
    if spec is None or spec.loader is None:
        raise EffectError(f"effect plug-in {p} is not an importable Python file")
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except SystemExit as exc:
        raise EffectError(f"effect plug-in {p} called sys.exit({clip(repr(exc.code), 80)}) while importing") from None
    except Exception as exc:
        raise EffectError(f"effect plug-in {p} failed to import: {clip(str(exc))}") from exc
    names = []
    source = str(p.resolve())
    for obj in vars(module).values():
        if inspect.isclass(obj) and issubclass(obj, Effect) and obj.__module__ == module.__name__ and obj.name:
            known = _REGISTRY.get(obj.name)
            if known is not None and known not in BUILTIN_EFFECTS and known.plugin_file != source:
                raise EffectError(f"effect plug-in {p} defines {obj.name!r}, which {known.plugin_file} defines too: "
                                  "rename one (each effect name is one effect)")
            obj.plugin_file = source
            register(obj, override=override)
            names.append(obj.name)
    if not names:
        raise EffectError(f"effect plug-in {p} defines no Effect subclass with a name")
    return names


def available() -> dict[str, type[Effect]]:
    """All registered effect classes by name."""
    _load_entry_points()
    return dict(_REGISTRY)


def effect_class(name: str) -> type[Effect]:
    reg = available()
    if name not in reg:
        close = difflib.get_close_matches(name.lower(), list(reg), n=1, cutoff=0.6)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise EffectError(f"unknown effect {name!r} ({hint}a plug-in's? load its file with --effect-plugin); known: "
                          f"{', '.join(sorted(reg))}")
    return reg[name]


def make_effect(name: str, **values: float) -> Effect:
    return effect_class(name)(**values)


def parse_effect_arg(text: str) -> tuple[str, dict[str, float]]:
    """Parse 'name', 'name=value' (the first fittable parameter) or 'name:param=value,param=value'."""
    text = text.strip()
    if ":" in text:
        name, rest = text.split(":", 1)
        values = {}
        for item in filter(None, rest.split(",")):
            key, _, val = item.partition("=")
            values[key.strip()] = float(val)
        return name.strip(), values
    if "=" in text:
        name, _, val = text.partition("=")
        cls = effect_class(name.strip())
        fittable = [p for p in cls.params if p.fittable]
        if not fittable:
            raise EffectError(f"effect {name!r} takes no value")
        return name.strip(), {fittable[0].name: float(val)}
    return text, {}


def build_effects(spec: Iterable[str | Effect] | Mapping[str, Mapping[str, float]] | None) -> list[Effect]:
    """Effects from names / 'name=value' strings / a mapping name -> parameters (e.g. a profile's)."""
    if spec is None:
        return []
    if isinstance(spec, Mapping):
        return [make_effect(n, **dict(v or {})) for n, v in spec.items()]
    out: list[Effect] = []
    for item in spec:
        if isinstance(item, Effect):
            out.append(item)
        else:
            name, values = parse_effect_arg(str(item))
            out.append(make_effect(name, **values))
    return out
