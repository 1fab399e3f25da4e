#!/usr/bin/env python3
"""The cross-check table of docs/experiments/benchmarl_mappo.md: BenchMARL MAPPO runs
(`benchmarl_run.py --eval-only 50 --eval-layouts tending`, eval_tending.csv) beside our
MAPPO (untuned: results/paper/A, tuned: results/paper/AT), SMAPPO (A), greedy and random
(`tending eval`, results/paper/A/{greedy,random}), all on 6.4_2's evaluation layouts
(eval seeds 0, 1, 2 x 50 episodes, argmax), and the paper's MAPPO (Table I).

    python bench/python/benchmarl_table.py OUT.csv RUN_DIR[=LABEL] [RUN_DIR[=LABEL] ...]

Runs with the same LABEL (training seeds) make one row (default label: BenchMARL MAPPO,
stock MlpConfig).

Each cell: mean (population std) over training seeds of the mean over the 150 episodes;
scripts: std over the 3 eval seeds, as bench/experiments/table.py. "MU (paper's protocol)":
the mean over each run's last 100 training episodes (BenchMARL: episodes.csv's train rows;
ours: log.csv, as table.py's last100). Prints a markdown table and writes OUT.csv.
"""

from __future__ import annotations

import csv
import statistics
import sys
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "results" / "paper"
SETUP = "6.4_2"
PAPER_MAPPO_MU = "0.51 (0.05)"  # Table I, 6.4_2, MAPPO (shared/paper, REFERENCE.md)


def ms(xs, p):
    m = statistics.fmean(xs)
    s = statistics.pstdev(xs) if len(xs) > 1 else 0.0
    return f"{m:.{p}f} ({s:.{p}f})"


def benchmarl_run(run: Path):
    """(parts, collisions, mu, team reward) means over eval_tending.csv's policy rows;
    the same for greedy; and the mean MU of the last 100 training episodes."""
    by = defaultdict(list)
    for r in csv.DictReader(open(run / "eval_tending.csv")):
        by[r["method"]].append(tuple(float(r[k]) for k in
                                     ("parts_delivered", "collisions", "mu", "team_reward")))
    means = {m: tuple(statistics.fmean(x[i] for x in v) for i in range(4))
             for m, v in by.items()}
    train = [float(r["mu"]) for r in csv.DictReader(open(run / "episodes.csv"))
             if r["phase"] == "train"]
    return means, statistics.fmean(train[-100:]), len(train)


def ours(kind: str, model: str):
    """Per training seed: (parts, collisions, mu, team reward) over its eval results.csv
    rows of 6.4_2, and the last-100-training-episodes MU of its log.csv."""
    out = []
    for seed in sorted((PAPER / kind / SETUP / model).glob("seed*")):
        if not (seed / "eval" / "results.csv").exists():
            continue  # a run still training
        rows = [r for r in csv.DictReader(open(seed / "eval" / "results.csv"))
                if r["setup"] == SETUP]
        ev = tuple(statistics.fmean(float(r[k]) for r in rows)
                   for k in ("parts_delivered", "collisions", "mu", "team_reward"))
        log = list(csv.DictReader(open(seed / "log.csv")))
        end = int(log[-1]["episodes"])
        last = statistics.fmean(float(r["mu"]) for r in log if int(r["episodes"]) > end - 100)
        out.append((ev, last))
    return out


def script(name: str):
    rows = [r for r in csv.DictReader(open(PAPER / "A" / name / "eval" / "results.csv"))
            if r["setup"] == SETUP]
    return [tuple(float(r[k]) for k in ("parts_delivered", "collisions", "mu", "team_reward"))
            for r in rows]


def main(argv):
    if len(argv) < 2:
        raise SystemExit(__doc__)
    out = Path(argv[0])
    groups = {}
    for spec in argv[1:]:
        path, _, label = spec.partition("=")
        groups.setdefault(label or "BenchMARL MAPPO, stock MlpConfig", []).append(Path(path))
    table = []  # method, training seeds, parts, collisions, mu, team reward, mu paper proto

    all_bm = []
    for label, runs in groups.items():
        bm = [benchmarl_run(r) for r in runs]
        all_bm += bm
        pol = [b[0]["policy"] for b in bm]
        table.append([label, len(bm),
                      ms([x[0] for x in pol], 1), ms([x[1] for x in pol], 1),
                      ms([x[2] for x in pol], 2), ms([x[3] for x in pol], 1),
                      ms([b[1] for b in bm], 2)])
    bm = all_bm
    for label, kind, model in (("our MAPPO, untuned (A)", "A", "mappo"),
                               ("our MAPPO, tuned (AT, T's t7)", "AT", "mappo"),
                               ("our SMAPPO (A)", "A", "smappo")):
        o = ours(kind, model)
        ev = [x[0] for x in o]
        table.append([label, len(o), ms([x[0] for x in ev], 1), ms([x[1] for x in ev], 1),
                      ms([x[2] for x in ev], 2), ms([x[3] for x in ev], 1),
                      ms([x[1] for x in o], 2)])
    table.append(["the paper's MAPPO (Table I)", "-", "-", "-", "-", "-", PAPER_MAPPO_MU])
    for name in ("greedy", "random"):
        s = script(name)
        table.append([f"{name} (`tending eval`, std over eval seeds)", "none (scripted)",
                      ms([x[0] for x in s], 1), ms([x[1] for x in s], 1),
                      ms([x[2] for x in s], 2), ms([x[3] for x in s], 1), "-"])
    # The Python evaluation's greedy against `tending eval`'s: the same layouts if equal.
    py_greedy = statistics.fmean(b[0]["greedy"][0] for b in bm)
    rust_greedy = statistics.fmean(x[0] for x in script("greedy"))
    head = ["method", "training seeds", "parts delivered", "contact steps", "MU",
            "team reward", "MU (paper's protocol)"]
    with open(out, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(head)
        w.writerows(table)
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for row in table:
        print("| " + " | ".join(str(c) for c in row) + " |")
    print(f"\ngreedy through the Python evaluation {py_greedy:.3f} parts, `tending eval` "
          f"{rust_greedy:.3f}; BenchMARL training episodes per run: "
          f"{', '.join(str(b[2]) for b in bm)}; wrote {out}")


if __name__ == "__main__":
    main(sys.argv[1:])
