"""One verdict per claim of the SMAPPO paper, from the paper-budget campaign's results.

    verdict.py [--runs results/paper] [--paper bench/experiments/paper_mu.csv] [--out FILE]

Reads what bench/experiments/campaign.sh (and queue47.sh) have finished under RUNS
(evaluation results.csv and training log.csv per experiment, model and training seed) and
writes a Markdown table: the claim, the paper's figure, ours, and reproduced / direction only
/ not / pending. A claim whose runs are not all there (3 training seeds of every model and
setup it needs) is 'pending', with what is missing. Our figures use our protocol (argmax,
50 episodes x 3 eval seeds) except Table I's, which, like the paper, averages the last 100
training episodes; both protocols are in the experiment's own page (docs/experiments/<X>.md).

Rules (issue 47; fixed before the runs of that issue, written down so a verdict can be
checked). They are two-sided: a result far better than the paper's does not reproduce it.
- Our interval of a MU: the mean over training seeds +- TOL_MU (0.05 MU), widened to the
  seeds' own min-max when they spread further.
- Our interval of a percentage (SMAPPO over MAPPO, parts; or fewer collisions): the gain of
  the seed means g +- TOL_PCT (25 %) of g, widened to the gains of every (SMAPPO seed,
  MAPPO seed) pairing when they spread further.
- A sized claim (a table's MU, "up to X %", Fig. 5's crossings) is *reproduced* when the
  paper's figure lies inside our interval (for a table: both models' MU on every setup, and
  SMAPPO above MAPPO on every setup); *direction only* when the order holds (SMAPPO ahead
  of MAPPO on every setup / the gain has the paper's sign) but the size does not; *not*
  otherwise.
- A claim without a size (an order, e.g. "fewer collisions on every curriculum setup") is
  *reproduced* when the order holds, on seed means, on every setup it names, *not*
  otherwise; the detail says on how many it holds.
- Fig. 7 (reward at a curriculum stage change) is judged per robot (team reward / robots of
  the stage, seed mean): a drop is a fall from the 5 updates before the change to the 5
  after larger than twice the standard error of that difference (from the update-to-update
  spread in the two windows). The paper: SMAPPO drops at the first change only, MAPPO at
  every one.
- Collisions are judged twice, under the same rule: as contact steps (robot-steps in
  contact with anything; for A from the last 100 training episodes, as Table I) and as
  collision events (a robot starting to touch something: the paper's word, from the
  evaluations only, since the training log has no events; bench/experiments/onsets.py added
  them to evaluations made before `tending eval` counted them). A claim whose evaluations
  lack events is pending.
"""
import argparse, csv, glob, itertools, math, os, statistics, sys

sys.path.insert(0, os.path.dirname(__file__))
import table  # noqa: E402  (the campaign's reader: one parser for tables and verdicts)

EVENTS = table.EVENTS  # index of collision events in a metric tuple
UNIT = {1: "contact steps per episode", EVENTS: "collision events per episode"}
SEEDS = 3
TOL_MU = 0.05    # MU units
TOL_PCT = 0.25   # share of our own percentage
SETUPS = {
    "A": ["6.4_2", "8.6_2", "10.6_4", "12.8_4", "14.10_4", "100.16_2"],
    "B": ["6.4_2", "12.8_4", "18.12_6", "24.16_8"],
    "C": ["2.2_2", "4.2_2", "12.8_4", "18.12_6", "24.16_8", "30.20_10", "36.24_12", "42.28_14"],
    "D": ["6.4_2", "12.8_4", "18.12_6", "24.16_8"],
    "U": ["100.16_2"],
    # the paper's schedule (one 200-step env per PPO update, 15 epochs, 1 mini-batch)
    "P": ["6.4_2", "14.10_4"],
    # A's MAPPO re-trained with the tuned settings (docs/experiments/T.md); SMAPPO is A's
    "AT": ["6.4_2", "14.10_4"],
    # AT with MAPPO's hidden size 128 (T-extra, beyond T's budget, beat T's selection)
    "AT128": ["6.4_2", "14.10_4"],
    # B's curriculum on the paper's schedule (Fig. 7's axis: one env per update)
    "PB": ["6.4_2", "12.8_4", "18.12_6", "24.16_8"],
}
A2000 = ["6.4_2", "8.6_2", "10.6_4", "12.8_4", "14.10_4"]  # Table I at 2,000 episodes
# Experiments read by Table I's protocol (last 100 training episodes), one folder per setup.
PER_SETUP = ("A", "U", "P", "AT", "AT128")
# zero-shot (Sec. V-C): the paper's "far" setups are one smaller and four larger than 6.4_2;
# MAPPO is safer on the three nearest
C_FAR = ["2.2_2", "24.16_8", "30.20_10", "36.24_12", "42.28_14"]
C_NEAR = ["4.2_2", "12.8_4", "18.12_6"]


