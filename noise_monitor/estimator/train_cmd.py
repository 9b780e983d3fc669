"""`noise-monitor train`: generate (or reuse) a seeded dataset and train one estimator variant."""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

from ..physics import load_profile
from ..physics.effects import load_plugin_file
from ..physics.metadata import STATIC_FIELDS
from .data import Scheme, camera_of, generate, imagery_of, load, photo_variants_of, procedural_of, save, scheme_of
from .device import resolve_device
from .images import JPEG_QUALITY, PHOTO_DOWNSCALE, Imagery
from .networks import VARIANTS
from .train import TrainSettings, train


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--variant", required=True, choices=VARIANTS)
    p.add_argument("--out", required=True, type=Path, help="output directory (checkpoint.pt, <variant>.pt)")
    p.add_argument("--steps", type=int, default=3000)
    p.add_argument("--batch", type=int, default=32)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--seed", type=int, default=0, help="training seed (batch order, initialisation)")
    p.add_argument("--data", type=Path, default=None,
                   help="dataset .npz (generated there if missing; default <out>/train_data.npz)")
    p.add_argument("--data-seed", type=int, default=1, help="seed of the generated dataset")
    p.add_argument("--patches", type=int, default=16000, help="patches to generate")
    p.add_argument("--patch-size", type=int, default=64)
    p.add_argument("--photo-variants", type=int, default=0,
                   help=f"use each training photo N times at a random {PHOTO_DOWNSCALE[0]}-{PHOTO_DOWNSCALE[1]:g}x "
                        "downscale and gamma instead of once at 2x (the shipped full_meta's last stages use 3; "
                        "0 = the paper-style recipe)")
    p.add_argument("--procedural", type=int, default=0,
                   help="add N procedural images of pixel-scale structure to the training images (fractal hillshades, "
                        "gratings, fabric, halftone, text; the shipped confidence head uses 40)")
    p.add_argument("--photo-scales", type=float, nargs=2, default=list(PHOTO_DOWNSCALE), metavar=("LOW", "HIGH"),
                   help="with --photo-variants: log-uniform range of the photos' area downscale (1 = native; default "
                        f"{PHOTO_DOWNSCALE[0]} {PHOTO_DOWNSCALE[1]:g})")
    p.add_argument("--photo-native", type=float, default=0.0, metavar="P",
                   help="with --photo-variants: probability that a variant keeps the photo's native resolution")
    p.add_argument("--photo-rotate", type=float, default=0.0, metavar="P",
                   help="with --photo-variants: probability that a variant is rotated by an arbitrary angle")
    p.add_argument("--jpeg", type=float, default=0.0, metavar="P",
                   help=f"probability that a clean source image is JPEG-compressed (quality {JPEG_QUALITY[0]}-"
                        f"{JPEG_QUALITY[1]}) before cropping")
    p.add_argument("--manmade", type=int, default=0, metavar="N",
                   help="add N man-made procedural scenes (dead leaves of polygons, periodic bars: straight edges at "
                        "arbitrary angles)")
    p.add_argument("--grain", type=int, default=0, metavar="N",
                   help="add N grainy procedural pictures (near-white grain of 0.4-1.5 px as scene content)")
    p.add_argument("--charts", type=int, default=0, metavar="N",
                   help="add N test charts (tiles over the whole 0..255 range: flat, ramps, smooth textures, step wedges)")
    p.add_argument("--gratings", type=int, default=0, metavar="N",
                   help="add N plain gratings (one or two sine gratings of 1.5-6 px periods over the whole image)")
    p.add_argument("--unexpected-shapes", type=float, nargs="+", default=[0.0], metavar="G",
                   help="exponents g of the unexpected noise's per-pixel sigma ~ (clean intensity)^g, one drawn per "
                        "patch (0 = the flat N(0, s); 0.5 shot-like; 1 PRNU-like: noise whose shape the stated model "
                        "lacks; default 0)")
    p.add_argument("--width", type=int, default=None, help="conv features (default: 16)")
    p.add_argument("--depth", type=int, default=None, help="conv layers (full_meta) / residual blocks (paper family)")
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    p.add_argument("--resume", action="store_true", help="continue from <out>/checkpoint.pt")
    p.add_argument("--checkpoint-every", type=int, default=250, help="steps between checkpoints")
    p.add_argument("--keep-checkpoints", action="store_true",
                   help="also keep the weights of every checkpoint as <out>/step_<N>.pt (to choose one on tuning sets)")
    p.add_argument("--init", type=Path, default=None, help="start from these weights (<variant>.pt; fine-tuning)")
    p.add_argument("--confidence", action="store_true",
                   help="full_meta with --init: add a confidence head (the measurement's predicted error; patches "
                        "it cannot measure are declined) and train it alone, the measurement frozen")
    p.add_argument("--anchor", type=float, default=0.0, metavar="W",
                   help="full_meta with --init (weights with a confidence head): pull the measurement toward the "
                        "init's reading on the patches the init declines, with weight W (keeps the reading of content "
                        "one image cannot measure from drifting while fine-tuning on new imagery; 0 = off)")
    p.add_argument("--spectral", action="store_true",
                   help="full_meta: also give the network a line-robust noise scale (the median of the patch's "
                        "high-band periodogram, which a pixel-scale grating does not move); from --init weights "
                        "without it, its input weights start at zero")
    p.add_argument("--shape-trend", action="store_true",
                   help="full_meta: also give the network the shape-trend scalars (how the noise's intensity "
                        "dependence departs from the stated model's); from --init weights without them, their input "
                        "weights start at zero")
    p.add_argument("--profile", default=None,
                   help="camera profile (YAML or bundled name): its effects are simulated and enter the physics "
                        "prior, and its sensor fields replace the random sensor (e.g. a profile written by "
                        "`noise-monitor analyze --write-profile`, to fine-tune with --init)")
    p.add_argument("--effect-plugin", action="append", default=[], metavar="FILE",
                   help="load effects from FILE (for a profile that uses plug-in effects; repeatable)")
    p.add_argument("--replace-builtin-effects", action="store_true",
                   help="let --effect-plugin effects replace built-in effects of the same name (else an error)")
    p.add_argument("--device", default="auto", help="auto (CUDA if available), cpu, cuda")
    p.add_argument("--json", type=Path, default=None, help="write a JSON summary here")


