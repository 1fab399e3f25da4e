"""Aggregate `tending eval` results.csv files (one per trained model) into the paper's
layout: per setup and model, mean (std) over training seeds of parts, collisions, MU."""
import csv, statistics, sys
from collections import defaultdict

title, scale, seeds, files = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4:]
rows = defaultdict(list)  # (setup, model) -> [(parts, collisions, mu)]
for f in files:
    model = "smappo" if "/smappo/" in f else "mappo"
    for r in csv.DictReader(open(f)):
        rows[(r["setup"], model)].append(
            (float(r["parts_delivered"]), float(r["collisions"]), float(r["mu"])))

def ms(xs, p):
    m = statistics.fmean(xs)
    s = statistics.pstdev(xs) if len(xs) > 1 else 0.0
    return f"{m:.{p}f} ({s:.{p}f})"

print(f"# {title}\n")
print(f"Budget: {scale} x the paper's episodes; training seeds {seeds}; each cell is mean (std) "
      "over training seeds of the mean over evaluation episodes.\n")
print("| setup | model | seeds | parts delivered | collisions | MU |")
print("|---|---|---|---|---|---|")
setups = sorted({s for s, _ in rows}, key=lambda s: [int(x) for x in s.replace('_', '.').split('.')])
for s in setups:
    for m in ("smappo", "mappo"):
        v = rows.get((s, m))
        if not v:
            continue
        print(f"| {s} | {m} | {len(v)} | {ms([x[0] for x in v], 1)} | {ms([x[1] for x in v], 1)} | {ms([x[2] for x in v], 2)} |")
