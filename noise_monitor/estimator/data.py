"""Seeded training / benchmark data: clean patches corrupted by the sequential simulator.

Every group of ``group`` patches shares one random sensor and conditions (``sample_metadata``), so the
analytic tables (~0.2-0.3 s per metadata) are built once per group; the tables are stored with the data
so training never needs the noise model again. Per patch:
  - the stated-metadata simulation gives the per-source truth (std of each source's own clipped noise
    map, sequential protocol) and sigma_model = sqrt(PN^2 + DCSN^2 + RN^2);
  - the paper's xi scheme: with probability ``p_scheme`` each source is, with probability 1/2, generated
    with another random gain than stated (``overrides``), in an independent simulation;
  - unexpected noise: with probability ``p_unexpected`` an additive N(0, s) (s log-uniform in
    ``unexpected_range``, or ``unexpected_sigma`` if set), clipped, measured as the std of its increment;
    with several ``unexpected_shapes`` its per-pixel sigma grows as (clean intensity)^g, g drawn from them
    (0: flat; 0.5: shot-like; 1: PRNU-like), s its RMS over the patch: noise whose shape the stated model lacks;
  - sigma_image = sqrt(sum of the image's per-source sigma^2 + unexpected^2), xi = sigma_model - sigma_image.

A camera's own effect set (``effects``, e.g. a profile extended by the lab) is simulated on top of the
paper's sources and enters sigma_model, sigma_image and the tables (the ``extra`` row); fixed-pattern
effects get a fresh pattern seed per group so no pattern can be memorised. ``sensor`` (a profile's
static fields) fixes the sensor while the operating conditions stay random.
"""
from __future__ import annotations

import json
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from ..bag.staging import write_atomic
from ..physics import CameraMetadata, NoiseModel, factor_to_db, sample_metadata
from ..physics.effects import effect_class
from ..physics.metadata import NUMERIC_FIELDS, STATIC_FIELDS
from .images import Imagery, sample_clean_patches, source_images
from .physics_prior import EXTRA, SOURCES, PhysicsPrior

TRUTH_KEYS = ("pn", "dcsn", "rn", EXTRA, "sigma_model", "sigma_image", "xi")
EffectSpecs = Mapping[str, Mapping[str, float]]


@dataclass(frozen=True)
class Scheme:
    """How patches are corrupted beyond the stated metadata (see the module docstring)."""

    p_scheme: float = 0.5
    p_source: float = 0.5
    p_unexpected: float = 0.5
    unexpected_range: tuple[float, float] = (0.3, 12.0)
    unexpected_sigma: float | None = None
    unexpected_shapes: tuple[float, ...] = (0.0,)

    def as_dict(self) -> dict:
        return asdict(self)


#: The benchmark's three parts: (a) clean metadata, (b) the paper's gain corruption, (c) +N(0, 5 DN).
PARTS: dict[str, Scheme] = {
    "a": Scheme(p_scheme=0.0, p_unexpected=0.0),
    "b": Scheme(p_scheme=1.0, p_unexpected=0.0),
    "c": Scheme(p_scheme=0.0, p_unexpected=1.0, unexpected_sigma=5.0),
}


def meta_to_row(meta: CameraMetadata) -> np.ndarray:
    return np.array([getattr(meta, f) for f in NUMERIC_FIELDS] + [meta.is_cmos], dtype=np.float64)


def row_to_meta(row: np.ndarray) -> CameraMetadata:
    values = {f: float(v) for f, v in zip(NUMERIC_FIELDS, row[:-1])}
    return CameraMetadata.from_mapping({**values, "sensor_type": "cmos" if row[-1] else "ccd"})


def _random_gain_meta(meta: CameraMetadata, rng: np.random.Generator) -> CameraMetadata:
    return meta.replace(gain_db=float(factor_to_db(rng.uniform(1.0, 16.0))))


def camera_model(effects: EffectSpecs | None, rng: np.random.Generator | None = None) -> NoiseModel:
    """The paper's sources plus ``effects``; with ``rng``, fixed patterns get random seeds."""
    specs = {name: dict(params) for name, params in (effects or {}).items()}
    if rng is not None:
        for name, params in specs.items():
            if any(p.name == "seed" for p in effect_class(name).params):
                params["seed"] = int(rng.integers(0, 2**31 - 1))
    return NoiseModel(extra=specs)


