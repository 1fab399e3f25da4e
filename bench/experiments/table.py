"""Aggregate `tending eval` results.csv files into the paper's layout: per setup and model,
mean (std) over training seeds of parts delivered, collisions and MU, next to the paper's MU.

    table.py [--exp C] [--paper paper_mu.csv] [--out docs/experiments/C.md] TITLE SCALE SEEDS CSV...

One results.csv per trained model (training seed); its rows of one setup (evaluation seeds)
are averaged first. The model is the first word of the `policy` column (smappo, mappo,
greedy, random). A scripted baseline (greedy, random) has no training seeds: its cells carry
the std over evaluation seeds when there are several, '-' otherwise.

With --out, the text below the KEEP marker of an existing file (the hand-written discussion)
is kept; a file from before the marker keeps what follows its first table."""
import argparse, csv, math, os, statistics, sys
from collections import defaultdict

KEEP = "<!-- Generated above by bench/experiments/table.py; text below this line is kept on regeneration. -->"
ORDER = ["smappo", "mappo", "greedy", "greedy-orca", "matching-orca", "shipped", "random"]
# evaluated, never trained here: one evaluation, std over eval seeds
SCRIPTED = {"greedy", "greedy-orca", "matching-orca", "shipped", "random"}
# methods whose results.csv `policy` column does not name them (the shipped policy is an
# SMAPPO, greedy-ORCA a greedy): named by their directory (run.sh EXTRA=1)
BY_DIR = {"greedy-orca", "matching-orca", "shipped"}
# contact steps by kind (results.csv columns), after parts, collisions and MU
KINDS = ["collisions_robot_robot", "collisions_robot_machine", "collisions_robot_storage",
         "collisions_robot_wall"]
METRICS = ["parts_delivered", "collisions", "mu"] + KINDS
# read when present, NaN otherwise: collision events (onsets) came with issue 47
# (bench/experiments/onsets.py adds them to older evaluations); index EVENTS in a tuple
OPTIONAL = ["collision_events"]
EVENTS = len(METRICS)


def setup_key(s):
    try:
        return [int(x) for x in s.replace("_", ".").split(".")]
    except ValueError:
        return [10**9, s]


def norm_setup(s):
    k = setup_key(s)
    return f"{k[0]}.{k[1]}_{k[2]}" if len(k) == 3 and all(isinstance(x, int) for x in k) else s


def model_of(policy, path):
    for part in path.split(os.sep):
        if part in BY_DIR:
            return part
    word = (policy.split() or [""])[0].lower()
    if word:
        return word
    for part in reversed(path.split(os.sep)):
        if part in ORDER:
            return part
    sys.exit(f"{path}: empty policy column and no model in the path")


def read_eval(path, eval_seed=None):
    """-> model, {setup: [(parts, collisions, mu, contacts by kind...) per eval row]}
    (only the rows of `eval_seed` when given)"""
    try:
        rows = list(csv.DictReader(open(path)))
    except OSError as e:
        sys.exit(f"{path}: {e}")
    if not rows:
        sys.exit(f"{path}: no data rows")
    need = {"policy", "setup"} | set(METRICS)
    missing = need - set(rows[0].keys())
    if missing:
        sys.exit(f"{path}: missing column(s) {', '.join(sorted(missing))}")
    models = {model_of(r["policy"], path) for r in rows}
    if len(models) != 1:
        sys.exit(f"{path}: several policies {sorted(models)}; one model per file expected")
    per = defaultdict(list)
    for i, r in enumerate(rows, start=2):
        if eval_seed is not None and r.get("seed", "0") != str(eval_seed):
            continue
        try:
            per[r["setup"]].append(tuple(float(r[k]) for k in METRICS)
                                   + tuple(float(r.get(k) or "nan") for k in OPTIONAL))
        except ValueError as e:
            sys.exit(f"{path}:{i}: {e}")
    return models.pop(), per


