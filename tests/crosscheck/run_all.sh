#!/usr/bin/env bash
# Every cross-check set (gen3.py ... gen10.py) with one binary, and their
# aggregate lines only (the held-back halves stay blind: no per-recording
# lines are printed). Usage:
#   tests/crosscheck/run_all.sh BIN OUT
# BIN: the drawcal binary to measure (e.g. target/release/drawcal);
# OUT: a scratch directory. Each set is planned once into OUT/plan/genN
# (kept and reused), copied to OUT/BINNAME/genN, run and scored there;
# OUT/BINNAME/genN/score.txt holds the scorer's output. About 20 s per set
# on 2 cores after planning. Needs python3 with numpy and scipy.
set -euo pipefail
BIN=$(realpath "$1")
OUT=$2
HERE=$(cd "$(dirname "$0")" && pwd)
NAME=$(basename "$BIN")
for g in 3 4 5 6 7 8 9 10; do
  [ -f "$HERE/gen$g.py" ] || continue
  plan="$OUT/plan/gen$g"
  if [ ! -f "$plan/plan.json" ]; then
    mkdir -p "$plan"
    env "XC${g}_OUT=$plan" python3 "$HERE/gen$g.py" plan > /dev/null
  fi
  d="$OUT/$NAME/gen$g"
  rm -rf "$d"
  mkdir -p "$d"
  cp -r "$plan/." "$d/"
  env XCHECK_TOOL="$BIN" "XC${g}_OUT=$d" python3 "$HERE/gen$g.py" run > /dev/null
  env "XC${g}_OUT=$d" python3 "$HERE/gen$g.py" score > "$d/score.txt"
  echo "## gen$g"
  # The aggregate blocks only: from the first '== ' header on.
  sed -n '/^== /,$p' "$d/score.txt" | grep -E '^== |located right|misnamed|silent  |ratio tool|false alarms'
done
