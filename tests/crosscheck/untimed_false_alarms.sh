#!/usr/bin/env bash
# Effect-free sessions without a clock: simulate, drop time_s and temp_c,
# identify with the physics analysis, count the sessions with any finding.
#   tests/crosscheck/untimed_false_alarms.sh [n_poses] [first_seed]
# (EVAL.md: 80 poses from seed 100, and 200 poses from seed 200.)
set -euo pipefail
BIN=${BIN:-target/release/drawcal}
POSES=${1:-80}
SEED0=${2:-100}
W=$(mktemp -d)
trap 'rm -rf "$W"' EXIT
n=0
fa=0
for robot in er3a ur5 arm4_mdh; do
  for seed in $(seq "$SEED0" $((SEED0 + 19))); do
    echo "{\"robot\":\"$robot\",\"n_poses\":$POSES,\"seed\":$seed,\"effects\":[]}" >"$W/s.json"
    rm -rf "$W/e"
    "$BIN" simulate --spec "$W/s.json" --out "$W/e" >/dev/null 2>&1 || continue
    python3 - "$W/e" <<'PY'
import csv, sys
d = sys.argv[1]
r = list(csv.reader(open(f"{d}/poses.csv")))
drop = {r[0].index("time_s"), r[0].index("temp_c")}
csv.writer(open(f"{d}/nt.csv", "w", newline="")).writerows(
    [[x for i, x in enumerate(row) if i not in drop] for row in r])
PY
    "$BIN" identify --robot "$W/e/robot.json" --rig "$W/e/rig.json" --poses "$W/e/nt.csv" --out "$W/e/r.json" >/dev/null 2>&1
    f=$(python3 -c "import json,sys; print(' '.join(x['effect'] for x in json.load(open(sys.argv[1]))['findings']))" "$W/e/r.json")
    n=$((n + 1))
    if [ -n "$f" ]; then
      fa=$((fa + 1))
      echo "$robot seed $seed: $f"
    fi
  done
done
echo "false alarms $fa / $n"
