"""`noise-monitor train`: generate (or reuse) a seeded dataset and train one estimator variant."""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from .data import Scheme, generate, load, save
from .train import VARIANTS, TrainSettings, train

HELP = "train an estimator variant (full_meta, drne, wo_meta, min_meta, full_meta_paper) on simulated data"


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
    p.add_argument("--width", type=int, default=None, help="conv features (default: 16)")
    p.add_argument("--depth", type=int, default=None, help="conv layers (full_meta) / residual blocks (paper family)")
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    p.add_argument("--resume", action="store_true", help="continue from <out>/checkpoint.pt")
    p.add_argument("--init", type=Path, default=None, help="start from these weights (<variant>.pt; fine-tuning)")
    p.add_argument("--device", default="auto", help="auto (CUDA if available), cpu, cuda")
    p.add_argument("--json", type=Path, default=None, help="write a JSON summary here")


def _check(args: argparse.Namespace) -> None:
    for name in ("steps", "batch", "patches", "threads"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name} must be >= 1")
    if args.patch_size < 16:
        raise ValueError("--patch-size must be >= 16")
    if args.lr <= 0:
        raise ValueError("--lr must be > 0")


def _command(args: argparse.Namespace) -> str:
    """The equivalent command line (every option explicit)."""
    parts = ["noise-monitor train"]
    for key, value in vars(args).items():
        if key.startswith("_") or key in ("command", "json") or value is None or value is False:
            continue
        flag = "--" + key.replace("_", "-")
        parts.append(flag if value is True else f"{flag} {value}")
    return " ".join(parts)


def run(args: argparse.Namespace) -> int:
    _check(args)
    data_path = args.data or args.out / "train_data.npz"
    t0 = time.time()
    if data_path.is_file():
        data = load(data_path)
    else:
        data = generate(args.patches, args.patch_size, args.data_seed, "train", Scheme())
        save(data, data_path)
    gen_s = time.time() - t0
    settings = TrainSettings(args.variant, steps=args.steps, batch=args.batch, lr=args.lr, seed=args.seed,
                             width=args.width, depth=args.depth)
    path = train(settings, data, args.out, resume=args.resume, device=args.device, threads=args.threads, init=args.init)
    summary = {"variant": args.variant, "command": _command(args), "data_seed": args.data_seed, "weights": str(path), "data": str(data_path),
               "patches": int(len(data["noisy"])), "patch_size": int(data["noisy"].shape[-1]),
               "data_seconds": round(gen_s, 1), "train_seconds": round(time.time() - t0 - gen_s, 1),
               "settings": vars(settings)}
    print(json.dumps(summary, indent=2))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(summary, indent=2))
    return 0
