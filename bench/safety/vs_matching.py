#!/usr/bin/env python3
"""The bundled policy against the scripts including matching-ORCA (docs/RESULTS.md 7.8):
parts / contact steps per episode for greedy-ORCA, matching-ORCA (the target planner
always asking for the "matched" entry, policy/pretrained/matching_orca.safetensors) and
the bundled policy, and the policy's parts over the better script's, its contacts against
the script with fewer.

Usage: vs_matching.py MATCHING_DIR EVAL_DIR...  (EVAL_DIR/{greedy-orca,targets}/results.csv,
MATCHING_DIR/results.csv; `tending eval --out` layouts). Prints Markdown. Standard
library only."""
import csv
import sys
from collections import defaultdict
from pathlib import Path
from statistics import mean


def read(path):
    rows = defaultdict(list)  # setup -> rows
    with open(path) as fh:
        for r in csv.DictReader(fh):
            rows[r["setup"]].append(r)
    return rows


def setup_key(s):
    n, rest = s.split(".", 1)
    m, k = rest.split("_")
    return (int(n), int(m), int(k))


def main(matching_dir, eval_dirs):
    matching = read(Path(matching_dir) / "results.csv")
    script, policy = {}, {}
    for d in eval_dirs:
        script.update(read(Path(d) / "greedy-orca" / "results.csv"))
        policy.update(read(Path(d) / "targets" / "results.csv"))

    def m(rows, col):
        return mean(float(r[col]) for r in rows)

    print("| setup | greedy-ORCA | matching-ORCA | bundled policy | policy / better script "
          "| policy contacts <= fewer script's | matching-ORCA / greedy-ORCA |")
    print("|---|---|---|---|---|---|---|")
    wins = dict(parts=0, contacts=0, both=0, n=0, match_parts=0)
    for s in sorted(set(matching) & set(script) & set(policy), key=setup_key):
        g, a, p = script[s], matching[s], policy[s]
        gp, ap, pp = (m(x, "parts_delivered") for x in (g, a, p))
        gc, ac, pc = (m(x, "collisions") for x in (g, a, p))
        ratio = pp / max(gp, ap)
        ok_c = pc <= min(gc, ac) + 1e-9
        wins["n"] += 1
        wins["parts"] += ratio >= 1.0
        wins["contacts"] += ok_c
        wins["both"] += ratio >= 1.0 and ok_c
        wins["match_parts"] += ap >= gp
        print(f"| {s} | {gp:.1f} / {gc:.1f} | {ap:.1f} / {ac:.1f} | {pp:.1f} / {pc:.1f} "
              f"| {ratio:.2f} | {'yes' if ok_c else '**no**'} | {ap / gp:.2f} |")
    print()
    print(f"Bundled policy, {wins['n']} setups: parts at least the better script's on "
          f"{wins['parts']}, contacts at most the fewer script's on {wins['contacts']}, "
          f"both on {wins['both']}. matching-ORCA delivers at least greedy-ORCA's parts on "
          f"{wins['match_parts']}.")


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2:])
