#!/usr/bin/env bash
# Fleet-scale history figures for BENCHMARKS.md ("Fleet scale").
#
#   tests/api/load/fleet.sh sqlite|postgres
#
# Seeds a fresh database with N calibrations (default 100,000) across ROBOTS
# robots (2,000) at SITES sites (20) with examples/fleet_seed.rs (real engine
# reports, 27 to 134 KB of JSON each), serves it with the release binary,
# and measures the history routes with wrk (Debian package `wrk`) and a
# reader key: each route for DUR (10s) on CONNS connections (4), every
# request a path drawn at random from a list spread over sites, robots and
# months (tests/api/load/history.lua). Prints a table of p50/p99/requests
# per second per route, the server's peak RSS, and the query plans.
#
# DB=URL measures an already seeded database instead (no seeding).
# Fresh databases: sqlite:$WORKDIR/fleet-N.db ($WORKDIR default
# /tmp/drawcal-fleet, kept for reuse), or the PostgreSQL database fleet_N
# on $PG_URL (default postgres://postgres@127.0.0.1:5432), dropped and
# created again.
# ROUTES selects routes by name (default all; see `route` below).
set -euo pipefail
cd "$(dirname "$0")/../../.."
BACKEND=${1:?usage: fleet.sh sqlite|postgres}
N=${N:-100000}
ROBOTS=${ROBOTS:-2000}
SITES=${SITES:-20}
DUR=${DUR:-10s}
CONNS=${CONNS:-4}
PORT=${PORT:-18090}
WORKDIR=${WORKDIR:-/tmp/drawcal-fleet}
PG_URL=${PG_URL:-postgres://postgres@127.0.0.1:5432}
BIN=${BIN:-target/release/drawcal}
SEED=${SEED:-target/release/examples/fleet_seed}
BASE=http://127.0.0.1:$PORT
mkdir -p "$WORKDIR"
WORK=$(mktemp -d)
SERVER=
trap '[ -n "$SERVER" ] && kill $SERVER 2>/dev/null; wait 2>/dev/null; rm -rf "$WORK"' EXIT
[ -x "$BIN" ] && [ -x "$SEED" ] || cargo build --release --bin drawcal --example fleet_seed

if [ -z "${DB:-}" ]; then
  case $BACKEND in
    sqlite) DB=sqlite://$WORKDIR/fleet-$N.db; rm -f "$WORKDIR/fleet-$N.db"*;;
    postgres)
      DB=$PG_URL/fleet_$N
      psql -q "$PG_URL/postgres" -c "DROP DATABASE IF EXISTS fleet_$N" -c "CREATE DATABASE fleet_$N";;
    *) echo "backend: sqlite or postgres" >&2; exit 2;;
  esac
  TASKS=1; [ "$BACKEND" = postgres ] && TASKS=8
  echo "### seeding $N calibrations, $ROBOTS robots, $SITES sites ($(date -u +%FT%TZ))"
  /usr/bin/time -f "seed: %e s wall, peak RSS %M KB" "$SEED" "$DB" --calibrations $N --robots $ROBOTS --sites $SITES --tasks $TASKS
fi
case $BACKEND in
  sqlite) echo "database size: $(du -h "${DB#sqlite://}" | cut -f1)";;
  postgres) echo "database size: $(psql -tA "$DB" -c 'SELECT pg_size_pretty(pg_database_size(current_database()))')";;
esac

export KEY=dck_fleet_admin_key_0123456789abcdef0123456789ab
DRAWCAL_ADMIN_KEY=$KEY DATABASE_URL=$DB RUST_LOG=warn "$BIN" serve --listen 127.0.0.1:$PORT 2>"$WORK/server.log" &
SERVER=$!
until curl -sf $BASE/ready >/dev/null; do sleep 0.2; kill -0 $SERVER || { cat "$WORK/server.log"; exit 1; }; done
# Dashboards read with a reader key.
READER=$("$BIN" keys create --name "reader-$(date +%s%N)" --role reader --database "$DB")
echo "server: $(grep -m1 -o 'runtime_threads=[0-9]*' "$WORK/server.log" || true) load average $(cut -d' ' -f1-3 /proc/loadavg)"