class Exp:
    """One experiment's finished runs: (setup, model) -> per-seed (parts, collisions, mu)."""

    def __init__(self, runs_dir, name):
        self.name = name
        files = sorted(glob.glob(f"{runs_dir}/{name}/*/seed*/eval/results.csv")
                       + glob.glob(f"{runs_dir}/{name}/*/*/seed*/eval/results.csv"))
        self.eval, _ = table.aggregate(files) if files else ({}, {})
        self.logs = {}
        if name in PER_SETUP:  # Table I's protocol: last 100 training episodes
            for f in glob.glob(f"{runs_dir}/{name}/*/*/seed*/log.csv"):
                if os.path.exists(os.path.join(os.path.dirname(f), ".done")):
                    setup, model, v = table.last100(f)
                    self.logs.setdefault((setup, model), []).append(v)
        self.curves = {}
        for f in glob.glob(f"{runs_dir}/{name}/*/seed*/log.csv") + glob.glob(
                f"{runs_dir}/{name}/*/*/seed*/log.csv"):
            if os.path.exists(os.path.join(os.path.dirname(os.path.realpath(f)), ".done")):
                parts = f.split(os.sep)
                model = next(p for p in reversed(parts) if p in table.ORDER)
                setup = parts[-4] if name in PER_SETUP else None
                self.curves.setdefault((setup, model), []).append(list(csv.DictReader(open(f))))

    def borrow(self, other, model):
        """Take `model`'s runs from another experiment (AT: A's SMAPPO beside the tuned MAPPO)."""
        for src, dst in ((other.eval, self.eval), (other.logs, self.logs),
                         (other.curves, self.curves)):
            for k, v in src.items():
                if k[1] == model:
                    dst[k] = v

    def values(self, setup, model, k):
        """Per-seed values of metric k (0 parts, 1 collisions, 2 MU, EVENTS collision
        events) of the seeds finished so far (None if none, or if an evaluation lacks the
        metric). Table I (A) uses the last 100 training episodes, but for events, which
        only evaluations count."""
        src = self.logs if self.name in PER_SETUP and k != EVENTS else self.eval
        v = src.get((setup, model), [])
        vals = [x[k] for x in v]
        return vals if vals and not any(math.isnan(x) for x in vals) else None

    def lacks_events(self, setups):
        """(setup model) pairs evaluated whose evaluations have no collision events."""
        return [f"{s} {m}" for s in self.done(setups) for m in ("smappo", "mappo")
                if self.values(s, m, EVENTS) is None]

    def missing(self, setups, models=("smappo", "mappo")):
        """(setup model) pairs with fewer than SEEDS finished seeds."""
        return [f"{s} {m}" for s in setups for m in models
                if len(self.values(s, m, 2) or []) < SEEDS]

    def done(self, setups):
        return [s for s in setups if self.values(s, "smappo", 2) and self.values(s, "mappo", 2)]

    def seeds_note(self, setups):
        n = {len(self.values(s, m, 2) or []) for s in setups for m in ("smappo", "mappo")}
        return "" if n == {SEEDS} else f" [interim: {min(n)}-{max(n)} of {SEEDS} seeds]"


def mean(xs):
    return statistics.fmean(xs)


def pct(a, b):
    return 100.0 * (a / b - 1.0) if b else float("inf")


def mu_interval(vals):
    m = mean(vals)
    return min(m - TOL_MU, min(vals)), max(m + TOL_MU, max(vals))


def gain(sm, mp, fewer):
    """SMAPPO over MAPPO in %: more parts (pct) or fewer collisions (reduction)."""
    if fewer:
        return 100.0 * (1 - sm / mp) if mp else 0.0
    return pct(sm, mp)


def gain_interval(svals, mvals, fewer=False):
    """(gain of the seed means, lo, hi): +- TOL_PCT of it, widened to every seed pairing."""
    g = gain(mean(svals), mean(mvals), fewer)
    pairs = [gain(a, b, fewer) for a, b in itertools.product(svals, mvals)]
    return g, min(g - TOL_PCT * abs(g), min(pairs)), max(g + TOL_PCT * abs(g), max(pairs))


