"""Peak memory of `noise-monitor replay` on hostile bags (issue 16) against an ordinary bag.

Each replay runs in its own process; its peak resident memory is read with getrusage. The hostile bags:
MCAP chunks that expand to 2 GiB (zstd) and 1 GiB (lz4), honest about that size or claiming 1 MiB, a chunk
of zeros exactly at the limit (decompressed, then refused), and a rosbag2 folder whose metadata.yaml is a
YAML alias bomb. Prints one line per case.

    .venv/bin/python bench/bench_hostile.py [--workdir out/bench_hostile]
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "test")]  # the repository first: test/msg_adapters/ is not the package

from test_security import bomb_mcap, laughs  # noqa: E402  (the generators the tests use)

from noise_monitor.bag.bounded import MAX_CHUNK_BYTES  # noqa: E402
from noise_monitor.bag.simulate import simulate_bag  # noqa: E402

GIB = 2**30
MEASURE = ("import resource, subprocess, sys; r = subprocess.run(sys.argv[1:], capture_output=True, text=True); "
           "print(r.returncode, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, "
           "(r.stderr.strip().splitlines() or [''])[-1][:150], sep='\\t')")


def measure(bag: Path, out: Path) -> tuple[int, float, float, str]:
    """(exit code, peak RSS in MB, wall s, last stderr line) of one replay in a fresh process."""
    cmd = [sys.executable, "-m", "noise_monitor.cli", "replay", str(bag), "--profile", "icx285", "--out", str(out),
           "--no-plot", "--threads", "1"]
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", MEASURE, *cmd], capture_output=True, text=True, check=True)
    code, rss_kb, err = res.stdout.rstrip("\n").split("\t")
    return int(code), int(rss_kb) / 1024, time.perf_counter() - t0, err


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", type=Path, default=None)
    args = ap.parse_args()
    work = args.workdir or Path(tempfile.mkdtemp(prefix="bench_hostile_"))
    work.mkdir(parents=True, exist_ok=True)
    cases = {"ordinary bag (20 frames 640x512)": simulate_bag(work / "ok.mcap", "icx285", "static", frames=20,
                                                               width=640, height=512, hold_s=0.0)}
    for kind, real in (("zstd", 2 * GIB), ("lz4", GIB)):
        cases[f"{kind} chunk -> {real // GIB} GiB, declared honestly"] = bomb_mcap(
            work / f"{kind}_honest.mcap", kind, real, real)
        cases[f"{kind} chunk -> {real // GIB} GiB, declared 1 MiB"] = bomb_mcap(
            work / f"{kind}_lying.mcap", kind, real, 2**20)
    cases["zstd chunk of zeros at the limit (257 MiB)"] = bomb_mcap(work / "at_limit.mcap", "zstd", MAX_CHUNK_BYTES,
                                                                    MAX_CHUNK_BYTES)
    folder = simulate_bag(work / "alias_bomb", "icx285", "static", frames=2, width=64, height=64, hold_s=0.0)
    meta = folder / "metadata.yaml"
    meta.write_text(laughs(levels=9) + meta.read_text().replace("storage_identifier: mcap", "storage_identifier: *l9"))
    cases["metadata.yaml alias bomb (10^9 nodes)"] = folder
    print(f"{'case':45s} {'file':>10s} {'exit':>4s} {'peak RSS':>9s} {'wall':>6s}  reason")
    for name, bag in cases.items():
        size = sum(f.stat().st_size for f in bag.iterdir()) if bag.is_dir() else bag.stat().st_size
        code, rss, wall, err = measure(bag, work / f"out_{bag.stem}")
        print(f"{name:45s} {size / 1e3:8.0f}kB {code:4d} {rss:7.0f}MB {wall:5.1f}s  {err}")


if __name__ == "__main__":
    main()
