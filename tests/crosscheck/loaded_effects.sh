#!/usr/bin/env bash
# The effects driven by a gravity load, on drawcal's own simulator with
# payload blocks (0 / 1.5 / 3 kg): each concealed alone at 3x the point
# noise, 15 seeds per arm (ER3A, UR5), must be named alone at its place;
# effect-free sessions with the same payloads must name nothing.
#   tests/crosscheck/loaded_effects.sh BIN
# BIN: the drawcal binary (e.g. target/release/drawcal). About 2 minutes.
set -euo pipefail
BIN=$(realpath "$1")
W=$(mktemp -d)
trap 'rm -rf "$W"' EXIT
declare -A ok tot
run() { # robot seed effect-json wanted
  echo "{\"robot\":\"$1\",\"n_poses\":150,\"seed\":$2,\"session\":{\"payload_kg\":[0,1.5,3,0,1.5,3]},\"effects\":[$3]}" > "$W/s.json"
  "$BIN" simulate --spec "$W/s.json" --out "$W/d" > /dev/null
  "$BIN" identify --robot "$W/d/robot.json" --rig "$W/d/rig.json" --poses "$W/d/poses.csv" --out "$W/r.json" > /dev/null 2>&1
  local got
  got=$(python3 -c "import json;print(' '.join(f\"{x['effect']}:{x.get('joint')}\" for x in json.load(open('$W/r.json'))['findings']))")
  local key="$1/${4:-effect-free}"
  tot[$key]=$(( ${tot[$key]:-0} + 1 ))
  if [ "$got" == "$4" ]; then ok[$key]=$(( ${ok[$key]:-0} + 1 )); else echo "$key seed $2: found '$got'"; fi
}
for robot in er3a ur5; do
  case $robot in er3a) forearm=4 ;; ur5) forearm=3 ;; esac
  for s in $(seq 200 214); do
    run $robot "$s" '{"effect":"tool_compliance","size_x_noise":3}' "tool_compliance:None"
    run $robot "$s" '{"effect":"link_bending","joint":2,"size_x_noise":3}' "link_bending:2"
    run $robot "$s" "{\"effect\":\"link_bending\",\"joint\":$forearm,\"size_x_noise\":3}" "link_bending:$forearm"
  done
  for s in $(seq 300 314); do
    for j in 2 3 5; do
      run $robot "$s" "{\"effect\":\"joint_compliance\",\"joint\":$j,\"size_x_noise\":3}" "joint_compliance:$j"
    done
    run $robot "$s" '{"effect":"base_tilt","size_x_noise":3}' "base_tilt:None"
  done
  for s in $(seq 100 129); do
    run $robot "$s" "" ""
  done
done
for k in $(printf '%s\n' "${!tot[@]}" | sort); do echo "$k: ${ok[$k]:-0}/${tot[$k]} as simulated"; done
