"""What limits issue 10's parts target, setup by setup: the best script, the bundled policy
and the target as shares of the parts bound (`tending bound`, sim::parts_bound: the most
parts any controller moving at K_speed could deliver on the same layouts), and how far the
policy is from the target. The same numbers as docs/safety/limits.png, as a table.

A setup is "balanced" when the bound is within 1.2x the best script: there the target asks
for nearly every part the layout allows. Elsewhere (few robots, or few storages for the
fleet) the bound is loose, because it ignores the storage queues and the robots' time.
usage: limits_table.py EVAL_DIR... [--compare NAME=RESULTS_CSV]... > limits.md
(each EVAL_DIR holds targets/, greedy/, greedy-orca/ and bound.csv; each --compare adds a
column NAME / best script, e.g. matching-ORCA or greedy-ORCA at another margin)
"""
import csv
import statistics
import sys

TARGET = 1.1
BALANCED = 1.2  # bound / best script at most this: the target is near the ceiling


def load(path, column="parts_delivered"):
    """{setup: mean of `column` over seeds} of one CSV."""
    by = {}
    with open(path) as f:
        for r in csv.DictReader(f):
            by.setdefault(r["setup"], []).append(float(r[column]))
    return {s: statistics.mean(v) for s, v in by.items()}


def key(setup):
    return [int(x) for x in setup.replace("_", ".").split(".")]


def main(args):
    compare = []  # (name, {setup: parts})
    while "--compare" in args:
        i = args.index("--compare")
        name, path = args[i + 1].split("=", 1)
        compare.append((name, load(path)))
        args = args[:i] + args[i + 2:]
    pol, greedy, orca, bound = {}, {}, {}, {}
    for d in args:
        pol.update(load(f"{d}/targets/results.csv"))
        greedy.update(load(f"{d}/greedy/results.csv"))
        orca.update(load(f"{d}/greedy-orca/results.csv"))
        bound.update(load(f"{d}/bound.csv", "parts_bound"))
    head = "| setup | class | best script / bound | policy / bound | 1.1x / bound | ceiling (bound / best script) | policy / best script | parts per episode short of 1.1x |"
    for name, _ in compare:
        head += f" {name} / best script |"
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    counts = {}
    for s in sorted(pol, key=key):
        best = max(greedy[s], orca[s])
        b = bound[s]
        ceiling = b / best
        cls = "balanced" if ceiling <= BALANCED else "loose bound"
        short = TARGET * best - pol[s]
        met = short <= 0
        counts.setdefault(cls, [0, 0])
        counts[cls][0] += met
        counts[cls][1] += 1
        row = (f"| {s} | {cls} | {best / b:.3f} | {pol[s] / b:.3f} | {TARGET * best / b:.3f} | "
               f"{ceiling:.2f} | {pol[s] / best:.3f} | {'met' if met else f'{short:.1f}'} |")
        for _, parts in compare:
            row += f" {parts[s] / best:.3f} |" if s in parts else " - |"
        print(row)
    print()
    for cls, (met, n) in counts.items():
        print(f"- {cls}: 1.1x met on {met} of {n}")


if __name__ == "__main__":
    main(sys.argv[1:])