def inside(x, iv):
    return iv[0] - 1e-9 <= x <= iv[1] + 1e-9


def pending(e, setups, ours, note):
    miss = e.missing(setups)
    if miss:
        return ("pending", ours + e.seeds_note(e.done(setups)),
                note + f"; {len(miss)} (setup, model) pairs have fewer than {SEEDS} seeds")
    return None


def table_verdict(e, paper, setups):
    """Tables I-IV: both models' MU against the paper's, per setup, and the order."""
    done = e.done(setups)
    if not done:
        return "pending", "-", f"no setup finished ({len(e.missing(setups))} runs missing)"
    cells, s_in, m_in, order = [], [], [], []
    for s in done:
        sv, mv = e.values(s, "smappo", 2), e.values(s, "mappo", 2)
        si, mi = mu_interval(sv), mu_interval(mv)
        ps, pm = paper[(s, "smappo")][0], paper.get((s, "mappo"), (None,))[0]
        s_in.append(inside(ps, si))
        m_in.append(pm is None or inside(pm, mi))
        order.append(mean(sv) > mean(mv))
        cells.append(f"{s} {mean(sv):.2f} [{si[0]:.2f}, {si[1]:.2f}] vs "
                     f"{mean(mv):.2f} [{mi[0]:.2f}, {mi[1]:.2f}]")
    n = len(done)
    note = (f"paper's MU inside our interval: SMAPPO {sum(s_in)}/{n}, MAPPO {sum(m_in)}/{n}; "
            f"SMAPPO above MAPPO on {sum(order)}/{n}")
    ours = "; ".join(cells)
    p = pending(e, setups, ours, note)
    if p:
        return p
    if all(s_in) and all(m_in) and all(order):
        v = "reproduced"
    elif all(order):
        v = "direction only"
    else:
        v = "not"
    return v, ours, note


def gain_verdict(e, setups, paper_pct, k=0, fewer=False):
    """'up to X %': the largest SMAPPO-over-MAPPO gain of metric k (fewer: reduction),
    the paper's X inside our interval of it."""
    done = e.done(setups)
    if not done:
        return "pending", "-", f"{len(e.missing(setups))} runs missing"
    if k == EVENTS and e.lacks_events(setups):
        return no_events(e, setups)
    gains = {s: gain_interval(e.values(s, "smappo", k), e.values(s, "mappo", k), fewer)
             for s in done}
    best = max(gains, key=lambda s: gains[s][0])
    g, lo, hi = gains[best]
    # shown as the change of SMAPPO against MAPPO, as the paper writes it (-49 %: fewer)
    sign = -1 if fewer else 1
    a, b = sorted((sign * lo, sign * hi))
    ours = f"{sign * g:+.0f} % [{a:+.0f}, {b:+.0f}] ({best})"
    note = "per setup: " + ", ".join(f"{s} {sign * x[0]:+.0f} %" for s, x in gains.items())
    p = pending(e, setups, ours, note)
    if p:
        return p
    if lo - 1e-9 <= paper_pct <= hi + 1e-9:
        return "reproduced", ours, note
    return ("direction only" if g > 0 else "not"), ours, note


def no_events(e, setups):
    miss = e.lacks_events(setups)
    return ("pending", "-", f"{len(miss)} evaluated (setup, model) pairs lack collision "
            "events (bench/experiments/onsets.py adds them)")


def order_verdict(e, setups, smappo_fewer=True, k=1):
    """A claim without a size: on every setup named, SMAPPO has fewer (smappo_fewer) or
    more (not smappo_fewer) collisions (k: 1 contact steps, EVENTS events) than MAPPO, on
    seed means."""
    done = e.done(setups)
    if not done:
        return "pending", "-", f"{len(e.missing(setups))} runs missing"
    if k == EVENTS and e.lacks_events(setups):
        return no_events(e, setups)
    holds = [s for s in done
             if (mean(e.values(s, "smappo", k)) < mean(e.values(s, "mappo", k))) == smappo_fewer]
    who = "SMAPPO" if smappo_fewer else "MAPPO"
    ours = f"{who} fewer on {len(holds)}/{len(done)}"
    note = ", ".join(f"{s} {mean(e.values(s, 'smappo', k)):.0f} vs {mean(e.values(s, 'mappo', k)):.0f}"
                     for s in done) + f" (SMAPPO vs MAPPO, {UNIT[k]})"
    p = pending(e, setups, ours, note)
    if p:
        return p
    return ("reproduced" if len(holds) == len(done) else "not"), ours, note


