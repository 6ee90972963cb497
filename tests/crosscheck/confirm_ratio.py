#!/usr/bin/env python3
"""Tool/twin held-out RMS ratio (geometric mean over a set's recordings with
an effect, as the scorer's `ratio tool/oracle`) over all test poses, over
the confirmation half (every other test pose in session order, the poses
`--confirm-half` keeps from every decision) and over the gate half (the
others), for each binary's cross-check run. Aggregates only: no
per-recording line is printed (held-back halves stay blind).

Usage: confirm_ratio.py OUT BIN [BIN...]   (OUT as given to run_all.sh;
reads OUT/BIN/genN/*/report.json and */oracle/report.json)
"""
import glob, json, math, os, sys


def gmean(xs):
    xs = [x for x in xs if x and math.isfinite(x)]
    return math.exp(sum(math.log(x) for x in xs) / len(xs)) if xs else float("nan")


def rms(errs):
    return math.sqrt(sum(e[0] ** 2 + e[1] ** 2 + e[2] ** 2 for e in errs) / len(errs)) if errs else float("nan")


def subsets(rep):
    """Per-pose errors of the test poses: all, confirmation half, gate half;
    and whether the report's own marks (when present) agree."""
    test = [p for p in rep["per_pose"] if p["split"] == "test"]
    conf = test[1::2]
    gate = test[0::2]
    marked = [p for p in rep["per_pose"] if p.get("confirmation")]
    agree = None if not marked else [p["pose"] for p in marked] == [p["pose"] for p in conf]
    e = lambda ps: [p["after_mm"] for p in ps]
    return {"all": rms(e(test)), "conf": rms(e(conf)), "gate": rms(e(gate)),
            "scorer": rep["stats"]["test"]["after"]["rms_mm"], "n_test": len(test),
            "agree": agree, "stats_conf": (rep["stats"].get("confirmation") or {}).get("after", {}).get("rms_mm")}


def half_of(h):
    return "tune" if h.startswith("tune") else ("heldback" if h.startswith("heldback") else h)


def main(out, bins):
    pooled = {}
    print(f"{'set':6s} {'half':9s} {'bin':6s} {'n':>3s} {'scorer':>7s} {'all':>7s} {'gate':>7s} {'conf':>7s}"
          f"   null(all/conf)   checks")
    for g in range(3, 11):
        for b in bins:
            d = f"{out}/{b}/gen{g}"
            if not os.path.isdir(d):
                continue
            groups = {}
            for t in sorted(glob.glob(f"{d}/*/truth3.json")):
                rd = os.path.dirname(t)
                truth = json.load(open(t))
                try:
                    tool = subsets(json.load(open(f"{rd}/report.json")))
                    twin = subsets(json.load(open(f"{rd}/oracle/report.json")))
                except Exception:
                    tool = twin = None
                groups.setdefault(half_of(truth["half"]), []).append((truth["kind"], tool, twin))
            for h, rows in groups.items():
                ooc = [(t, o) for k, t, o in rows if k != "none" and t and o]
                nul = [(t, o) for k, t, o in rows if k == "none" and t and o]
                r = lambda key, rr: gmean([t[key] / o[key] for t, o in rr])
                for key in ("all", "gate", "conf"):
                    pooled.setdefault((h, b, key), []).extend(t[key] / o[key] for t, o in ooc)
                missing = sum(1 for k, t, o in rows if not (t and o))
                small = sum(1 for t, o in ooc + nul if t["n_test"] < 20)
                disagree = sum(1 for t, o in ooc + nul for x in (t, o) if x["agree"] is False)
                stats_off = sum(1 for t, o in ooc + nul for x in (t, o)
                                if x["stats_conf"] is not None and abs(x["stats_conf"] - x["conf"]) > 1e-9 * max(1, x["conf"]))
                scorer_off = sum(1 for t, o in ooc + nul for x in (t, o)
                                 if abs(x["scorer"] - x["all"]) > 1e-6 * max(1, x["all"]))
                print(f"gen{g:<3d} {h:9s} {b:6s} {len(ooc):3d} {r('scorer', ooc):7.3f} {r('all', ooc):7.3f} "
                      f"{r('gate', ooc):7.3f} {r('conf', ooc):7.3f}   {r('all', nul):6.3f}/{r('conf', nul):6.3f}"
                      f"   missing {missing} <20test {small} mark!=rule {disagree} stats!=per_pose {stats_off}"
                      f" scorer!=per_pose {scorer_off}")
    print("pooled over gen3..gen10 (geometric mean over every recording with an effect of the half):")
    for h in dict.fromkeys(k[0] for k in pooled):
        for b in bins:
            n = len(pooled.get((h, b, "all"), []))
            print(f"  {h:9s} {b:6s} {n:4d}  all {gmean(pooled[(h, b, 'all')]):.3f}  gate {gmean(pooled[(h, b, 'gate')]):.3f}"
                  f"  conf {gmean(pooled[(h, b, 'conf')]):.3f}")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:])
