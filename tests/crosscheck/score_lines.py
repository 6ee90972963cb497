#!/usr/bin/env python3
"""The aggregate lines of each set's score.txt (from the first '== ' header
on, as run_all.sh prints them), one row per set, half and binary.
Usage: score_lines.py OUT BIN [BIN...]"""
import re, sys

out, bins = sys.argv[1], sys.argv[2:]
print(f"{'set':6s} {'half':12s} {'bin':6s} {'located%':>8s} {'misn/10':>7s} {'silent%':>7s} {'ratio':>6s} {'worst':>6s} {'falseal':>8s}")
for g in range(3, 11):
    for b in bins:
        try:
            txt = open(f"{out}/{b}/gen{g}/score.txt").read()
        except OSError:
            continue
        agg = txt[txt.index("\n== ") + 1:] if "\n== " in txt else txt[txt.index("== "):]
        for blk in agg.split("== ")[1:]:
            label = blk.split(":")[0]
            f = lambda pat: (re.search(pat, blk) or [None, "-"])[1]
            v = [f(p) for p in (r"located right\s+([\d.]+)", r"misnamed / 10\s+([\d.]+)", r"silent\s+([\d.]+)",
                                r"ratio tool/oracle\s+([\d.]+)", r"worst ([\d.]+)", r"false alarms\s+(\d+ of \d+)")]
            if all(x == "-" for x in v):
                continue
            print(f"gen{g:<3d} {label:12s} {b:6s} {v[0]:>8s} {v[1]:>7s} {v[2]:>7s} {v[3]:>6s} {v[4]:>6s} {v[5]:>8s}")