def few_agents_verdict(e, small="8.6_2", large="14.10_4", paper_gap=0.01):
    """Sec. V-A: 'with fewer agents MAPPO performs comparably to SMAPPO, but as the number
    of agents increases MAPPO's performance degrades'. Size: the MU gap SMAPPO - MAPPO at
    8.6_2 (paper 0.66 - 0.65 = 0.01) inside our interval of it (+- TOL_MU, widened to every
    seed pairing); direction: the gap at 8.6_2 smaller than at 14.10_4 (the largest setup
    trained for 2,000 episodes)."""
    setups = [small, large]
    done = e.done(setups)
    if len(done) < 2:
        return "pending", "-", f"{len(e.missing(setups))} runs missing"
    gaps = {}
    for s in setups:
        sv, mv = e.values(s, "smappo", 2), e.values(s, "mappo", 2)
        g = mean(sv) - mean(mv)
        pairs = [a - b for a, b in itertools.product(sv, mv)]
        gaps[s] = (g, min(g - TOL_MU, min(pairs)), max(g + TOL_MU, max(pairs)))
    g, lo, hi = gaps[small]
    ours = f"MU gap {small} {g:+.2f} [{lo:+.2f}, {hi:+.2f}], {large} {gaps[large][0]:+.2f}"
    note = ", ".join(f"{s} SMAPPO {mean(e.values(s, 'smappo', 2)):.2f} vs MAPPO "
                     f"{mean(e.values(s, 'mappo', 2)):.2f}" for s in setups)
    p = pending(e, setups, ours, note)
    if p:
        return p
    if lo - 1e-9 <= paper_gap <= hi + 1e-9 and gaps[large][0] > g:
        return "reproduced", ours, note
    return ("direction only" if gaps[large][0] > g else "not"), ours, note


def collisions_fall_verdict(e, a="10.6_4", b="12.8_4", k=1):
    """Sec. V-A: collisions drop from 10.6_4 to 12.8_4 (both models; the paper gives no
    figure, Fig. 4's bars only): an order claim."""
    setups = [a, b]
    if len(e.done(setups)) < 2:
        return "pending", "-", f"{len(e.missing(setups))} runs missing"
    if k == EVENTS and e.lacks_events(setups):
        return no_events(e, setups)
    falls = {m: (mean(e.values(a, m, k)), mean(e.values(b, m, k))) for m in ("smappo", "mappo")}
    ours = "; ".join(f"{m} {x:.0f} -> {y:.0f}" for m, (x, y) in falls.items())
    n = sum(1 for x, y in falls.values() if y < x)
    src = "evaluations" if k == EVENTS else "last 100 training episodes"
    note = f"falls for {n} of 2 models ({UNIT[k]}, {src})"
    p = pending(e, setups, ours, note)
    if p:
        return p
    return ("reproduced" if n == 2 else "not"), ours, note


def smoothed(runs):
    """Per seed: (episodes, updates, reward smoothed over 5 updates, final = mean of the
    last 100 episodes), and the same for the seed mean."""
    n = min(len(r) for r in runs)
    eps = [int(runs[0][i]["episodes"]) for i in range(n)]
    upd = [int(runs[0][i]["update"]) for i in range(n)]
    out = []
    for curve in [[float(r[i]["team_reward"]) for i in range(n)] for r in runs] + \
            [[mean(float(r[i]["team_reward"]) for r in runs) for i in range(n)]]:
        sm = [mean(curve[max(0, i - 4):i + 1]) for i in range(n)]
        final = mean(x for x, ep in zip(curve, eps) if ep > eps[-1] - 100)
        out.append((sm, final))
    return eps, upd, out


def crossing(xs, sm, level):
    return next((x for x, r in zip(xs, sm) if r >= level), None)