# Path lists, seeded: every site, 200 robots, every month of the two years.
python3 - "$WORK" "$ROBOTS" "$SITES" <<'PY'
import random, sys
work, robots, sites = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
rnd = random.Random(7)
site = lambda: f"site-{rnd.randrange(sites):02d}"
def month():
    y, m = 2025 + rnd.randrange(2), 1 + rnd.randrange(12)
    return f"from={y}-{m:02d}-01&to={y}-{m:02d}-28"
routes = {
    "list_site": lambda: f"/calibrations?site={site()}",
    "list_site_page": lambda: f"/calibrations?site={site()}&limit=100&offset={rnd.randrange(0, 4900, 100)}",
    "list_site_line_month": lambda: f"/calibrations?site={site()}&line=L{1 + rnd.randrange(5)}&{month()}",
    "list_site_rms": lambda: f"/calibrations?site={site()}&max_test_rms_mm=0.05",
    "list_month": lambda: f"/calibrations?{month()}",
    "list_robot": lambda: f"/calibrations?robot_id={1 + rnd.randrange(robots)}",
    "accuracy": lambda: f"/robots/{1 + rnd.randrange(robots)}/accuracy",
    "accuracy_csv": lambda: f"/robots/{1 + rnd.randrange(robots)}/accuracy?format=csv",
    "csv_site_month": lambda: f"/calibrations?site={site()}&{month()}&format=csv",
    "csv_site": lambda: f"/calibrations?site={site()}&format=csv",
}
for name, make in routes.items():
    with open(f"{work}/{name}.paths", "w") as f:
        f.writelines(make() + "\n" for _ in range(200))
PY
ROUTES=${ROUTES:-list_site list_site_page list_site_line_month list_site_rms list_month list_robot accuracy accuracy_csv csv_site_month csv_site}

echo "### $BACKEND, $N calibrations: wrk -t1 -c$CONNS -d$DUR --timeout 30s per route ($(date -u +%FT%TZ))"
printf '| route | example | rows | bytes | p50 | p99 | requests/s | non-2xx |\n|---|---|---|---|---|---|---|---|\n'
for r in $ROUTES; do
  EX=$(head -1 "$WORK/$r.paths")
  # One answer of the example path: its rows and size.
  curl -sS -o "$WORK/answer" -H "authorization: Bearer $READER" "$BASE$EX"
  ROWS=$(python3 - "$WORK/answer" <<'PY'
import json, sys
t = open(sys.argv[1]).read()
try:
    j = json.loads(t)
    print(f"{len(j['items'])} of {j['total']}" if "items" in j else len(j["history"]))
except ValueError:
    print(t.count("\n") - 1)
PY
)
  OUT=$(PATHS=$WORK/$r.paths KEY=$READER wrk -t1 -c$CONNS -d$DUR --timeout 30s --latency -s tests/api/load/history.lua $BASE)
  P50=$(awk '/Latency Distribution/{f=1} f && $1=="50%"{print $2; exit}' <<<"$OUT")
  P99=$(awk '/Latency Distribution/{f=1} f && $1=="99%"{print $2; exit}' <<<"$OUT")
  RPS=$(awk '/^Requests\/sec/{print $2}' <<<"$OUT")
  BAD=$(awk '/Non-2xx/{print $5}' <<<"$OUT")
  grep -q 'Socket errors' <<<"$OUT" && BAD="${BAD:-0}, $(grep -o 'Socket errors.*' <<<"$OUT")"
  printf '| %s | `%s` | %s | %s | %s | %s | %s | %s |\n' "$r" "$EX" "$ROWS" "$(stat -c %s "$WORK/answer")" "$P50" "$P99" "$RPS" "${BAD:-0}"
done
T0=$(date +%s%N)
curl -sS -o "$WORK/all.csv" -H "authorization: Bearer $READER" "$BASE/calibrations?format=csv"
echo "the whole history as CSV (one request): $(( ($(date +%s%N) - T0) / 1000000 )) ms, $(( $(wc -l < "$WORK/all.csv") - 1 )) rows, $(stat -c %s "$WORK/all.csv") bytes"
echo "server peak RSS (VmHWM): $(awk '/VmHWM/{print $2, $3}' /proc/$SERVER/status); now (VmRSS): $(awk '/VmRSS/{print $2, $3}' /proc/$SERVER/status)"
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg)"
if [ -n "${EXPLAIN-1}" ]; then
  echo "### query plans"
  "$SEED" "$DB" --explain
fi
