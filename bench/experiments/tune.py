"""MAPPO tuning at 6.4_2 (issue 47, experiment T): table, selection, docs/experiments/T.md.

    tune.py [--runs results/paper] [--configs bench/experiments/T] [--budget 8] [--out docs/experiments/T.md]

One run per config (bench/experiments/T/<name>.toml, on top of A's 8 envs per update and
2,000 episodes), training seed 10 (not one of the campaign's training seeds 0-2), evaluated
on held-out evaluation seeds 100,101,102 x 50 episodes (not the campaign's eval seeds 0-2;
training layouts come from (seed, update) hashes, evaluation layouts from (eval seed,
episode) hashes). The untuned reference is A's three MAPPO 6.4_2 policies (campaign
settings, training seeds 0-2) evaluated on the same held-out seeds.

Selection rule (fixed before the runs): once `budget` configs have finished, the config with
the highest held-out MU (argmax, mean over the 150 episodes) wins; within 0.01 MU of the
best, the one with fewer contact steps. It is written to results/paper/T/selected.toml
(with the winner's name in its first line) for experiment AT.
"""
import argparse, csv, glob, os, statistics, sys

KEEP = "<!-- Generated above by bench/experiments/tune.py; text below this line is kept on regeneration. -->"


def held_out(path):
    rows = list(csv.DictReader(open(path)))
    per = [(float(r["mu"]), float(r["parts_delivered"]), float(r["collisions"])) for r in rows]
    return [statistics.fmean(x[k] for x in per) for k in range(3)], \
        (statistics.pstdev([x[0] for x in per]) if len(per) > 1 else 0.0)


def last100(path):
    rows = list(csv.DictReader(open(path)))
    end = int(rows[-1]["episodes"])
    last = [r for r in rows if int(r["episodes"]) > end - 100]
    return statistics.fmean(float(r["mu"]) for r in last), float(rows[-1]["wall_secs"]), \
        int(rows[-1]["episodes"]), int(rows[-1]["update"])


def settings(path):
    return ", ".join(l.strip().replace(" = ", " ") for l in open(path)
                     if l.strip() and not l.startswith("#"))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", default="results/paper")
    ap.add_argument("--configs", default="bench/experiments/T")
    ap.add_argument("--budget", type=int, default=8)
    ap.add_argument("--out", default="docs/experiments/T.md")
    a = ap.parse_args()
    rows, done = [], []
    for cfg in sorted(glob.glob(f"{a.configs}/*.toml")):
        name = os.path.basename(cfg)[:-5]
        d = f"{a.runs}/T/{name}"
        ev, log = f"{d}/eval/results.csv", f"{d}/log.csv"
        fin = os.path.exists(f"{d}/.done") and os.path.exists(ev)
        cells = [name, settings(cfg), "10"]
        if fin:
            (mu, parts, coll), sd = held_out(ev)
            tmu, wall, eps, upd = last100(log)
            cells += [f"{mu:.3f} ({sd:.3f})", f"{parts:.1f}", f"{coll:.0f}", f"{tmu:.2f}",
                      f"{wall / 60:.1f} min"]
            done.append((name, cfg, mu, coll))
        else:
            cells += ["running" if os.path.exists(log) else "queued"] + ["-"] * 4
        rows.append(cells)
    ref = sorted(glob.glob(f"{a.runs}/T/untuned-A-seed*/eval/results.csv"))
    if ref:
        vals = [held_out(f)[0] for f in ref]
        tm = [last100(f"{a.runs}/A/6.4_2/mappo/seed{f.split('seed')[-1][0]}/log.csv") for f in ref]
        rows.insert(0, [f"untuned (A's MAPPO, {len(ref)} seeds)",
                        "campaign: ppo_epoch 10, num_mini_batch 4, lr 5e-4, critic_lr 5e-4, entropy_coef 0.01",
                        ", ".join(f.split("untuned-A-seed")[-1][0] for f in ref),
                        f"{statistics.fmean(v[0] for v in vals):.3f} ({statistics.pstdev([v[0] for v in vals]):.3f} over seeds)",
                        f"{statistics.fmean(v[1] for v in vals):.1f}",
                        f"{statistics.fmean(v[2] for v in vals):.0f}",
                        f"{statistics.fmean(t[0] for t in tm):.2f}",
                        f"{statistics.fmean(t[1] for t in tm) / 60:.1f} min"])
    chosen = None
    if len(done) >= a.budget:
        best = max(x[2] for x in done)
        near = [x for x in done if x[2] >= best - 0.01]
        chosen = min(near, key=lambda x: x[3])
        text = open(chosen[1]).read()
        with open(f"{a.runs}/T/selected.toml", "w") as f:
            f.write(f"# selected: {chosen[0]} (bench/experiments/tune.py, held-out MU {chosen[2]:.3f})\n")
            f.write("".join(l for l in text.splitlines(True) if not l.startswith("#")))
    out = ["# T: MAPPO tuned at 6.4_2 with the budget of tuning runs SMAPPO had", "",
           f"Each config: one MAPPO run on 6.4_2, 2,000 episodes (250 updates of 8 envs: A's budget), "
           f"training seed 10, every other setting the trainer's default (MAPPO's reference values, "
           f"policy/src/train/config.rs); evaluated with argmax actions on held-out evaluation "
           f"seeds 100, 101, 102 x 50 episodes. Held-out MU: mean (std over the 3 eval seeds). "
           f"One training seed per config: each row is an anecdote, the ranking is noisy at "
           f"differences below a few hundredths. Budget: {a.budget} runs (SMAPPO's own tuning at "
           f"6.4_2 took 8: PPO runs A-E and 3 reward-sanity runs, docs/bench/train.md). "
           f"Finished: {len(done)} of {a.budget}.", "",
           "Selection rule (fixed before the runs): the highest held-out MU; within 0.01 of it, "
           "fewer contact steps. "
           + (f"**Selected: {chosen[0]}** (results/paper/T/selected.toml), re-run with 3 seeds "
              f"in AT (docs/experiments/AT.md)." if chosen else "Not selected yet."), "",
           "| config | settings (on top of n_envs 8) | training seed(s) | held-out MU | parts | contact steps | MU, last 100 training episodes | wall |",
           "|---|---|---|---|---|---|---|---|"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    out += ["", "Not configurable in the trainer, so not tuned: MAPPO's hidden size (64, "
            "`ArchConfig::mappo`) and its observation normalisation (LayerNorm on the input, "
            "always on, as the reference's use_feature_normalization).", "",
            "![T: training curves](T_curves.png)", "", KEEP]
    keep = ""
    if os.path.exists(a.out) and KEEP in open(a.out).read():
        keep = open(a.out).read().split(KEEP, 1)[1].strip("\n")
    text = "\n".join(out) + "\n" + ("\n" + keep + "\n" if keep else "")
    open(a.out, "w").write(text)
    print(chosen[0] if chosen else "")


if __name__ == "__main__":
    main()
