"""Effect registry: built-ins, plug-ins from Python files and the ``noise_monitor.effects`` entry points."""
from __future__ import annotations

import importlib.util
import inspect
import sys
from collections.abc import Iterable, Mapping
from importlib.metadata import entry_points
from pathlib import Path

from .base import DISTRIBUTIONS, STRUCTURES, Distribution, Effect, EffectError
from .builtin import BUILTIN_EFFECTS

ENTRY_POINT_GROUP = "noise_monitor.effects"
_REGISTRY: dict[str, type[Effect]] = {cls.name: cls for cls in BUILTIN_EFFECTS}
_entry_points_loaded = False


def register(cls: type[Effect]) -> type[Effect]:
    """Register an Effect subclass under its ``name`` (usable as a class decorator)."""
    if not (inspect.isclass(cls) and issubclass(cls, Effect)) or not cls.name:
        raise EffectError(f"{cls!r} is not an Effect subclass with a name")
    if not isinstance(cls.distribution, Distribution):
        raise EffectError(f"effect {cls.name!r}: unknown distribution {cls.distribution!r}; "
                          f"choose from {', '.join(DISTRIBUTIONS)}")
    if cls.structure not in STRUCTURES:
        raise EffectError(f"effect {cls.name!r}: unknown structure {cls.structure!r}; "
                          f"choose from {', '.join(STRUCTURES)}")
    _REGISTRY[cls.name] = cls
    return cls


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


def load_plugin_file(path: str | Path) -> list[str]:
    """Import a Python file and register every Effect subclass it defines; returns their names."""
    p = Path(path)
    if not p.is_file():
        raise EffectError(f"effect plug-in file {p} does not exist")
    spec = importlib.util.spec_from_file_location(f"noise_monitor_plugin_{p.stem}", p)
    if spec is None or spec.loader is None:
        raise EffectError(f"effect plug-in {p} is not an importable Python file")
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except Exception as exc:
        raise EffectError(f"effect plug-in {p} failed to import: {exc}") from exc
    names = []
    for obj in vars(module).values():
        if inspect.isclass(obj) and issubclass(obj, Effect) and obj.__module__ == module.__name__ and obj.name:
            register(obj)
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
        raise EffectError(f"unknown effect {name!r}; known: {', '.join(sorted(reg))}")
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
