#!/bin/bash
# The lab's claims on fresh campaigns, by the code of another source tree (BEFORE) and by this one, side by side.
#   bash experiments/lab_several_effects/before_after.sh BEFORE_TREE OUT_DIR SEED... -- EFFECT...
# e.g. git worktree add /tmp/before <commit>; bash .../before_after.sh /tmp/before /tmp/runs 650 651 -- prnu=1 dsnu=0.3
set -euo pipefail
here=$(cd "$(dirname "$0")/../.." && pwd)
before=$1; out=$2; shift 2
seeds=(); while [ "$1" != "--" ]; do seeds+=("$1"); shift; done; shift
eff=(); for e in "$@"; do eff+=(--effect "$e"); done
py=$here/.venv/bin/python
mkdir -p "$out"
for s in "${seeds[@]}"; do
  bag=$out/seed$s.mcap
  [ -f "$bag" ] || $py -m noise_monitor.cli simulate-bag "$bag" --profile ev76c661 --scenario campaign_heldout \
      --frames 120 --seed "$s" "${eff[@]}" > /dev/null
  (cd "$before" && PYTHONPATH=$before $py -m noise_monitor.cli analyze "$bag" --profile ev76c661 --no-estimator \
      --quiet --json "$out/seed$s.before.json" > /dev/null) &
  (cd "$here" && $py -m noise_monitor.cli analyze "$bag" --profile ev76c661 --no-estimator --quiet \
      --json "$out/seed$s.after.json" > /dev/null)
  wait
  $py - "$out/seed$s" <<'PY'
import json, sys
def claims(path):
    d = json.load(open(path))
    return {c["effect"]: {k: round(v, 4) for k, v in ((c.get("beyond") or {}).get("params") or c["params"]).items()}
            for c in d["candidates"] if c["significant"]}
stem = sys.argv[1]
print(stem.rsplit("/", 1)[-1], "before:", claims(stem + ".before.json"), "| after:", claims(stem + ".after.json"))
PY
done
