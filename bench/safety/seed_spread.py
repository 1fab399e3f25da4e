"""How firm issue 10's parts target is: the bundled policy's parts over the best script's,
per evaluation seed, from the results.csv files `bench/safety/eval_all.sh targets` writes.

Every seed's 50 episodes are the same layouts for the policy and the scripts, so each seed
gives one paired ratio. The best script is the one with more parts over all seeds (as in the
targets table). A setup whose every seed is at 1.1x or more holds the target firmly; one whose
seeds straddle 1.1 is within the noise of 3 x 50 episodes.
usage: seed_spread.py EVAL_DIR... > seed_spread.md  (each EVAL_DIR holds targets/, greedy/,
greedy-orca/)
"""
import csv
import statistics
import sys

TARGET = 1.1


def load(path):
    """{(setup, seed): mean parts delivered} of one results.csv."""
    with open(path) as f:
        return {(r["setup"], int(r["seed"])): float(r["parts_delivered"]) for r in csv.DictReader(f)}


def main(dirs):
    pol, greedy, orca = {}, {}, {}
    for d in dirs:
        pol.update(load(f"{d}/targets/results.csv"))
        greedy.update(load(f"{d}/greedy/results.csv"))
        orca.update(load(f"{d}/greedy-orca/results.csv"))
    rows = []
    for setup in sorted({s for s, _ in pol}):
        seeds = sorted(k for s, k in pol if s == setup)
        mean = lambda d: statistics.mean(d[(setup, k)] for k in seeds)
        best, name = (greedy, "greedy") if mean(greedy) >= mean(orca) else (orca, "greedy-orca")
        per_seed = [pol[(setup, k)] / best[(setup, k)] for k in seeds]
        rows.append((mean(pol) / mean(best), setup, name, per_seed))
    firm = sum(min(r[3]) >= TARGET for r in rows)
    met = sum(r[0] >= TARGET for r in rows)
    print("| setup | best script | policy / best script | per seed (0, 1, 2) | every seed at 1.1x |")
    print("|---|---|---|---|---|")
    for overall, setup, name, per_seed in sorted(rows, reverse=True):
        seeds = ", ".join(f"{x:.3f}" for x in per_seed)
        print(f"| {setup} | {name} | {overall:.3f} | {seeds} | {'yes' if min(per_seed) >= TARGET else 'no'} |")
    print()
    print(f"1.1x over all seeds: {met} of {len(rows)}; at every seed: {firm} of {len(rows)}.")


if __name__ == "__main__":
    main(sys.argv[1:])
