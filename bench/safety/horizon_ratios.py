"""Parts and contact steps of bench/safety/obstacle_horizon.sh's runs: per group (screen,
eval), each run's geometric mean of parts over the 28 setups against the same controller
at 0.3 s, and its largest contact steps per episode; then each evaluation run against the
results committed under docs/safety (the same seeds and episodes must give the same
numbers). usage: horizon_ratios.py OUT"""
import csv
import math
import sys
from collections import defaultdict
from pathlib import Path


SAFETY = Path(__file__).resolve().parents[2] / "docs" / "safety"
EVAL_DIRS = ("eval", "eval_extra", "eval_wide")
# evaluation run -> the committed results.csv files holding the same runs
COMMITTED = {
    "greedy": [SAFETY / d / "greedy" / "results.csv" for d in EVAL_DIRS],
    "greedy-orca-0.3": [SAFETY / d / "greedy-orca" / "results.csv" for d in EVAL_DIRS],
    "greedy-orca-0.15": [SAFETY / "obstacles" / "greedy-orca-0.15" / "results.csv"],
    "policy-0.15": [SAFETY / d / "targets" / "results.csv" for d in EVAL_DIRS],
    "policy-0.3": [SAFETY / f"{d}_before_obstacles" / "targets" / "results.csv" for d in EVAL_DIRS],
}
FIELDS = ("parts_delivered", "collisions", "collisions_robot_robot")


def rows(paths):
    """{(setup, seed): (parts, contact steps, robot-robot)} from every file that exists."""
    out = {}
    for p in paths:
        if p.exists():
            with open(p) as f:
                for r in csv.DictReader(f):
                    out[(r["setup"], r["seed"])] = tuple(float(r[k]) for k in FIELDS)
    return out


def load(path):
    """{setup: (mean parts, mean contact steps)} over the file's seeds."""
    by = defaultdict(list)
    for (setup, _), r in rows([path]).items():
        by[setup].append(r[:2])
    return {s: tuple(sum(x[i] for x in v) / len(v) for i in range(2)) for s, v in by.items()}


def against_committed(out):
    print("## eval against docs/safety\n\n| run | rows | equal to the committed |\n|---|---|---|")
    for name, paths in COMMITTED.items():
        new = rows([Path(out) / "eval" / name / "results.csv"])
        old = rows(paths)
        same = sum(1 for k, v in new.items()
                   if k in old and all(round(a, 6) == round(b, 6) for a, b in zip(old[k], v)))
        print(f"| {name} | {len(new)} | {same} |")


def main(out):
    for group in ("screen", "eval"):
        runs = {p.name: load(p / "results.csv") for p in sorted((Path(out) / group).iterdir())
                if (p / "results.csv").exists()}
        print(f"## {group}\n\n| run | parts vs 0.3 s | most contact steps per episode (setup) |\n|---|---|---|")
        for name, r in runs.items():
            family = name.rsplit("-", 1)[0]
            base = runs.get(f"{family}-0.3")
            ratio = "-"
            if base is not None and family != name:
                ratio = f"{math.exp(sum(math.log(r[s][0] / base[s][0]) for s in r) / len(r)):.4f}x"
            worst = max(r, key=lambda s: r[s][1])
            print(f"| {name} | {ratio} | {r[worst][1]:.1f} ({worst}) |")
        print()
    against_committed(out)


if __name__ == "__main__":
    main(sys.argv[1])