def convergence(e, setup="14.10_4"):
    """Fig. 5: episodes for SMAPPO's reward (smoothed over 5 updates) to reach 50 % and 70 %
    of its final value (mean of its last 100 episodes): the paper's 100 / 200 inside our
    interval (the seed mean's crossing +- TOL_PCT, widened to each seed's own crossing).
    Direction: SMAPPO's smoothed seed-mean reward above MAPPO's at every update from its
    50 % crossing on (the paper: SMAPPO learns faster and keeps a gap)."""
    runs = e.curves.get((setup, "smappo"), [])
    if len(runs) < SEEDS:
        return "pending", "-", f"{len(runs)}/{SEEDS} SMAPPO runs at {setup} finished"
    eps, upd, curves = smoothed(runs)
    ivs, res = {}, {}
    for frac, paper in ((0.5, 100), (0.7, 200)):
        per = [crossing(eps, sm, frac * f) for sm, f in curves[:-1]]
        c = crossing(eps, curves[-1][0], frac * curves[-1][1])
        if c is None or None in per:
            ivs[frac], res[frac] = None, False
            continue
        lo, hi = min(c * (1 - TOL_PCT), min(per)), max(c * (1 + TOL_PCT), max(per))
        ivs[frac] = (c, lo, hi)
        res[frac] = lo <= paper <= hi
    fmt = lambda iv: "never" if iv is None else f"{iv[0]} [{iv[1]:.0f}, {iv[2]:.0f}]"
    ours = (f"50 % at {fmt(ivs[0.5])} episodes, 70 % at {fmt(ivs[0.7])} "
            f"(final reward {curves[-1][1]:.0f})")
    u = {f: (upd[eps.index(ivs[f][0])] if ivs[f] else None) for f in (0.5, 0.7)}
    notes = [f"counted in PPO updates (the reference code's episodes, if it ran one env per "
             f"update): 50 % at update {u[0.5]}, 70 % at {u[0.7]}"]
    direction = None
    mp = e.curves.get((setup, "mappo"), [])
    if len(mp) >= SEEDS and ivs[0.5]:
        meps, _, mcurves = smoothed(mp)
        notes.append(f"MAPPO's final reward {mcurves[-1][1]:.0f}")
        mby = dict(zip(meps, mcurves[-1][0]))
        start = ivs[0.5][0]
        direction = all(r > mby[x] for x, r in zip(eps, curves[-1][0]) if x >= start and x in mby)
    notes.append("plot: A_fig5.png")
    if len(mp) < SEEDS:
        return "pending", ours, "; ".join(notes + [f"{len(mp)}/{SEEDS} MAPPO runs"])
    if all(res.values()) and direction:
        v = "reproduced"
    elif direction:
        v = "direction only"
    else:
        v = "not"
    return v, ours, "; ".join(notes)


def stage_drops(e, window=5):
    """Fig. 7, per robot: at each stage change, the seed-mean of team reward / robots over
    the `window` updates before against the `window` after; a drop counts when the fall is
    larger than twice the standard error of that difference."""
    out, runs_of = {}, {}
    for (_, model), runs in e.curves.items():
        if len(runs) < SEEDS:
            continue
        n = min(len(r) for r in runs)
        per_robot = [mean(float(r[i]["team_reward"]) / int(r[i]["setup"].split(".")[0])
                          for r in runs) for i in range(n)]
        idx = [i for i in range(1, n) if runs[0][i]["stage"] != runs[0][i - 1]["stage"]]
        res = []
        for i in idx:
            b, a = per_robot[max(0, i - window):i], per_robot[i:i + window]
            se = (statistics.variance(b) / len(b) + statistics.variance(a) / len(a)) ** 0.5
            res.append((mean(b), mean(a), mean(a) - mean(b) < -2 * se))
        out[model] = res
        runs_of[model] = len(runs)
    if not {"smappo", "mappo"} <= set(out):
        return "pending", "-", "curriculum runs not finished"
    ours = "; ".join(f"{m}: " + ", ".join(f"{b:.1f}->{a:.1f}{'*' if d else ''}" for b, a, d in out[m])
                     for m in ("smappo", "mappo"))
    drops = {m: [j + 1 for j, x in enumerate(out[m]) if x[2]] for m in out}
    k = len(out["mappo"])
    if drops["smappo"] == [1] and drops["mappo"] == list(range(1, k + 1)):
        v = "reproduced"
    elif len(drops["smappo"]) < len(drops["mappo"]):
        v = "direction only"
    else:
        v = "not"
    return v, ours, (f"per robot, {window} updates either side, * = a drop (> 2 standard "
                     f"errors): SMAPPO at stage changes {drops['smappo'] or 'none'}, MAPPO at "
                     f"{drops['mappo'] or 'none'}")


# The paper's 100.16_2 training: 3.54 days per seed on an AMD EPYC 9654 (96 cores), the
# core-hours if every core was busy (the paper does not say how many it used).
PAPER_DAYS_100, PAPER_CORES = 3.54, 96


