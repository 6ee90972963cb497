#!/usr/bin/env bash
# Schema-driven run of openapi.yaml against a live `drawcal serve` (issue 21,
# item 6): schemathesis with every check, positive and negative data, an
# admin key. Not part of .ci/run (it needs pip; about 50 s with the
# defaults on two cores, see docs/SERVICE.md).
#
#   tests/api/schemathesis.sh [extra schemathesis arguments]
#
# Environment: DRAWCAL_BIN (default: target/debug/drawcal, built if absent),
# SCHEMATHESIS (default: schemathesis on PATH, else installed into a venv
# under target/schemathesis-venv), PORT (default 18089), MAX_EXAMPLES
# (default 30 per operation), SEED (default 1).
# Exits non-zero on any failure of the run.
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/../.." && pwd)
cd "$ROOT"
PORT=${PORT:-18089}
BASE=http://127.0.0.1:$PORT
MAX_EXAMPLES=${MAX_EXAMPLES:-30}
SEED=${SEED:-1}

BIN=${DRAWCAL_BIN:-$ROOT/target/debug/drawcal}
if [ ! -x "$BIN" ]; then
    cargo build --bin drawcal
fi

if [ -n "${SCHEMATHESIS:-}" ]; then
    ST=$SCHEMATHESIS
elif command -v schemathesis >/dev/null; then
    ST=schemathesis
else
    VENV=$ROOT/target/schemathesis-venv
    if [ ! -x "$VENV/bin/schemathesis" ]; then
        python3 -m venv "$VENV"
        "$VENV/bin/pip" install -q 'schemathesis>=4,<5'
    fi
    ST=$VENV/bin/schemathesis
fi

WORK=$(mktemp -d)
SERVER_PID=
cleanup() {
    if [ -n "$SERVER_PID" ]; then
        kill "$SERVER_PID" 2>/dev/null || true
        wait "$SERVER_PID" 2>/dev/null || true
    fi
    rm -rf "$WORK"
}
trap cleanup EXIT

DB=sqlite://$WORK/drawcal.db
KEY=$("$BIN" keys create --name schemathesis --role admin --database "$DB")
# Key 2: the one POST /keys/{id}/revoke is run on (schemathesis.toml).
"$BIN" keys create --name revoked-by-schemathesis --role reader --database "$DB" >/dev/null

# The rate limits are raised: a schema-driven run submits hundreds of
# uploads and jobs a minute from one key, and a 429 would hide what the
# handler makes of the request. The limits themselves are tested in
# tests/api/limits.rs.
"$BIN" serve --listen "127.0.0.1:$PORT" --database "$DB" \
    --max-uploads-per-minute 1000000 --max-jobs-per-minute 1000000 \
    --max-queued-jobs 1000000 \
    2>"$WORK/serve.log" &
SERVER_PID=$!
for _ in $(seq 1 100); do
    curl -sf "$BASE/ready" >/dev/null && break
    sleep 0.1
done
curl -sf "$BASE/ready" >/dev/null || { cat "$WORK/serve.log"; exit 1; }

# Seed: a model, robot, rig, session with poses and one calibration,
# activated, so that the routes with an id have something to find
# (ids 1) and /compensate something to compensate with.
D=tests/data/er3a_paper_like
post() {
    curl -sS --fail-with-body -X POST -H "Authorization: Bearer $KEY" \
        -H 'content-type: application/json' "$@" >/dev/null
}
post "$BASE/models" --data-binary @$D/robot.json
post "$BASE/robots" -d '{"serial_number": "ER3A-0001", "model_id": 1, "site": "plant-1"}'
post "$BASE/rigs" --data-binary @$D/rig.json
post "$BASE/sessions" -d '{"robot_id": 1, "rig_id": 1, "name": "seed"}'
curl -sS --fail-with-body -X POST -H "Authorization: Bearer $KEY" \
    -H 'content-type: text/csv' --data-binary @$D/poses.csv \
    "$BASE/sessions/1/poses" >/dev/null
post "$BASE/sessions/1/jobs"
for _ in $(seq 1 600); do
    curl -sS -H "Authorization: Bearer $KEY" "$BASE/jobs/1" |
        grep -Eq '"state":"(succeeded|failed|cancelled)"' && break
    sleep 0.5
done
curl -sS -H "Authorization: Bearer $KEY" "$BASE/jobs/1" | grep -q '"state":"succeeded"' ||
    { echo "seed job did not succeed" >&2; exit 1; }
post "$BASE/robots/1/activate" -d '{"calibration_id": 1, "reason": "seed"}'

# Every check is on by default (the config file turns one off for two
# routes; object_level_authorization needs two users and does not run).
START=$(date +%s)
set +e
SCHEMATHESIS_HOOKS=tests/api/schemathesis_hooks.py \
"$ST" --config-file tests/api/schemathesis.toml run openapi.yaml --url "$BASE" \
    -H "Authorization: Bearer $KEY" \
    --mode all \
    --max-examples "$MAX_EXAMPLES" --seed "$SEED" \
    --generation-database none \
    --report junit --report-dir "$WORK/report" \
    --no-color "$@"
RC=$?
set -e
echo "schemathesis: exit $RC after $(($(date +%s) - START)) s"
exit $RC
