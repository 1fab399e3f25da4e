#!/usr/bin/env python3
"""Learning curves of `benchmarl_run.py` runs: parts delivered per episode against frames,
training episodes (mean per iteration) and evaluation episodes (argmax, mean per
evaluation), with the greedy script's reference episodes as a horizontal line.

    python bench/python/benchmarl_plot.py OUT.png RUN_DIR[=LABEL] [RUN_DIR[=LABEL] ...]
        [--ours LOG.csv[=LABEL] ...] [--hline VALUE=LABEL ...] [--smooth FRAMES] [--title T]

Each RUN_DIR is a `--out` directory of benchmarl_run.py (episodes.csv, iterations.csv).
Runs given the same LABEL (e.g. training seeds) are drawn as their mean. ``--ours`` adds a
`tending train` log.csv (one row per update: parts_delivered of its episodes against
episodes x 200 frames), same-label logs averaged likewise, so our trainer's curve shares
the frame axis. ``--hline`` draws a reference level (e.g. an evaluation table's figure).
"""

from __future__ import annotations

import argparse
import csv
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


def read_ours(log: Path, episode_steps: int = 200):
    """[(frames, parts per episode)] of a `tending train` log.csv (one row per update)."""
    with open(log) as f:
        return [(int(r["episodes"]) * episode_steps, float(r["parts_delivered"]))
                for r in csv.DictReader(f)]


def smooth(series, frames):
    """Mean over the points of the last `frames` frames (at least the point itself)."""
    if not series:
        return []
    step = series[1][0] - series[0][0] if len(series) > 1 else frames
    w = max(1, round(frames / step))
    return [(series[i][0], sum(p for _, p in series[max(0, i - w + 1):i + 1])
             / len(series[max(0, i - w + 1):i + 1])) for i in range(len(series))]


def mean_over(runs):
    """Pointwise mean of several [(frames, y)] series over the frames all of them have."""
    if len(runs) == 1:
        return runs[0]
    common = set.intersection(*(set(f for f, _ in r) for r in runs))
    d = [dict(r) for r in runs]
    return [(f, sum(x[f] for x in d) / len(d)) for f in sorted(common)]


def groups(specs):
    """{label: [path, ...]} in first-seen order."""
    out = {}
    for spec in specs:
        path, _, label = spec.partition("=")
        out.setdefault(label or Path(path).name, []).append(Path(path))
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("out", type=Path)
    p.add_argument("runs", nargs="+", metavar="RUN_DIR[=LABEL]")
    p.add_argument("--ours", action="append", default=[], metavar="LOG.csv[=LABEL]")
    p.add_argument("--hline", action="append", default=[], metavar="VALUE=LABEL")
    p.add_argument("--smooth", type=int, default=6400,
                   help="training curves: mean over the last this many frames")
    p.add_argument("--title", default="BenchMARL MAPPO on tending 6.4_2 (one seed)")
    args = p.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5.5))
    greedy = None
    i = 0
    for label, paths in groups(args.runs).items():
        read_all = [read(run) for run in paths]
        train = mean_over([smooth(r[0], args.smooth) for r in read_all if r[0]] or [[]])
        ev = mean_over([r[1] for r in read_all if r[1]] or [[]])
        gs = [r[2] for r in read_all if r[2] is not None]
        greedy = sum(gs) / len(gs) if gs else greedy
        wall = sum(r[3] for r in read_all) / len(read_all)
        n = f", mean of {len(paths)} seeds" if len(paths) > 1 else ""
        color = f"C{i}"
        i += 1
        if train:
            ax.plot([f for f, _ in train], [y for _, y in train], color=color, alpha=0.6,
                    lw=1.5, label=f"{label}: training episodes, mean of the last "
                                  f"{args.smooth:,} frames ({wall / 60:.0f} min{n})")
        if ev:
            ax.plot([f for f, _ in ev], [y for _, y in ev], "o-", color=color, lw=2, ms=3,
                    label=f"{label}: evaluation (argmax, 10 episodes{n})")
    for label, paths in groups(args.ours).items():
        curve = mean_over([smooth(read_ours(log), args.smooth) for log in paths])
        n = f", mean of {len(paths)} seeds" if len(paths) > 1 else ""
        ax.plot([f for f, _ in curve], [y for _, y in curve], color=f"C{i}", lw=1.5,
                label=f"{label}: training episodes, mean of the last {args.smooth:,} "
                      f"frames{n}")
        i += 1
    if greedy is not None:
        ax.axhline(greedy, color="k", ls="--", lw=1,
                   label=f"greedy script ({greedy:.1f}, the runs' reference episodes)")
    for j, spec in enumerate(args.hline):
        value, _, label = spec.partition("=")
        ax.axhline(float(value), color=f"C{i + j}", ls=":", lw=1.2,
                   label=f"{label} ({float(value):.1f})")
    ax.set_xlabel("frames (env steps collected)")
    ax.set_ylabel("parts delivered per episode")
    ax.set_title(args.title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=1)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
