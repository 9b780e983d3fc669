"""Weight-space interpolation of two fine-tunes of one network (WiSE-FT, Wortsman et al. 2022): every parameter
and buffer ``(1 - alpha) * A + alpha * B``; the checkpoint's other fields (config, step counts, camera) from B.

Usage: .venv/bin/python experiments/full_meta_shape_trend/interpolate.py A.pt B.pt --alpha 0.5 --out C.pt
"""
from __future__ import annotations

import argparse
from pathlib import Path

import torch


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a", type=Path)
    ap.add_argument("b", type=Path)
    ap.add_argument("--alpha", type=float, default=0.5, help="weight of B")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    a, b = (torch.load(p, map_location="cpu", weights_only=True) for p in (args.a, args.b))
    if a["config"] != b["config"] or a["state_dict"].keys() != b["state_dict"].keys():
        raise SystemExit(f"{args.a} and {args.b} are not the same network")
    out = dict(b, state_dict={k: ((1.0 - args.alpha) * a["state_dict"][k].float() + args.alpha * v.float()).to(v.dtype)
                              for k, v in b["state_dict"].items()})
    args.out.parent.mkdir(parents=True, exist_ok=True)
    torch.save(out, args.out)
    print(args.out)


if __name__ == "__main__":
    main()
