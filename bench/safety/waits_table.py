"""The table of docs/RESULTS.md 7.15 from bench/safety/machine_waits.sh's outputs.

For each setup: the policy's parts, what 1.1x the best script needs, the parts bound, the
ready-part steps per machine per episode by class (machine_waits.rs), and the parts the
policy would deliver if every ready-part step after a machine's first pick were served at
once (each prep_steps idle steps of a machine are one part: an optimistic estimate, since
the robots that would serve them still have to carry), with the share of those steps a
better controller would have to remove to reach 1.1x.
Usage: python3 bench/safety/waits_table.py DIR
"""
import collections
import csv
import glob
import re
import sys

PREP_STEPS = 20
DOCS = "docs/safety"
ORDER = ("2.2_2 4.2_2 6.4_2 12.8_4 18.12_6 24.16_8 30.20_10 36.24_12 42.28_14 100.16_2 "
         "3.3_1 8.6_3 10.4_2 20.10_4 50.20_5 75.30_10 2.8_1 3.1_1 5.10_2 16.4_1 30.6_1 "
         "40.40_2 60.12_3 64.32_16 80.40_4 90.20_3 100.8_1 100.50_10").split()


def mean(xs):
    return sum(xs) / len(xs)


def main(out):
    script = collections.defaultdict(lambda: collections.defaultdict(list))
    bound = collections.defaultdict(list)
    for d in ("eval", "eval_extra", "eval_wide"):
        for pol in ("greedy", "greedy-orca"):
            for r in csv.DictReader(open(f"{DOCS}/{d}/{pol}/results.csv")):
                script[r["setup"]][pol].append(float(r["parts_delivered"]))
        for r in csv.DictReader(open(f"{DOCS}/{d}/bound.csv")):
            bound[r["setup"]].append(float(r["parts_bound"]))
    print("| setup | policy parts | 1.1x best script | bound | ready-part steps per machine "
          "per episode: first pick / at box / en route / no robot free | policy + every later "
          "wait served at once | later waits to remove for 1.1x |")
    print("|---|---|---|---|---|---|---|")
    met = reachable = 0
    for s in ORDER:
        rows = []
        for f in sorted(glob.glob(f"{out}/{s}.*.txt")):
            t = open(f).read()
            parts = float(re.search(r"parts ([\d.]+)", t).group(1))
            waits = re.search(r"first ([\d.]+), at-box ([\d.]+), en-route ([\d.]+), "
                              r"none-free ([\d.]+)", t).groups()
            rows.append([parts] + [float(w) for w in waits])
        if not rows:
            continue
        parts, first, at_box, en_route, none_free = (mean(c) for c in zip(*rows))
        machines = int(s.split(".")[1].split("_")[0])
        best = max(mean(v) for v in script[s].values())
        need = 1.1 * best
        later = machines * (at_box + en_route + none_free) / PREP_STEPS
        if parts >= need:
            verdict = "met"
            met += 1
        elif parts + later >= need:
            verdict = f"{100 * (need - parts) / later:.0f} %"
            reachable += 1
        else:
            verdict = "all would not do"
        print(f"| {s} | {parts:.1f} | {need:.1f} | {mean(bound[s]):.1f} | {first:.1f} / "
              f"{at_box:.1f} / {en_route:.1f} / {none_free:.1f} | {parts + later:.1f} | "
              f"{verdict} |")
    print(f"\n1.1x met on {met} setups; within reach of removing later waits on {reachable}; "
          f"out of reach of it on {len(ORDER) - met - reachable}.")


if __name__ == "__main__":
    main(sys.argv[1])
