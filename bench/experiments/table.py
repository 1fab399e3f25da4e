"""Aggregate `tending eval` results.csv files into the paper's layout: per setup and model,
mean (std) over training seeds of parts delivered, collisions and MU, next to the paper's MU.

    table.py [--exp C] [--paper paper_mu.csv] [--out docs/experiments/C.md] TITLE SCALE SEEDS CSV...

One results.csv per trained model (training seed); its rows of one setup (evaluation seeds)
are averaged first. The model is the first word of the `policy` column (smappo, mappo,
greedy, random). A scripted baseline (greedy, random) has no training seeds: its cells carry
the std over evaluation seeds when there are several, '-' otherwise.

With --out, the text below the KEEP marker of an existing file (the hand-written discussion)
is kept; a file from before the marker keeps what follows its first table."""
import argparse, csv, os, statistics, sys
from collections import defaultdict

KEEP = "<!-- Generated above by bench/experiments/table.py; text below this line is kept on regeneration. -->"
ORDER = ["smappo", "mappo", "greedy", "random"]
SCRIPTED = {"greedy", "random"}


def setup_key(s):
    try:
        return [int(x) for x in s.replace("_", ".").split(".")]
    except ValueError:
        return [10**9, s]


def norm_setup(s):
    k = setup_key(s)
    return f"{k[0]}.{k[1]}_{k[2]}" if len(k) == 3 and all(isinstance(x, int) for x in k) else s


def model_of(policy, path):
    word = (policy.split() or [""])[0].lower()
    if word:
        return word
    for part in reversed(path.split(os.sep)):
        if part in ORDER:
            return part
    sys.exit(f"{path}: empty policy column and no model in the path")


def read_eval(path):
    """-> model, {setup: [(parts, collisions, mu) per eval row]}"""
    try:
        rows = list(csv.DictReader(open(path)))
    except OSError as e:
        sys.exit(f"{path}: {e}")
    if not rows:
        sys.exit(f"{path}: no data rows")
    need = {"policy", "setup", "parts_delivered", "collisions", "mu"}
    missing = need - set(rows[0].keys())
    if missing:
        sys.exit(f"{path}: missing column(s) {', '.join(sorted(missing))}")
    models = {model_of(r["policy"], path) for r in rows}
    if len(models) != 1:
        sys.exit(f"{path}: several policies {sorted(models)}; one model per file expected")
    per = defaultdict(list)
    for i, r in enumerate(rows, start=2):
        try:
            per[r["setup"]].append(
                (float(r["parts_delivered"]), float(r["collisions"]), float(r["mu"])))
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


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--exp", help="experiment name (A..D): paper rows and plot names")
    ap.add_argument("--paper", help="CSV experiment,setup,model,mu,std of the paper's MU")
    ap.add_argument("--out", help="write here, keeping the hand-written text below the marker")
    ap.add_argument("--eval-episodes", help="episodes per evaluation (for the note)")
    ap.add_argument("title")
    ap.add_argument("scale")
    ap.add_argument("seeds")
    ap.add_argument("files", nargs="+")
    a = ap.parse_args()

    # (setup, model) -> per training run: per-run mean over its evaluation rows
    runs = defaultdict(list)
    # (setup, model) -> evaluation rows of a scripted baseline (std over eval seeds)
    scripted_rows = defaultdict(list)
    for f in a.files:
        model, per = read_eval(f)
        for setup, vals in per.items():
            runs[(setup, model)].append(tuple(statistics.fmean(v[k] for v in vals) for k in range(3)))
            if model in SCRIPTED:
                scripted_rows[(setup, model)].extend(vals)
    paper = read_paper(a.paper, a.exp)

    out = [f"# {a.title}\n"]
    out.append(
        f"Budget: {a.scale} x the paper's episodes; training seeds {a.seeds}; each cell is mean (std) "
        "over training seeds of the mean over evaluation episodes"
        + (f" ({a.eval_episodes} per setup, eval seed 0)" if a.eval_episodes else "")
        + ". Scripted baselines are not trained: one evaluation on the same setups, episodes "
        "and eval seeds, so their std is '-' (or over eval seeds when there are several). "
        "paper MU: the paper's value for that model at its full budget"
        + (f" ({tables(a.exp)})" if a.exp and tables(a.exp) else "")
        + ", '-' where it reports none.\n")
    out.append("| setup | model | training seeds | parts delivered | collisions | MU | paper MU |")
    out.append("|---|---|---|---|---|---|---|")
    setups = sorted({s for s, _ in runs}, key=setup_key)
    models = sorted({m for _, m in runs}, key=lambda m: (ORDER.index(m) if m in ORDER else len(ORDER), m))
    for s in setups:
        for m in models:
            v = runs.get((s, m))
            if not v:
                continue
            if m in SCRIPTED and len(v) == 1:
                rows = scripted_rows[(s, m)]
                several = len(rows) > 1
                cells = [ms([r[k] for r in rows], p, several) for k, p in ((0, 1), (1, 1), (2, 2))]
                seeds = "none (scripted)"
            else:
                cells = [ms([x[k] for x in v], p) for k, p in ((0, 1), (1, 1), (2, 2))]
                seeds = str(len(v))
            pm = paper.get((norm_setup(s), m))
            pcell = "-" if pm is None else (f"{pm[0]:.2f} ({float(pm[1]):.2f})" if pm[1] else f"{pm[0]:.2f}")
            out.append(f"| {s} | {m} | {seeds} | {' | '.join(cells)} | {pcell} |")
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
    return {"A": "Table I", "B": "Table II", "C": "Table III", "D": "Table IV"}.get(exp, "")


if __name__ == "__main__":
    main()
