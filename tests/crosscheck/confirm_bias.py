#!/usr/bin/env python3
"""Aggregates only (no per-recording line): over each set's half, how many
recordings' findings differ between two binaries, whether their effect-free
twins' reports agree, and the difference in differences of the tool/twin
ratio between the gate and confirmation halves:
  DiD = gmean over recordings of (gate/conf ratio, binary B) / (gate/conf, binary A)
which, under B's `--confirm-half`, estimates how much lower (optimistic)
B's held-out figure is on the poses its gates read than on poses they did
not (net of the two halves' own difference, which A treats alike).
Usage: confirm_bias.py OUT A B"""
import glob, json, math, os, sys
sys.path.insert(0, os.path.dirname(__file__))
from confirm_ratio import subsets, half_of

out, A, B = sys.argv[1:4]
tot = {"n": 0, "logs": [], "logs_all_conf": []}
print(f"{'set':6s} {'half':9s} {'n':>3s} {'findings differ':>15s} {'twins differ':>12s} {'DiD gate/conf':>13s}")
for g in range(3, 11):
    groups = {}
    for t in sorted(glob.glob(f"{out}/{A}/gen{g}/*/truth3.json")):
        name = os.path.basename(os.path.dirname(t))
        truth = json.load(open(t))
        if truth["kind"] == "none":
            continue
        try:
            ra, rb = (json.load(open(f"{out}/{x}/gen{g}/{name}/report.json")) for x in (A, B))
            oa, ob = (json.load(open(f"{out}/{x}/gen{g}/{name}/oracle/report.json")) for x in (A, B))
        except Exception:
            continue
        groups.setdefault(half_of(truth["half"]), []).append((ra, rb, oa, ob))
    for h, rows in groups.items():
        fd = sum(1 for ra, rb, _, _ in rows if [(f["effect"], f.get("joint"), f.get("sensor")) for f in ra["findings"]]
                 != [(f["effect"], f.get("joint"), f.get("sensor")) for f in rb["findings"]])
        td = sum(1 for _, _, oa, ob in rows if oa["stats"]["test"]["after"]["rms_mm"] != ob["stats"]["test"]["after"]["rms_mm"])
        logs = []
        for ra, rb, oa, ob in rows:
            sa, sb, soa, sob = map(subsets, (ra, rb, oa, ob))
            ga = (sa["gate"] / soa["gate"]) / (sa["conf"] / soa["conf"])
            gb = (sb["gate"] / sob["gate"]) / (sb["conf"] / sob["conf"])
            logs.append(math.log(gb / ga))
        tot["logs"] += logs
        tot["n"] += len(rows)
        print(f"gen{g:<3d} {h:9s} {len(rows):3d} {fd:15d} {td:12d} {math.exp(sum(logs) / len(logs)):13.3f}")
m = sum(tot["logs"]) / len(tot["logs"])
sd = math.sqrt(sum((x - m) ** 2 for x in tot["logs"]) / (len(tot["logs"]) - 1))
print(f"all sets, {tot['n']} recordings with an effect: DiD {math.exp(m):.3f} "
      f"(log mean {m:+.4f} +- {sd / math.sqrt(len(tot['logs'])):.4f} s.e.)")