def read_paper(path, exp):
    out = {}
    if not path or not exp:
        return out
    for r in csv.DictReader(open(path)):
        if r["experiment"] == exp:
            out[(norm_setup(r["setup"]), r["model"].lower())] = (float(r["mu"]), r.get("std"))
    return out


def ms(xs, p, std_ok=True):
    if any(math.isnan(x) for x in xs):
        return "-"  # an optional column some evaluation lacks
    m = statistics.fmean(xs)
    if not std_ok:
        return f"{m:.{p}f} (-)"
    s = statistics.pstdev(xs) if len(xs) > 1 else 0.0
    return f"{m:.{p}f} ({s:.{p}f})"


def kept_text(path):
    if not path or not os.path.exists(path):
        return ""
    text = open(path).read()
    if KEEP in text:
        return text.split(KEEP, 1)[1].strip("\n")
    lines, i = text.splitlines(), 0
    while i < len(lines) and not lines[i].startswith("|"):
        i += 1
    while i < len(lines) and lines[i].startswith("|"):
        i += 1
    return "\n".join(lines[i:]).strip("\n")


def last100(path):
    """A training log.csv -> (setup, model, (parts, collisions, mu)) averaged over the
    updates that cover its last 100 episodes (the paper's Table I protocol)."""
    rows = list(csv.DictReader(open(path)))
    if not rows:
        sys.exit(f"{path}: no data rows")
    end = int(rows[-1]["episodes"])
    last = [r for r in rows if int(r["episodes"]) > end - 100]
    model = next((p for p in reversed(path.split(os.sep)) if p in ORDER), None)
    if model is None:
        sys.exit(f"{path}: no model in the path")
    return rows[-1]["setup"], model, tuple(
        statistics.fmean(float(r[k]) for r in last) for k in ("parts_delivered", "collisions", "mu"))


def aggregate(files, eval_seed=None):
    """(setup, method) -> list of per-run metric tuples (training seeds), and for scripted
    methods the per-eval-row tuples (std over eval seeds)."""
    runs, scripted_rows = defaultdict(list), defaultdict(list)
    for f in files:
        model, per = read_eval(f, eval_seed)
        for setup, vals in per.items():
            if not vals:
                continue
            runs[(setup, model)].append(
                tuple(statistics.fmean(v[k] for v in vals) for k in range(len(vals[0]))))
            if model in SCRIPTED:
                scripted_rows[(setup, model)].extend(vals)
    return runs, scripted_rows


