"""Benchmark of start-up: `noise-monitor --help` and a replay's time to its first processed frame.

Each figure is the median of ``--runs`` fresh processes (the OS file cache warm after the first), wall
time and the process's CPU time (user + system; the better figure on a loaded machine).
Usage: .venv/bin/python bench/bench_startup.py [--runs 5]     Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FIRST_FRAME = """
import json, resource, sys, time
t0 = time.perf_counter()
from noise_monitor.bag.replay import replay
from noise_monitor.monitor import pipeline
done = pipeline.Monitor.process
def first(self, frame, received_ns=None):
    done(self, frame, received_ns)
    ru = resource.getrusage(resource.RUSAGE_SELF)
    print(json.dumps({"wall_s": time.perf_counter() - t0, "cpu_s": ru.ru_utime + ru.ru_stime,
                      "torch_imported": "torch" in sys.modules}))
    raise SystemExit(0)
pipeline.Monitor.process = first
replay(sys.argv[1], sys.argv[2], None, progress=False, plot=False, threads=1)
"""
HELP = """
import json, resource, time, sys
t0 = time.perf_counter()
from noise_monitor.cli import main
try:
    main(["--help"])
except SystemExit:
    pass
ru = resource.getrusage(resource.RUSAGE_SELF)
print(json.dumps({"wall_s": time.perf_counter() - t0, "cpu_s": ru.ru_utime + ru.ru_stime}), file=sys.stderr)
"""


def measure(code: str, args: list[str], runs: int, stream: str) -> dict[str, float]:
    rows = []
    for _ in range(runs):
        res = subprocess.run([sys.executable, "-c", code, *args], cwd=ROOT, capture_output=True, text=True, check=True)
        rows.append(json.loads((res.stdout if stream == "stdout" else res.stderr).strip().splitlines()[-1]))
    return {k: statistics.median(r[k] for r in rows) for k in ("wall_s", "cpu_s")} | (
        {"torch_imported": any(r.get("torch_imported") for r in rows)})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    print(f"{'what':58s} {'wall [s]':>9s} {'CPU [s]':>8s}")
    h = measure(HELP, [], args.runs, "stderr")
    print(f"{'noise-monitor --help (interpreter start excluded)':58s} {h['wall_s']:9.3f} {h['cpu_s']:8.3f}")
    for bag, profile in (("bags/icx285_lab.mcap", "icx285"), ("bags/ev76c661_field.mcap", "ev76c661")):
        r = measure(FIRST_FRAME, [bag, profile], args.runs, "stdout")
        label = f"replay {Path(bag).name}: first frame processed"
        print(f"{label:58s} {r['wall_s']:9.3f} {r['cpu_s']:8.3f}  (torch imported: {r['torch_imported']})")


if __name__ == "__main__":
    main()
