#!/usr/bin/env bash
# CPU per history export, for BENCHMARKS.md ("Fleet scale"): what one
# request costs the server (and PostgreSQL), which the machine's load moves
# far less than it moves wall times.
#
#   DB=URL tests/api/load/export_cpu.sh [PATH]
#
# Serves the already seeded database DB (see fleet.sh) with BIN (default
# target/release/drawcal), makes a reader key, sends PATH (default a site's
# whole history as CSV) WARM times (5), then N times (100) one after the
# other with curl, and prints per request: the server's CPU (utime + stime
# of the process, /proc/PID/stat), on PostgreSQL the CPU of every
# `postgres` process alive before and after (the backends of the pool's
# connections), the wall time's median and max, and the answer's size
# (which must be the same for every build compared).
set -euo pipefail
cd "$(dirname "$0")/../../.."
DB=${DB:?DB=URL of a seeded database}
P=${1:-/calibrations?site=site-03&format=csv}
BIN=${BIN:-target/release/drawcal}
N=${N:-100}
WARM=${WARM:-5}
PORT=${PORT:-18091}
BASE=http://127.0.0.1:$PORT
WORK=$(mktemp -d)
SERVER=
trap '[ -n "$SERVER" ] && kill $SERVER 2>/dev/null; wait 2>/dev/null; rm -rf "$WORK"' EXIT

KEY=dck_fleet_admin_key_0123456789abcdef0123456789ab
DRAWCAL_ADMIN_KEY=$KEY DATABASE_URL=$DB RUST_LOG=warn "$BIN" serve --listen 127.0.0.1:$PORT 2>"$WORK/server.log" &
SERVER=$!
until curl -sf $BASE/ready >/dev/null; do sleep 0.2; kill -0 $SERVER || { cat "$WORK/server.log"; exit 1; }; done
READER=$("$BIN" keys create --name "cpu-$(date +%s%N)" --role reader --database "$DB")

# utime + stime in clock ticks: of the server, and of each postgres process.
ticks() { awk '{print $14 + $15}' "/proc/$1/stat"; }
pg_ticks() {
  for d in /proc/[0-9]*; do
    [ "$(cat "$d/comm" 2>/dev/null)" = postgres ] || continue
    awk -v p="${d#/proc/}" '{print p, $14 + $15}' "$d/stat" 2>/dev/null || true
  done | sort
}
get() { curl -sS -o "$WORK/answer" -w '%{time_total}\n' -H "authorization: Bearer $READER" "$BASE$P"; }

for _ in $(seq "$WARM"); do get >/dev/null; done
PG0=$(pg_ticks)
S0=$(ticks $SERVER)
for _ in $(seq "$N"); do get; done >"$WORK/times"
S1=$(ticks $SERVER)
PG1=$(pg_ticks)
HZ=$(getconf CLK_TCK)
PG=$(join <(echo "$PG0") <(echo "$PG1") | awk '{s += $3 - $2} END {print s + 0}')
python3 - "$WORK/times" "$S0" "$S1" "$PG" "$HZ" "$N" "$(stat -c %s "$WORK/answer")" "$P" "$(cut -d' ' -f1-3 /proc/loadavg)" <<'PY'
import statistics, sys
times = [float(x) * 1000 for x in open(sys.argv[1])]
s0, s1, pg, hz, n = int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]), int(sys.argv[6])
ms = lambda t: t * 1000 / hz / n
print(f"{sys.argv[8]}: {n} requests of {sys.argv[7]} bytes; server CPU {ms(s1 - s0):.2f} ms a request, "
      f"postgres CPU {ms(pg):.2f} ms; wall median {statistics.median(times):.1f} ms, max {max(times):.1f} ms; "
      f"load average after {sys.argv[9]}")
PY
