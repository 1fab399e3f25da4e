#!/usr/bin/env python3
"""Learning curves of `benchmarl_run.py` runs: parts delivered per episode against frames,
training episodes (mean per iteration) and evaluation episodes (argmax, mean per
evaluation), with the greedy script's reference episodes as a horizontal line.

    python bench/python/benchmarl_plot.py OUT.png RUN_DIR[=LABEL] [RUN_DIR[=LABEL] ...]

Each RUN_DIR is a `--out` directory of benchmarl_run.py (episodes.csv, iterations.csv).
"""

from __future__ import annotations

import csv
import sys
from collections import defaultdict
from pathlib import Path


def read(run: Path):
    """(train: [(frames, mean parts)], eval: [(frames, mean parts)], greedy mean or None,
    wall seconds at the last iteration)."""
    by = {"train": defaultdict(list), "eval": defaultdict(list), "greedy": defaultdict(list)}
    with open(run / "episodes.csv") as f:
        for r in csv.DictReader(f):
            by[r["phase"]][int(r["frames"])].append(float(r["parts_delivered"]))
    mean = lambda xs: sum(xs) / len(xs)  # noqa: E731
    series = {k: sorted((fr, mean(v)) for fr, v in d.items()) for k, d in by.items()}
    greedy = [p for _, p in series["greedy"]]
    with open(run / "iterations.csv") as f:
        its = list(csv.DictReader(f))
    wall = float(its[-1]["wall_s"]) if its else 0.0
    return series["train"], series["eval"], (mean(greedy) if greedy else None), wall


def main(argv):
    if len(argv) < 2:
        raise SystemExit(__doc__)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out, runs = Path(argv[0]), argv[1:]
    fig, ax = plt.subplots(figsize=(8, 4.5))
    greedy = None
    for i, spec in enumerate(runs):
        path, _, label = spec.partition("=")
        run = Path(path)
        label = label or run.name
        train, ev, g, wall = read(run)
        greedy = g if g is not None else greedy
        color = f"C{i}"
        if train:
            # Smoothed over the iterations of the last ~6,400 frames (32 episodes), so runs
            # of 4 and of 32 envs per iteration show alike.
            step = train[1][0] - train[0][0] if len(train) > 1 else 6400
            w = max(1, round(6400 / step))
            smooth = [sum(p for _, p in train[max(0, i - w + 1):i + 1]) / len(train[max(0, i - w + 1):i + 1])
                      for i in range(len(train))]
            ax.plot([f for f, _ in train], smooth, color=color, alpha=0.5, lw=1.2,
                    label=f"{label}: training episodes, mean of the last 6,400 frames "
                          f"({wall / 60:.0f} min)")
        if ev:
            ax.plot([f for f, _ in ev], [p for _, p in ev], "o-", color=color, lw=2,
                    label=f"{label}: evaluation (argmax)")
    if greedy is not None:
        ax.axhline(greedy, color="k", ls="--", lw=1, label=f"greedy script ({greedy:.1f})")
    ax.set_xlabel("frames (env steps collected)")
    ax.set_ylabel("parts delivered per episode")
    ax.set_title("BenchMARL MAPPO on tending 6.4_2 (one seed)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


if __name__ == "__main__":
    main(sys.argv[1:])
