#!/usr/bin/env bash
# Service load figures for BENCHMARKS.md ("## Service load").
#
#   tests/api/load/run.sh [path/to/release/drawcal]
#
# Starts the release binary on a fresh SQLite file, calibrates a robot from
# tests/data/er3a_paper_like, then measures with wrk (Debian package `wrk`):
#   1. POST /compensate, one joint target per request, 64 connections;
#   2. POST /compensate, 10,000 targets per request (batch throughput);
#   3. upload + identification of a 2000-pose session, end to end
#      (the first 2000 poses of tests/data/real_ur10_ipa_random).
#   0. (PARTS=health) GET /health, 64 connections: the same server's
#      ceiling, against which the keyed POST /compensate is compared;
#   4. (PARTS=rate, needs oha: `cargo install oha`) POST /compensate, one
#      joint target per request, 64 connections, at a fixed arrival rate
#      RATE (default 20000/s; open loop, latency corrected for coordinated
#      omission): latency at a given load rather than at saturation.
# SITE_KEY=1 sends the single targets (parts single and rate) with an operator key limited to the
# robot's site; INSECURE=1 serves with --insecure-no-auth (the key check left out, to
# measure what it costs); PARTS selects (default "single batch identify");
# DUR the wrk duration;
# LOG_LEVEL the server's RUST_LOG (default warn), LOG_FORMAT its log format.
# The generator shares the server's machine: WRK_THREADS (default 1) keeps it
# to one core's worth, as the server's default of one runtime thread per two
# cores expects; SERVER_CPUS and WRK_CPUS (taskset lists, e.g. 0 and 1) pin
# the two apart.
set -euo pipefail
cd "$(dirname "$0")/../../.."
BIN=${1:-target/release/drawcal}
DUR=${DUR:-15s}
WRK_THREADS=${WRK_THREADS:-1}
PORT=${PORT:-18080}
PARTS=${PARTS:-single batch identify}
has() { [[ " $PARTS " == *" $1 "* ]]; }
BASE=http://127.0.0.1:$PORT
WORK=$(mktemp -d)
trap 'kill $SERVER 2>/dev/null || true; wait $SERVER 2>/dev/null || true; rm -rf "$WORK"' EXIT

# Every route but /health and /ready needs a key: the server's first admin
# key, which every request below sends.
export KEY=dck_bench_admin_key_0123456789abcdef0123456789ab
DRAWCAL_ADMIN_KEY=$KEY DATABASE_URL=sqlite://$WORK/bench.db RUST_LOG=${LOG_LEVEL:-warn} DRAWCAL_LOG_FORMAT=${LOG_FORMAT:-text} ${SERVER_CPUS:+taskset -c $SERVER_CPUS} "$BIN" serve --listen 127.0.0.1:$PORT --workers 1 ${INSECURE:+--insecure-no-auth} 2>"$WORK/server.log" &
SERVER=$!
until curl -sf $BASE/ready >/dev/null; do sleep 0.2; done

j() { curl -sS --fail-with-body -H "authorization: Bearer $KEY" -H 'content-type: application/json' "$@"; }
k() { curl -sS -H "authorization: Bearer $KEY" "$@"; }
id() { python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])'; }
wait_job() {
  until k $BASE/jobs/$1 | grep -Eq '"state":"(succeeded|failed|cancelled)"'; do sleep 0.05; done
  k $BASE/jobs/$1 | python3 -c 'import json,sys; j=json.load(sys.stdin); assert j["state"]=="succeeded", j; print(j["calibration_id"])'
}
setup() { # dataset serial -> session id
  local D=tests/data/$1
  local M=$(j -X POST $BASE/models --data-binary @$D/robot.json | id)
  local R=$(j -X POST $BASE/robots -d "{\"serial_number\": \"$2\", \"model_id\": $M, \"site\": \"bench-site\"}" | id)
  local G=$(j -X POST $BASE/rigs --data-binary @$D/rig.json | id)
  local S=$(j -X POST $BASE/sessions -d "{\"robot_id\": $R, \"rig_id\": $G}" | id)
  echo "$R $S"
}

read ROBOT SESSION < <(setup er3a_paper_like BENCH-1)
k --fail-with-body -X POST $BASE/sessions/$SESSION/poses -H 'content-type: text/csv' --data-binary @tests/data/er3a_paper_like/poses.csv >/dev/null
JOB=$(j -X POST $BASE/sessions/$SESSION/jobs -d '{}' | id)
CAL=$(wait_job $JOB)
j -X POST $BASE/robots/$ROBOT/activate -d "{\"calibration_id\": $CAL, \"reason\": \"load test\"}" >/dev/null
# SITE_KEY=1: the single targets are sent with an operator key limited to
# the robot's site, as a floor client's would be (the site checked on every
# request), instead of the admin key.
if [[ -n "${SITE_KEY:-}" ]]; then
  OPERATOR=$(j -X POST $BASE/keys -d '{"name": "floor", "role": "operator", "sites": ["bench-site"]}' |
    python3 -c 'import json,sys; print(json.load(sys.stdin)["secret"])')
