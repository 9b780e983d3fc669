#!/bin/bash
# The lab's claims on fresh campaigns, by the code of another source tree (BEFORE) and by this one, side by side,
# then the totals: claims of the hidden effects and of effects not hidden, before and after.
#   [IMAGES=DIR] bash experiments/lab_several_effects/before_after.sh BEFORE_TREE OUT_DIR SEED... -- EFFECT...
# e.g. git worktree add /tmp/before <commit>; bash .../before_after.sh /tmp/before /tmp/runs 650 651 -- prnu=1 dsnu=0.3
# "{seed}" in an EFFECT is replaced by the bag's seed: "prnu:sigma_pct=1,seed={seed}" gives every bag its own sensor
# pattern (without it every bag shares the effect's pattern seed 0, one sensor). IMAGES builds the campaigns from the
# images in DIR (`simulate-bag --images`) instead of the scenario's own photographs.
set -euo pipefail
here=$(cd "$(dirname "$0")/../.." && pwd)
before=$1; out=$2; shift 2
seeds=(); while [ "$1" != "--" ]; do seeds+=("$1"); shift; done; shift
specs=("$@")
imgs=(); [ -n "${IMAGES:-}" ] && imgs=(--images "$IMAGES")
py=$here/.venv/bin/python
mkdir -p "$out"
for s in "${seeds[@]}"; do
  eff=(); for e in "${specs[@]}"; do eff+=(--effect "${e//\{seed\}/$s}"); done
  bag=$out/seed$s.mcap
  [ -f "$bag" ] || $py -m noise_monitor.cli simulate-bag "$bag" --profile ev76c661 --scenario campaign_heldout \
      --frames 120 --seed "$s" "${imgs[@]}" "${eff[@]}" > /dev/null
  (cd "$before" && PYTHONPATH=$before $py -m noise_monitor.cli analyze "$bag" --profile ev76c661 --no-estimator \
      --quiet --json "$out/seed$s.before.json" > /dev/null) &
  (cd "$here" && $py -m noise_monitor.cli analyze "$bag" --profile ev76c661 --no-estimator --quiet \
      --json "$out/seed$s.after.json" > /dev/null)
  wait
done
$py - "$out" "${specs[@]}" -- "${seeds[@]}" <<'PY'
import json, re, sys
out, rest = sys.argv[1], sys.argv[2:]
cut = rest.index("--")
hidden = {re.split("[:=]", spec)[0] for spec in rest[:cut]}
totals = {"before": [0, 0, 0], "after": [0, 0, 0]}  # hidden effects claimed, effects not hidden claimed, bags
def claims(path):
    d = json.load(open(path))
    return {c["effect"]: {k: round(v, 4) for k, v in c["claimed_params"].items()} for c in d["candidates"] if c["significant"]}
for s in rest[cut + 1:]:
    found = {}
    for when in totals:
        found[when] = claims(f"{out}/seed{s}.{when}.json")
        t = totals[when]
        t[0] += len(hidden & set(found[when])); t[1] += len(set(found[when]) - hidden); t[2] += 1
    print(f"seed{s}", "before:", found["before"], "| after:", found["after"],
          "" if set(found["before"]) == set(found["after"]) else " CHANGED")
for when, (true, other, bags) in totals.items():
    print(f"{when}: {true} of {len(hidden) * bags} hidden effects claimed, {other} claims of effects not hidden")
PY
