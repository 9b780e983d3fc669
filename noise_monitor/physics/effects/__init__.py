"""Noise effects: the plug-in API, the built-in library and the registry."""
from ..constants import PAPER_EFFECTS
from .base import DISTRIBUTIONS, STRUCTURES, Distribution, Effect, EffectError, Param
from .builtin import BUILTIN_EFFECTS
from .registry import (
    ENTRY_POINT_GROUP,
    available,
    build_effects,
    effect_class,
    load_plugin_file,
    make_effect,
    parse_effect_arg,
    register,
)

__all__ = [
    "DISTRIBUTIONS", "STRUCTURES", "Distribution", "Effect", "EffectError", "Param", "BUILTIN_EFFECTS",
    "PAPER_EFFECTS", "ENTRY_POINT_GROUP",
    "available", "build_effects", "effect_class", "load_plugin_file", "make_effect", "parse_effect_arg", "register",
]