def _check(args: argparse.Namespace) -> None:
    for name in ("steps", "batch", "patches", "threads"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name} must be >= 1")
    if min(args.photo_variants, args.procedural, args.manmade, args.grain, args.charts, args.gratings) < 0:
        raise ValueError("--photo-variants, --procedural, --manmade, --grain, --charts and --gratings must be >= 0")
    if any(not 0.0 <= g <= 2.0 for g in args.unexpected_shapes):
        raise ValueError("--unexpected-shapes exponents must be in [0, 2]")
    if args.checkpoint_every < 1:
        raise ValueError("--checkpoint-every must be >= 1")
    imagery(args)  # validates the imagery options
    if not imagery(args).default_photos and not args.photo_variants:
        raise ValueError("--photo-scales, --photo-native and --photo-rotate need --photo-variants >= 1")
    if args.patch_size < 16:
        raise ValueError("--patch-size must be >= 16")
    if args.lr <= 0:
        raise ValueError("--lr must be > 0")
    if args.confidence and (args.variant != "full_meta" or args.init is None):
        raise ValueError("--confidence needs --variant full_meta and --init (the measurement to qualify)")
    if args.anchor < 0 or (args.anchor and (args.variant != "full_meta" or args.init is None or args.confidence)):
        raise ValueError("--anchor must be >= 0 and needs --variant full_meta and --init (weights with a confidence "
                         "head), without --confidence")
    if (args.shape_trend or args.spectral) and args.variant != "full_meta":
        raise ValueError("--shape-trend and --spectral are inputs of the full_meta network")
    # before the data are generated (minutes at the default size; until 2026-12-04 these failed only after, some with
    # a traceback)
    resolve_device(args.device)
    if args.resume and not (args.out / "checkpoint.pt").is_file():
        raise FileNotFoundError(f"--resume: no checkpoint at {args.out / 'checkpoint.pt'}")
    if args.init is not None:
        _check_init(args.init, args.variant)


def _check_init(path: Path, variant: str) -> None:
    """``--init`` must be weights of this variant written by ``train`` (a ``<variant>.pt`` checkpoint)."""
    if not path.is_file():
        raise FileNotFoundError(f"--init: {path} not found")
    try:
        ck = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # not a torch file, or one with other objects than tensors
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ValueError(f"--init: {path} is not noise_monitor weights (a <variant>.pt of train): {first}") from None
    if not isinstance(ck, dict) or "variant" not in ck or "state_dict" not in ck:
        raise ValueError(f"--init: {path} is not noise_monitor weights (a <variant>.pt of train)")
    if ck["variant"] != variant:
        raise ValueError(f"--init: {path} holds {ck['variant']} weights, not {variant} (--variant)")


def _command(args: argparse.Namespace) -> str:
    """The equivalent command line (every option explicit)."""
    parts = ["noise-monitor train"]
    for key, value in vars(args).items():
        if key.startswith("_") or key in ("command", "json") or value is None or value is False:
            continue
        flag = "--" + key.replace("_", "-")
        if key in ("photo_scales", "unexpected_shapes"):  # one option of several values
            parts.append(f"{flag} {' '.join(f'{float(v):g}' for v in value)}")
            continue
        for v in value if isinstance(value, list) else [value]:
            parts.append(flag if v is True else f"{flag} {v}")
    return " ".join(parts)


