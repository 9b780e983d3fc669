"""Physics core: camera metadata, the extensible noise model (analytic and Monte-Carlo)."""
from .effects import Effect, EffectError, Param, available, build_effects, load_plugin_file, make_effect, register
from .metadata import (
    NORMALIZED_ORDER,
    PAPER_RANGES,
    CameraMetadata,
    CameraProfile,
    MetadataError,
    db_to_factor,
    factor_to_db,
    load_profile,
    sample_dynamic,
    sample_metadata,
    sample_static,
)
from .model import MODES, NoiseModel
from .sensor import Conditions, Pixels

__all__ = [
    "CameraMetadata", "CameraProfile", "Conditions", "Effect", "EffectError", "MetadataError", "MODES",
    "NORMALIZED_ORDER", "NoiseModel", "PAPER_RANGES", "Param", "Pixels", "available", "build_effects", "db_to_factor",
    "factor_to_db", "load_plugin_file", "load_profile", "make_effect", "register", "sample_dynamic",
    "sample_metadata", "sample_static",
]