def compute_table(runs_dir, cores=2):
    """Training wall time per finished run (log.csv's wall_secs: the trainer's own time in
    updates, saving excluded), mean over seeds, and core-hours as wall x this machine's
    cores (an upper bound: the trainer uses both, shared with other work)."""
    by = {}
    for f in sorted(glob.glob(f"{runs_dir}/*/*/seed*/log.csv") + glob.glob(f"{runs_dir}/*/*/*/seed*/log.csv")):
        if os.path.islink(f) or not os.path.exists(os.path.join(os.path.dirname(f), ".done")):
            continue
        rows = list(csv.DictReader(open(f)))
        parts = os.path.relpath(f, runs_dir).split(os.sep)
        exp, model = parts[0], parts[-3]
        what = rows[0]["setup"] if exp == "A" else "->".join(dict.fromkeys(r["setup"] for r in rows))
        key = (exp, what, model, rows[-1]["episodes"])
        by.setdefault(key, []).append(float(rows[-1]["wall_secs"]))
    out = ["| experiment | setup(s) | model | episodes | finished seeds | wall time per run | core-hours per run |",
           "|---|---|---|---|---|---|---|"]
    for (exp, what, model, eps), w in sorted(by.items()):
        m = statistics.fmean(w)
        out.append(f"| {exp} | {what} | {model} | {eps} | {len(w)} | {m / 60:.1f} min | {m * cores / 3600:.2f} |")
    paper_ch = PAPER_DAYS_100 * 24 * PAPER_CORES
    out.append("")
    out.append(f"The paper: {PAPER_DAYS_100} days per seed for 100.16_2 (100 episodes) on a "
               f"{PAPER_CORES}-core AMD EPYC 9654, {PAPER_DAYS_100 * 24:.0f} h wall and at most "
               f"{paper_ch:.0f} core-hours. Ours on this 2-core machine: the rows above.")
    return out