def _metadata(rng: np.random.Generator, sensor: Mapping[str, Any] | None) -> CameraMetadata:
    meta = sample_metadata(rng)
    if not sensor:
        return meta
    fixed = {k: v for k, v in sensor.items() if k in STATIC_FIELDS}
    return CameraMetadata.from_mapping({**meta.as_dict(), **fixed})


def generate(n: int, patch_size: int, seed: int, split: str = "train", scheme: Scheme = Scheme(),
             group: int = 8, progress: bool = True, effects: EffectSpecs | None = None,
             sensor: Mapping[str, Any] | None = None, photo_variants: int = 0,
             procedural: int = 0, imagery: Imagery = Imagery(),
             images: Sequence[np.ndarray] | None = None) -> dict[str, np.ndarray]:
    """A seeded dataset of ``n`` noisy patches with truths, metadata and the analytic tables per group.

    ``effects``: effect specs beyond the paper's sources (name -> parameters); ``sensor``: static
    metadata fields that replace the random sensor (operating conditions stay random);
    ``photo_variants``, ``procedural``, ``imagery``: see ``images.source_images`` (the defaults keep
    every earlier dataset bit-identical); ``images``: clean grayscale DN images to crop instead of the
    split's (``split`` then only names the set; e.g. ``user_images.load_image_set``).
    """
    if n < 1 or patch_size < 8:
        raise ValueError("need n >= 1 patches of at least 8x8 px")
    if images is not None and (photo_variants or procedural or not imagery.is_default()):
        raise ValueError("own images replace the split's imagery: no photo variants, procedural or imagery options")
    rng = np.random.default_rng(seed)
    prior = PhysicsPrior(camera_model(effects))  # validates the specs before any work
    if images is None:
        images = source_images(split, rng, variants=photo_variants, procedural=procedural, imagery=imagery)
    n_groups = -(-n // group)
    clean, source = sample_clean_patches(list(images), rng, n, patch_size)
    noisy = np.empty_like(clean)
    truth = {k: np.zeros(n) for k in TRUTH_KEYS}
    overridden = np.zeros((n, len(SOURCES)), dtype=bool)
    unexpected = np.zeros(n)
    group_of = np.repeat(np.arange(n_groups), group)[:n]
    metas, tables = [], []
    for g in tqdm(range(n_groups), desc=f"data {split} seed {seed}", disable=not progress, unit="group"):
        meta = _metadata(rng, sensor) if sensor else sample_metadata(rng)
        if effects:
            prior = PhysicsPrior(camera_model(effects, rng))
        metas.append(meta_to_row(meta))
        tables.append(prior.tables(meta))
        for i in np.flatnonzero(group_of == g):
            img, sig = prior.model.simulate(clean[i], meta, rng, mode="sequential")
            for s in SOURCES:
                truth[s][i] = sig[s]
            truth[EXTRA][i] = np.sqrt(sum(sig[e] ** 2 for e in prior.extra_effects))
            truth["sigma_model"][i] = sig["total"]
            if rng.random() < scheme.p_scheme:
                over = {s: _random_gain_meta(meta, rng) for s in SOURCES if rng.random() < scheme.p_source}
                if over:
                    overridden[i] = [s in over for s in SOURCES]
                    img, sig = prior.model.simulate(clean[i], meta, rng, mode="sequential", overrides=over)
            var_image = sig["total"] ** 2
            if rng.random() < scheme.p_unexpected:
                s_u = scheme.unexpected_sigma or float(np.exp(rng.uniform(*np.log(scheme.unexpected_range))))
                scale = _shape(clean[i], scheme.unexpected_shapes, rng) * s_u
                nxt = np.clip(img + (rng.normal(0.0, 1.0, img.shape) * scale).astype(np.float32), 0.0, 255.0)
                unexpected[i] = float(np.std(nxt - img, dtype=np.float64))
                var_image += unexpected[i] ** 2
                img = nxt
            noisy[i] = img
            truth["sigma_image"][i] = np.sqrt(var_image)
    truth["xi"] = truth["sigma_model"] - truth["sigma_image"]
    return {
        "noisy": noisy, "clean": clean, "source_index": source, "group_of": group_of, "meta_rows": np.stack(metas),
        "tables": np.stack(tables), "overridden": overridden, "unexpected": unexpected,
        "effects_json": np.array(json.dumps(_plain(effects), sort_keys=True)),
        "sensor_json": np.array(json.dumps(_plain(sensor), sort_keys=True)), "photo_variants": np.array(photo_variants),
        "procedural": np.array(procedural), "imagery_json": np.array(imagery.to_json()),
        "scheme_json": np.array(json.dumps(scheme.as_dict(), sort_keys=True)),
        **{f"truth_{k}": v for k, v in truth.items()},
    }


def _shape(clean: np.ndarray, shapes: tuple[float, ...], rng: np.random.Generator) -> np.ndarray | float:
    """Per-pixel sigma of unit RMS, proportional to (clean intensity)^g with g drawn from ``shapes``; the default
    flat shape returns 1.0 without a draw, so datasets of the default scheme stay bit-identical."""
    if len(shapes) == 1 and shapes[0] == 0.0:
        return 1.0
    g = float(shapes[int(rng.integers(len(shapes)))]) if len(shapes) > 1 else float(shapes[0])
    w = np.maximum(clean.astype(np.float64), 1.0) ** g
    return w / np.sqrt(np.mean(w**2))


def scheme_of(data: dict[str, np.ndarray]) -> Scheme:
    """The corruption scheme a dataset was generated with (the default for datasets older than its record)."""
    if "scheme_json" not in data:
        return Scheme()
    d = json.loads(str(data["scheme_json"]))
    return Scheme(**{**d, "unexpected_range": tuple(d["unexpected_range"]),
                     "unexpected_shapes": tuple(d["unexpected_shapes"])})


def _plain(specs: Mapping | None) -> dict:
    return {k: (_plain(v) if isinstance(v, Mapping) else v) for k, v in (specs or {}).items()}


def camera_of(data: dict[str, np.ndarray]) -> tuple[dict, dict]:
    """(effect specs, fixed sensor fields) a dataset was generated with (empty for the paper's camera)."""
    return tuple(json.loads(str(data[k])) if k in data else {} for k in ("effects_json", "sensor_json"))


def photo_variants_of(data: dict[str, np.ndarray]) -> int:
    """Photo variants a dataset was generated with (0 for datasets older than the option)."""
    return int(data["photo_variants"]) if "photo_variants" in data else 0


def procedural_of(data: dict[str, np.ndarray]) -> int:
    """Procedural images a dataset was generated with (0 for datasets older than the option)."""
    return int(data["procedural"]) if "procedural" in data else 0


def imagery_of(data: dict[str, np.ndarray]) -> Imagery:
    """The training imagery options a dataset was generated with (the defaults for datasets older than them)."""
    return Imagery.from_dict(json.loads(str(data["imagery_json"]))) if "imagery_json" in data else Imagery()


class DamagedDataset(ValueError):
    """A dataset file that cannot be read (cut short by an interrupted or disk-full write before 2026-12-04)."""


def save(data: dict[str, np.ndarray], path: Path) -> None:
    """Write atomically (an interrupted run leaves no truncated dataset)."""
    write_atomic(path, lambda fh: np.savez(fh, **data))  # type: ignore[arg-type]  # numpy's stub: **kwds


def load(path: Path) -> dict[str, np.ndarray]:
    if not Path(path).is_file():
        raise FileNotFoundError(f"dataset {path} not found")
    try:
        with np.load(path) as f:
            return {k: f[k] for k in f.files}
    except (zipfile.BadZipFile, EOFError, OSError, ValueError) as exc:
        raise DamagedDataset(f"dataset {path} cannot be read ({exc}): delete it to generate it again") from None


def metas_of(data: dict[str, np.ndarray]) -> list[CameraMetadata]:
    """Per-patch CameraMetadata of a dataset."""
    by_group = [row_to_meta(r) for r in data["meta_rows"]]
    return [by_group[g] for g in data["group_of"]]
