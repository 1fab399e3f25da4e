#!/usr/bin/env python3
"""Collision events (onsets) for the campaign's committed evaluations (issue 47).

The paper counts collisions as events; `tending eval` gave contact steps only until it
gained the `collision_events` column. Every results.csv under results/paper without that
column is evaluated again with the same checkpoint (found by checkpoint.sha256, or the
script named by its policy column / directory), setups, eval seeds and episode count.
Evaluation is deterministic, so every column the old file has must come back equal: the
new file replaces the old one only then, and a mismatch is reported and left alone.

    python3 bench/experiments/onsets.py [--runs results/paper] [--tending target/release/tending]

Idempotent: files that already have the column are skipped, so it can run again after the
queue adds evaluations. Progress goes to stdout, one line per file.
"""

import argparse
import csv
import glob
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile

SCRIPTS = {"greedy", "greedy-orca", "matching-orca", "random"}
SHIPPED = "policy/pretrained/smappo_6.4_2.safetensors"


def sha256(path):
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for b in iter(lambda: f.read(1 << 20), b""):
            h.update(b)
    return h.hexdigest()


def checkpoints(runs):
    """sha256 -> a checkpoint file with that content (every policy under runs, the shipped)."""
    out = {}
    for p in glob.glob(f"{runs}/**/*.safetensors", recursive=True) + [SHIPPED]:
        if "trainer_state" not in os.path.basename(p):
            out.setdefault(sha256(p), p)
    return out


def method_args(eval_dir, rows, by_hash):
    """The `tending eval` arguments naming the controller of this results.csv, or an error."""
    name = os.path.basename(os.path.dirname(eval_dir))
    policy = rows[0]["policy"]
    if name in SCRIPTS and policy.split()[0] in SCRIPTS | {"greedy"}:
        return ["--policy", name], None
    sum_file = os.path.join(eval_dir, "checkpoint.sha256")
    if not os.path.exists(sum_file):
        return None, f"no checkpoint.sha256 for policy {policy!r}"
    want = open(sum_file).read().strip()
    ck = by_hash.get(want)
    if ck is None:
        return None, f"no checkpoint with hash {want[:12]}"
    return ["--checkpoint", ck], None


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", default="results/paper")
    ap.add_argument("--tending", default="target/release/tending")
    a = ap.parse_args()
    files = sorted(glob.glob(f"{a.runs}/**/eval/results.csv", recursive=True))
    todo = []
    for f in files:
        rows = list(csv.DictReader(open(f)))
        if rows and "collision_events" not in rows[0]:
            todo.append((f, rows))
    # trained models first (the verdicts need them), the scripts after: whole-floor
    # matching on C's largest setups takes most of an hour here
    todo.sort(key=lambda t: os.path.basename(os.path.dirname(os.path.dirname(t[0]))) in SCRIPTS
              | {"shipped"})
    print(f"{len(todo)} of {len(files)} evaluations lack collision events", flush=True)
    by_hash = checkpoints(a.runs) if todo else {}
    bad = 0
    for i, (f, rows) in enumerate(todo, 1):
        d = os.path.dirname(f)
        args, err = method_args(d, rows, by_hash)
        if err:
            print(f"[{i}/{len(todo)}] {f}: skipped, {err}", flush=True)
            bad += 1
            continue
        setups = ",".join(dict.fromkeys(r["setup"] for r in rows))
        seeds = ",".join(dict.fromkeys(r["seed"] for r in rows))
        episodes = {r["episodes"] for r in rows}
        if len(episodes) != 1:
            print(f"[{i}/{len(todo)}] {f}: skipped, mixed episode counts {episodes}", flush=True)
            bad += 1
            continue
        with tempfile.TemporaryDirectory() as tmp:
            cmd = [a.tending, "eval", *args, "--setups", setups, "--seeds", seeds,
                   "--episodes", episodes.pop(), "--out", tmp]
            r = subprocess.run(cmd, capture_output=True, text=True)
            if r.returncode != 0:
                print(f"[{i}/{len(todo)}] {f}: eval failed: {r.stderr.strip()[-300:]}", flush=True)
                bad += 1
                continue
            new = list(csv.DictReader(open(os.path.join(tmp, "results.csv"))))
            same = len(new) == len(rows) and all(
                o[k] == n[k] for o, n in zip(rows, new) for k in o if k != "policy")
            if not same:
                print(f"[{i}/{len(todo)}] {f}: NOT replaced: the new evaluation differs", flush=True)
                bad += 1
                continue
            # keep the committed policy label (it names the file the campaign evaluated)
            with open(f, "w", newline="") as w:
                out = csv.DictWriter(w, fieldnames=list(new[0].keys()), lineterminator="\n")
                out.writeheader()
                for o, n in zip(rows, new):
                    out.writerow({**n, "policy": o["policy"]})
            shutil.copy(os.path.join(tmp, "results.md"), os.path.join(d, "results.md"))
        ev = sum(float(n["collision_events"]) for n in new) / len(new)
        print(f"[{i}/{len(todo)}] {f}: {ev:.1f} collision events per episode (mean of rows)",
              flush=True)
    print(f"done: {len(todo) - bad} updated, {bad} not", flush=True)
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