def table_i_rows(ex, pe, x, label, gain_label):
    """Table I at 6.4_2 and 14.10_4 and the +61 % headline for one more reading of
    experiment A (`x`: AT, AT128), each labelled with `label` formatted by the setup."""
    paper = {"6.4_2": "SMAPPO 0.74, MAPPO 0.51", "14.10_4": "SMAPPO 0.69, MAPPO 0.65"}
    return [(label.format(s), paper[s], table_verdict(ex[x], pe[x], [s])) for s in paper] + [
        (gain_label, "+61 %", gain_verdict(ex[x], SETUPS[x], 61))]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", default="results/paper")
    ap.add_argument("--paper", default="bench/experiments/paper_mu.csv")
    ap.add_argument("--out")
    a = ap.parse_args()
    paper = {}
    for r in csv.DictReader(open(a.paper)):
        paper[(r["experiment"], table.norm_setup(r["setup"]), r["model"])] = (float(r["mu"]), r["std"])
    pe = {x: {(s, m): v for (e, s, m), v in paper.items() if e == x} for x in "ABCDU"}
    pe["P"] = pe["AT"] = pe["AT128"] = pe["A"]  # other budget readings / baselines of Table I
    pe["PB"] = pe["B"]  # Table II under the paper's schedule
    ex = {x: Exp(a.runs, x) for x in ("A", "B", "C", "D", "U", "P", "AT", "AT128", "PB")}
    ex["AT"].borrow(ex["A"], "smappo")
    ex["AT128"].borrow(ex["A"], "smappo")
    rows = [
        "Full retraining (A: 2,000 episodes = 250 updates of 8 envs; 100.16_2: 104 episodes = 13 updates)",
        ("Table I at 2,000 episodes: MU of both models (6.4_2 ... 14.10_4)",
         "SMAPPO 0.66-0.79, MAPPO 0.51-0.72", table_verdict(ex["A"], pe["A"], A2000)),
        ("Table I, 100.16_2 (104 episodes = 13 updates): SMAPPO 0.91, MAPPO 0.64",
         "SMAPPO 0.91, MAPPO 0.64", table_verdict(ex["A"], pe["A"], ["100.16_2"])),
        ("Abstract: full retraining, up to 61 % improvement (parts)", "+61 %",
         gain_verdict(ex["A"], SETUPS["A"], 61)),
        ("Sec. V-A: 53 % more parts than MAPPO at 100.16_2", "+53 %",
         gain_verdict(ex["A"], ["100.16_2"], 53)),
        ("Sec. V-A: SMAPPO safer (fewer collisions on all but the smallest setup)",
         "5 of 6 (smallest: no significant difference)",
         order_verdict(ex["A"], SETUPS["A"][1:])),
        ("Collision events, Sec. V-A: SMAPPO safer on all but the smallest setup", "5 of 6",
         order_verdict(ex["A"], SETUPS["A"][1:], k=EVENTS)),
        ("Sec. V-A: collisions fall from 10.6_4 to 12.8_4 (robots are smaller at 12.8_4)",
         "fall (Fig. 4)", collisions_fall_verdict(ex["A"])),
        ("Collision events, Sec. V-A: collisions fall from 10.6_4 to 12.8_4",
         "fall (Fig. 4)", collisions_fall_verdict(ex["A"], k=EVENTS)),
        ("Sec. V-A: with few agents MAPPO is comparable to SMAPPO, and falls behind as agents grow",
         "8.6_2: 0.66 vs 0.65", few_agents_verdict(ex["A"])),
        ("Fig. 5: SMAPPO reaches 50 % of its final reward in 100 episodes, 70 % in 200 (14.10_4)",
         "100 / 200 episodes", convergence(ex["A"])),
        "Full retraining against MAPPO tuned as SMAPPO was (AT: A's SMAPPO, MAPPO re-trained with docs/experiments/T.md's settings, A's budget)",
        *table_i_rows(ex, pe, "AT", "Table I at {} against the tuned MAPPO",
                      "Abstract: up to 61 % more parts, against the tuned MAPPO (6.4_2, 14.10_4)"),
        "Against the tuned MAPPO with hidden size 128 (AT128: T-extra's settings, beyond T's 8-run budget, A's budget)",
        *table_i_rows(ex, pe, "AT128", "Hidden 128: Table I at {}",
                      "Hidden 128: up to 61 % more parts (6.4_2, 14.10_4)"),
        "The paper's schedule as its figures read it (P: one 200-step env per PPO update, 2,000 updates, 15 epochs, 1 mini-batch)",
        ("Table I at 6.4_2, paper's schedule", "SMAPPO 0.74, MAPPO 0.51",
         table_verdict(ex["P"], pe["P"], ["6.4_2"])),
        ("Table I at 14.10_4, paper's schedule", "SMAPPO 0.69, MAPPO 0.65",
         table_verdict(ex["P"], pe["P"], ["14.10_4"])),
        ("Abstract: up to 61 % more parts, paper's schedule (6.4_2, 14.10_4)", "+61 %",
         gain_verdict(ex["P"], SETUPS["P"], 61)),
        ("Fig. 5 under the paper's schedule (14.10_4)", "100 / 200 episodes", convergence(ex["P"])),
        "100.16_2 at 100 updates of 8 envs (U: 800 simulated episodes)",
        ("Sec. V-A, 100.16_2 at 100 updates (U): 53 % more parts than MAPPO", "+53 %",
         gain_verdict(ex["U"], SETUPS["U"], 53)),
        ("Table I, 100.16_2 at 100 updates (U): SMAPPO 0.91, MAPPO 0.64",
         "SMAPPO 0.91, MAPPO 0.64", table_verdict(ex["U"], pe["U"], SETUPS["U"])),
        "Curriculum (B: 2,000 episodes of 6.4_2, then +6.4_2 every 104 episodes = 13 updates)",
        ("Table II: curriculum MU of both models", "SMAPPO 0.54-0.79, MAPPO 0.39-0.55",
         table_verdict(ex["B"], pe["B"], SETUPS["B"])),
        ("Abstract: curriculum, up to 45 % more parts", "+45 %", gain_verdict(ex["B"], SETUPS["B"], 45)),
        ("Abstract: curriculum, up to 49 % fewer collisions", "-49 %",
         gain_verdict(ex["B"], SETUPS["B"], 49, k=1, fewer=True)),
        ("Collision events, abstract: curriculum, up to 49 % fewer collisions", "-49 %",
         gain_verdict(ex["B"], SETUPS["B"], 49, k=EVENTS, fewer=True)),
        ("Sec. V-B: SMAPPO has fewer collisions in every curriculum setup", "4 of 4",
         order_verdict(ex["B"], SETUPS["B"])),
        ("Collision events, Sec. V-B: fewer collisions in every curriculum setup", "4 of 4",
         order_verdict(ex["B"], SETUPS["B"], k=EVENTS)),
        ("Fig. 7, per robot: MAPPO's reward drops at every new stage, SMAPPO's at the first only",
         "drops: SMAPPO at 1, MAPPO at 1, 2, 3", stage_drops(ex["B"])),
        "Curriculum on the paper's schedule (PB: 2,000 updates of one 6.4_2 env, then 100 per stage: Fig. 7's 400K / 420K / 440K steps)",
        ("Table II, paper's schedule", "SMAPPO 0.54-0.79, MAPPO 0.39-0.55",
         table_verdict(ex["PB"], pe["PB"], SETUPS["PB"])),
        ("Paper's schedule, abstract: curriculum, up to 45 % more parts", "+45 %",
         gain_verdict(ex["PB"], SETUPS["PB"], 45)),
        ("Paper's schedule, abstract: up to 49 % fewer collisions (events)", "-49 %",
         gain_verdict(ex["PB"], SETUPS["PB"], 49, k=EVENTS, fewer=True)),
        ("Fig. 7 per robot, paper's schedule", "drops: SMAPPO at 1, MAPPO at 1, 2, 3",
         stage_drops(ex["PB"])),
        "Zero-shot from 6.4_2 (C)",
        ("Table III: zero-shot MU of both models", "SMAPPO 0.31-0.73, MAPPO 0.12-0.65",
         table_verdict(ex["C"], pe["C"], SETUPS["C"])),
        ("Abstract, Sec. V-C: zero-shot, 272 % more parts at 42.28_14", "+272 %",
         gain_verdict(ex["C"], ["42.28_14"], 272)),
        ("Sec. V-C: zero-shot SMAPPO safer on the far setups (2.2_2 and 24.16_8 ... 42.28_14)",
         "5 of 5 far setups", order_verdict(ex["C"], C_FAR)),
        ("Collision events, Sec. V-C: zero-shot SMAPPO safer on the far setups",
         "5 of 5 far setups", order_verdict(ex["C"], C_FAR, k=EVENTS)),
        ("Sec. V-C: zero-shot MAPPO safer on the three setups nearest training (4.2_2, 12.8_4, 18.12_6)",
         "3 of 3 near setups", order_verdict(ex["C"], C_NEAR, smappo_fewer=False)),
        ("Collision events, Sec. V-C: zero-shot MAPPO safer near training",
         "3 of 3 near setups", order_verdict(ex["C"], C_NEAR, smappo_fewer=False, k=EVENTS)),
        "Curriculum after a short initial training (D: 200 episodes, then the stages)",
        ("Table IV: short initial training MU of both models", "SMAPPO 0.27-0.76, MAPPO 0.17-0.48",
         table_verdict(ex["D"], pe["D"], SETUPS["D"])),
        ("Abstract: short initial training, up to 100 % more parts", "+100 %",
         gain_verdict(ex["D"], SETUPS["D"], 100)),
    ]
    out = ["Rules (bench/experiments/verdict.py, fixed in issue 47 before its runs): a sized "
           "claim is **reproduced** when the paper's figure lies inside our interval over "
           f"training seeds (MU: mean +- {TOL_MU}, widened to the seeds' min-max; a percentage: "
           f"ours +- {TOL_PCT:.0%} of it, widened to every SMAPPO-seed x MAPPO-seed pairing), "
           "**direction only** when SMAPPO is ahead of MAPPO as the paper says but the size "
           "is outside, **not** otherwise. A claim without a size (an order over setups) is "
           "reproduced when it holds on every setup it names. Intervals are in brackets. "
           "Collisions are judged twice: as contact steps (robot-steps in contact; A: last "
           "100 training episodes) and as collision events (a robot starting to touch "
           "something, the paper's count; evaluations only).", "",
           "| claim of the paper | paper | ours | verdict | detail |", "|---|---|---|---|---|"]
    counts = {}
    for r in rows:
        if isinstance(r, str):
            out.append(f"| **{r}** | | | | |")
            continue
        claim, theirs, (v, ours, note) = r
        counts[v] = counts.get(v, 0) + 1
        out.append(f"| {claim} | {theirs} | {ours} | **{v}** | {note} |")
    out += ["", "Verdicts: " + ", ".join(f"{k} {n}" for k, n in sorted(counts.items())) + "."]
    out += ["", "## Compute", ""] + compute_table(a.runs)
    text = "\n".join(out) + "\n"
    if a.out:
        open(a.out, "w").write(text)
    else:
        sys.stdout.write(text)


if __name__ == "__main__":
    main()