def imagery(args: argparse.Namespace) -> Imagery:
    """The training imagery options of the command line."""
    return Imagery(photo_scales=(float(args.photo_scales[0]), float(args.photo_scales[1])),
                   photo_native=args.photo_native, photo_rotate=args.photo_rotate, jpeg=args.jpeg, manmade=args.manmade,
                   grain=args.grain, charts=args.charts, gratings=args.gratings)


def scheme(args: argparse.Namespace) -> Scheme:
    """The training corruption scheme of the command line."""
    return Scheme(unexpected_shapes=tuple(float(g) for g in args.unexpected_shapes))


def camera(profile: str | None) -> tuple[dict, dict]:
    """(effect specs, static sensor fields) of a profile; empty for the paper's random cameras."""
    if profile is None:
        return {}, {}
    prof = load_profile(profile)
    sensor = {k: v for k, v in prof.values.items() if k in STATIC_FIELDS}
    return {k: dict(v) for k, v in prof.effects.items()}, sensor


def run(args: argparse.Namespace) -> int:
    _check(args)
    for plugin in args.effect_plugin:
        load_plugin_file(plugin, override=args.replace_builtin_effects)
    effects, sensor = camera(args.profile)
    data_path = args.data or args.out / "train_data.npz"
    t0 = time.time()
    reused = data_path.is_file()
    if reused:
        data = load(data_path)
        if camera_of(data) != (effects, sensor):
            raise ValueError(f"dataset {data_path} was generated for another camera (effects, sensor) than "
                             f"{args.profile or 'the paper random cameras'}: {camera_of(data)}; give a new --data path")
        if photo_variants_of(data) != args.photo_variants:
            raise ValueError(f"dataset {data_path} was generated with --photo-variants {photo_variants_of(data)}, not "
                             f"{args.photo_variants}; give a new --data path")
        if procedural_of(data) != args.procedural:
            raise ValueError(f"dataset {data_path} was generated with --procedural {procedural_of(data)}, not "
                             f"{args.procedural}; give a new --data path")
        if scheme_of(data) != scheme(args):
            raise ValueError(f"dataset {data_path} was generated with another corruption scheme "
                             f"({scheme_of(data).as_dict()}) than {scheme(args).as_dict()}; give a new --data path")
        if imagery_of(data) != imagery(args):
            raise ValueError(f"dataset {data_path} was generated with other imagery options "
                             f"({imagery_of(data).to_json()}) than {imagery(args).to_json()}; give a new --data path")
        size = (int(len(data["noisy"])), int(data["noisy"].shape[-1]), int(data.get("data_seed", args.data_seed)))
        if size != (args.patches, args.patch_size, args.data_seed):  # until 2026-12-04 recorded as asked, not as used
            raise ValueError(f"dataset {data_path} holds {size[0]} patches of {size[1]} px from data seed {size[2]}, "
                             f"not --patches {args.patches} --patch-size {args.patch_size} --data-seed "
                             f"{args.data_seed}; give those or a new --data path")
    else:
        data = generate(args.patches, args.patch_size, args.data_seed, "train", scheme(args), effects=effects, sensor=sensor,
                        photo_variants=args.photo_variants, procedural=args.procedural, imagery=imagery(args))
        save({**data, "data_seed": np.array(args.data_seed)}, data_path)
    gen_s = time.time() - t0
    settings = TrainSettings(args.variant, steps=args.steps, batch=args.batch, lr=args.lr, seed=args.seed,
                             width=args.width, depth=args.depth, confidence=args.confidence,
                             checkpoint_every=args.checkpoint_every, keep_checkpoints=args.keep_checkpoints,
                             anchor=args.anchor, shape_trend=args.shape_trend, spectral=args.spectral)
    path = train(settings, data, args.out, resume=args.resume, device=args.device, threads=args.threads, init=args.init)
    summary = {"variant": args.variant, "command": _command(args), "data_seed": args.data_seed, "weights": str(path), "data": str(data_path),
               "effects": effects, "sensor": sensor, "scheme": scheme(args).as_dict(),
               "photo_variants": args.photo_variants, "procedural": args.procedural,
               **({"imagery": imagery(args).as_dict()} if not imagery(args).is_default() else {}),
               "patches": int(len(data["noisy"])), "patch_size": int(data["noisy"].shape[-1]),
               "data_reused": reused, "data_seconds": round(gen_s, 1), "train_seconds": round(time.time() - t0 - gen_s, 1),
               "settings": vars(settings)}
    print(json.dumps(summary, indent=2))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(summary, indent=2))
    return 0