fi

python3 - "$ROBOT" "$WORK" <<'PY'
import json, random, sys
robot, work = int(sys.argv[1]), sys.argv[2]
rnd = random.Random(1)
def q():  # nominal joint targets inside the ER3A's limits
    return [round(rnd.uniform(lo, hi), 4) for lo, hi in [(-150, 150), (-90, 90), (-50, 120), (-150, 150), (-100, 100), (-300, 300)]]
json.dump({"robot_id": robot, "target": {"target": "t1", "q_deg": [10, -20, 30, 0, 40, 0]}}, open(f"{work}/one.json", "w"))
json.dump({"robot_id": robot, "targets": [{"target": f"t{i}", "q_deg": q()} for i in range(10000)]}, open(f"{work}/batch.json", "w"))
PY
# The server's CPU time (user + system, clock ticks) so far.
ticks() { awk '{print $14 + $15}' /proc/$SERVER/stat; }
# wrk with its output, then the server's CPU time per request it answered:
# what a request costs the server, whatever the generator beside it costs.
measured() {
  local t0 out
  t0=$(ticks)
  out=$("$@")
  echo "$out"
  echo "$out" | awk -v dt=$(( $(ticks) - t0 )) -v hz=$(getconf CLK_TCK) \
    '/requests in/ {printf "server CPU: %.1f us a request (%d requests)\n", dt / hz * 1e6 / $1, $1}'
}
if has health; then
  echo "### GET /health, 64 connections (load average: $(cut -d' ' -f1-3 /proc/loadavg))"
  measured ${WRK_CPUS:+taskset -c $WRK_CPUS} wrk -t$WRK_THREADS -c64 -d$DUR --latency $BASE/health
fi
if has single; then
  echo "### single target, 64 connections (load average: $(cut -d' ' -f1-3 /proc/loadavg))"
  BODY=$WORK/one.json KEY=${OPERATOR:-$KEY} measured ${WRK_CPUS:+taskset -c $WRK_CPUS} wrk -t$WRK_THREADS -c64 -d$DUR --latency -s tests/api/load/post.lua $BASE/compensate
fi
if has batch; then
  echo "### batch of 10,000 targets, 2 connections (load average: $(cut -d' ' -f1-3 /proc/loadavg))"
  BODY=$WORK/batch.json wrk -t2 -c2 -d$DUR --latency -s tests/api/load/post.lua $BASE/compensate
  k -H 'content-type: application/json' --data-binary @$WORK/batch.json $BASE/compensate |
    python3 -c 'import json,sys; r=json.load(sys.stdin); print("batch statuses:", {s: sum(1 for x in r["results"] if x["status"]==s) for s in ("ok","unreachable","joint_limit")})'
fi
if has rate; then
  echo "### single target, 64 connections, ${RATE:-20000} requests/s offered (load average: $(cut -d' ' -f1-3 /proc/loadavg))"
  ${OHA:-oha} --no-tui -z $DUR -c 64 -q ${RATE:-20000} --latency-correction -m POST \
    -H 'content-type: application/json' -H "authorization: Bearer ${OPERATOR:-$KEY}" -D $WORK/one.json $BASE/compensate |
    grep -E 'Success rate|Requests/sec|Slowest|Average|50.00%|90.00%|99.00%|99.90%|\[[0-9]+\] [0-9]+ responses'
fi
has identify || exit 0

echo "### upload + identify, 2000 poses"
head -n 2001 tests/data/real_ur10_ipa_random/poses.csv > $WORK/poses2000.csv
read R2 S2 < <(setup real_ur10_ipa_random BENCH-2)
T0=$(date +%s.%N)
k --fail-with-body -X POST $BASE/sessions/$S2/poses -H 'content-type: text/csv' --data-binary @$WORK/poses2000.csv >/dev/null
T1=$(date +%s.%N)
J2=$(j -X POST $BASE/sessions/$S2/jobs -d '{}' | id)
C2=$(wait_job $J2)
T2=$(date +%s.%N)
python3 -c "print(f'upload {($T1-$T0)*1000:.0f} ms, identify {($T2-$T1):.2f} s, end to end {($T2-$T0):.2f} s (calibration $C2)')"
k $BASE/calibrations/$C2 | python3 -c 'import json,sys; c=json.load(sys.stdin)["calibration"]; print("held-out RMS before/after (mm):", c["test_rms_before_mm"], c["test_rms_after_mm"])'
