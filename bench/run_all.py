"""Run every benchmark of bench/ in one go and print their figures one after the other.

Run: make bench   (or .venv/bin/python bench/run_all.py [name ...] to pick some, e.g. physics estimator)
"""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
SKIP_BY_DEFAULT = {"soak_replay"}  # long: run it on its own


def main(argv: list[str]) -> int:
    scripts = sorted(p for p in HERE.glob("*.py") if p.name != Path(__file__).name)
    if argv:
        scripts = [p for p in scripts if any(a in p.stem for a in argv)]
    else:
        scripts = [p for p in scripts if p.stem not in SKIP_BY_DEFAULT]
    failed = 0
    for script in scripts:
        print(f"\n=== {script.stem} ===", flush=True)
        t0 = time.perf_counter()
        rc = subprocess.call([sys.executable, str(script)], cwd=HERE.parent)
        print(f"--- {script.stem}: exit {rc}, {time.perf_counter() - t0:.0f} s", flush=True)
        failed += rc != 0
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