def cells_of(runs, scripted_rows, s, m, precision):
    """Formatted mean (std) cells of every metric, and the training-seed count."""
    v = runs[(s, m)]
    if m in SCRIPTED and len(v) == 1:
        rows = scripted_rows[(s, m)]
        return [ms([r[k] for r in rows], p, len(rows) > 1) for k, p in precision], "none (scripted)"
    return [ms([x[k] for x in v], p) for k, p in precision], str(len(v))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--exp", help="experiment name (A..D): paper rows and plot names")
    ap.add_argument("--paper", help="CSV experiment,setup,model,mu,std of the paper's MU")
    ap.add_argument("--out", help="write here, keeping the hand-written text below the marker")
    ap.add_argument("--eval-episodes", help="episodes per evaluation (for the note)")
    ap.add_argument("--eval-seeds", default="0", help="evaluation seeds (for the note)")
    ap.add_argument("--logs", nargs="*", default=[],
                    help="training log.csv files: the paper's protocol is their last 100 "
                         "episodes (Table I); without, it is evaluation seed 0 alone")
    ap.add_argument("title")
    ap.add_argument("scale")
    ap.add_argument("seeds")
    ap.add_argument("files", nargs="+")
    a = ap.parse_args()

    runs, scripted_rows = aggregate(a.files)
    # the paper's protocol: last 100 training episodes (A) or 50 episodes of eval seed 0
    if a.logs:
        paper_runs = defaultdict(list)
        for f in a.logs:
            # a run in flight (no .done) has no evaluation yet: its partial log must not
            # count either, or the column mixes seeds the table says it has not
            if not os.path.exists(os.path.join(os.path.dirname(os.path.realpath(f)), ".done")):
                continue
            setup, model, v = last100(f)
            paper_runs[(setup, model)].append((v[2],))
        proto = "mean over its last 100 training episodes"
    else:
        paper_runs, _ = aggregate(a.files, eval_seed=0)
        paper_runs = {k: [(x[2],) for x in v] for k, v in paper_runs.items()}
        proto = "evaluation seed 0 alone"
    paper = read_paper(a.paper, a.exp)

    n_seeds = len(a.eval_seeds.split(","))
    out = [f"# {a.title}\n"]
    out.append(
        f"Budget: {a.scale} x the paper's episodes; training seeds {a.seeds}; each cell is mean (std) "
        "over training seeds of the mean over evaluation episodes"
        + (f" ({a.eval_episodes} per setup and eval seed, eval seeds {a.eval_seeds}, argmax actions)"
           if a.eval_episodes else "")
        + ". Scripted baselines and the shipped policy are not trained here: one evaluation on "
        "the same setups, episodes and eval seeds, std over eval seeds"
        + (f" ({n_seeds})" if n_seeds > 1 else " ('-' with one)")
        + ". Collisions are contact steps per episode (robot-steps in contact), split by kind: "
        "robot-robot (r-r), robot-machine (r-m), robot-storage (r-s), robot-wall (r-w); "
        "events: collision events per episode (a robot starting to touch something, the "
        "paper's count). "
        f"MU (paper's protocol): trained models only, {proto}. "
        "paper MU: the paper's value at its full budget"
        + (f" ({tables(a.exp)})" if a.exp and tables(a.exp) else "")
        + ", '-' where it reports none.\n")
    out.append("| setup | method | training seeds | parts delivered | collisions | r-r | r-m | r-s "
               "| r-w | events | MU | MU (paper's protocol) | paper MU |")
    out.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    precision = [(0, 1), (1, 1), (3, 1), (4, 1), (5, 1), (6, 1), (EVENTS, 1), (2, 2)]
    setups = sorted({s for s, _ in runs}, key=setup_key)
    models = sorted({m for _, m in runs}, key=lambda m: (ORDER.index(m) if m in ORDER else len(ORDER), m))
    for s in setups:
        for m in models:
            if not runs.get((s, m)):
                continue
            cells, seeds = cells_of(runs, scripted_rows, s, m, precision)
            pp = paper_runs.get((s, m)) if m not in SCRIPTED else None
            pcell_ours = ms([x[0] for x in pp], 2) if pp else "-"
            pm = paper.get((norm_setup(s), m))
            pcell = "-" if pm is None else (f"{pm[0]:.2f} ({float(pm[1]):.2f})" if pm[1] else f"{pm[0]:.2f}")
            out.append(f"| {s} | {m} | {seeds} | {' | '.join(cells)} | {pcell_ours} | {pcell} |")
    if a.exp:
        e = a.exp
        out.append("")
        out.append("Plots (`tending plot`, mean over training seeds with std as error bars / bands):\n")
        out.append(f"![{e}: parts delivered]({e}_parts.png)\n\n![{e}: collisions]({e}_collisions.png)\n\n"
                   f"![{e}: MU]({e}_mu.png)\n\n![{e}: training curves]({e}_curves.png)")
    text = "\n".join(out) + "\n\n" + KEEP + "\n"
    keep = kept_text(a.out)
    if keep:
        text += "\n" + keep + "\n"
    if a.out:
        open(a.out, "w").write(text)
    else:
        sys.stdout.write(text)


def tables(exp):
    return {"A": "Table I", "B": "Table II", "C": "Table III", "D": "Table IV", "U": "Table I"}.get(
        exp, ""
    )


if __name__ == "__main__":
    main()
