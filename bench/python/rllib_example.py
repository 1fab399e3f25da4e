"""Train a shared PPO policy with Ray RLlib on the tending env: the
scale-out path (RLlib's env runners are Ray actors, so the same script runs on a cluster
with more `--runners`).

Every robot is an agent of one shared policy (parameter sharing, as in the paper's MAPPO
and SMAPPO). The observation is the padded flat layout (`obs_layout="flat"`), which
RLlib's default MLP encoder takes as is; the per-group Dict layout would need a custom
RLModule (a set encoder like SMAPPO's), out of scope for an example.

After training, the learned policy's greedy (argmax) actions are run for a few episodes
in the env and its parts delivered are printed next to random actions and the scripted
greedy baseline, so the figures say honestly how far the training got.

`--model smappo`: instead of RLlib's MLP, tending's own SMAPPO networks
(`tending.rllib.SmappoRLModule`: the Rust actor and centralised critic in torch, the Dict
observation, MAPPO's PPO settings), the trained policy exported with `--export` as a
`tending-policy` checkpoint (`tending eval --checkpoint`, `tending fleet --policy`).
`--address` joins a running Ray cluster (`ray start --head` ...) instead of starting one.

Usage (bench/python/run.sh does it): python bench/python/rllib_example.py --iters 10
(`--csv`/`--png`: the per-iteration figures as a table and, with matplotlib, a plot;
`--minutes` caps the training time. docs/bench/python.md has a 32-minute run.)

Long runs (`--model smappo --out DIR --checkpoint-every N`): every N iterations the policy
is exported (`DIR/policy.safetensors`, the trainer state beside it), evaluated in Rust
(`--tending-bin`: `tending eval --checkpoint`, argmax, `--ckpt-eval-episodes` layouts of
seed 100, not the seeds the final evaluation reports), the best one so far kept as
`DIR/best.safetensors`, and RLlib's own checkpoint written to `DIR/algo`, from which
`--resume` goes on after a stop; every iteration is appended to `DIR/progress.csv`.
docs/bench/rllib_cluster.md has a run on a two-node Ray cluster.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

import tending


def make_env(cfg):
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv

    return ParallelPettingZooEnv(
        tending.parallel_env(cfg.get("setup", "6.4_2"), seed=cfg.get("seed", 0), obs_layout="flat")
    )


EPISODE_STEPS = 200  # the scenario's episode length


def parts_logger(window):
    """An `on_episode_end` callback logging the finished training episode's parts delivered
    (every robot's info carries the episode metrics), averaged over the last `window`
    episodes like RLlib's episode return."""

    def on_episode_end(episode, metrics_logger=None, **kw):
        infos = episode.get_infos(-1)
        m = next((i["metrics"] for i in infos.values() if isinstance(i, dict) and "metrics" in i), None)
        if m is not None and metrics_logger is not None:
            metrics_logger.log_value("parts_delivered", m["parts_delivered"], window=window)

    return on_episode_end


def evaluate(policy, setup, episodes, seed=1000):
    """Mean parts delivered and contacts per episode with `policy(env, obs) -> actions`."""
    env = tending.parallel_env(setup, seed=seed, obs_layout="flat")
    genv = tending.parallel_env(setup, seed=seed)  # dict layout, for the greedy baseline
    parts, contacts = [], []
    for k in range(episodes):
        obs, _ = env.reset(seed=seed + k)
        gobs, _ = genv.reset(seed=seed + k)
        while env.agents:
            acts = policy(env, obs, genv, gobs)
            obs, *_ = env.step(acts)
            gobs, *_ = genv.step(acts)
        m = env.metrics()
        parts.append(m["parts_delivered"])
        contacts.append(m["collisions"])
    return float(np.mean(parts)), float(np.mean(contacts))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--setup", default="6.4_2")
    ap.add_argument("--iters", type=int, default=10)
    ap.add_argument("--minutes", type=float, default=None,
                    help="stop training after this many minutes even if --iters are not done")
    ap.add_argument("--runners", type=int, default=2, help="RLlib env runners (Ray actors)")
    ap.add_argument("--batch", type=int, default=None,
                    help="env steps per training batch (x robots = agent-steps); default 2400 "
                         "(both; tending.rllib's MAPPO settings for smappo)")
    ap.add_argument("--eval-episodes", type=int, default=5)
    ap.add_argument("--model", choices=("mlp", "smappo"), default="mlp",
                    help="RLlib's default MLP on the flat observation, or tending's SMAPPO "
                         "networks (tending.rllib) on the Dict one")
    ap.add_argument("--export", default=None,
                    help="with --model smappo: write the trained policy here (tending-policy)")
    ap.add_argument("--address", default=None,
                    help="ray.init(address=...): a running cluster's address, e.g. auto")
    ap.add_argument("--json", default=None, help="write the figures here")
    ap.add_argument("--md", default=None, help="append a markdown section of the figures here")
    ap.add_argument("--csv", default=None, help="write the per-iteration figures here")
    ap.add_argument("--out", default=None,
                    help="with --model smappo: a run directory (progress.csv, periodic exports, "
                         "RLlib checkpoint for --resume)")
    ap.add_argument("--checkpoint-every", type=int, default=10,
                    help="with --out: export, evaluate and checkpoint every this many iterations")
    ap.add_argument("--resume", action="store_true",
                    help="with --out: restore DIR/algo and go on (its progress.csv is kept)")
    ap.add_argument("--tending-bin", default=None,
                    help="the tending binary: evaluate each periodic export in Rust")
    ap.add_argument("--ckpt-eval-episodes", type=int, default=20)
    ap.add_argument("--train-set", action="append", default=[], metavar="KEY=VALUE",
                    help="with --model smappo: a PPOConfig.training() field (a Python literal), "
                         "e.g. lr=3e-4; repeatable")
    ap.add_argument("--png", default=None, help="plot return and parts per iteration here")
    a = ap.parse_args()

    import ray
    import torch
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec
    from ray.tune.registry import register_env

    if a.address:
        ray.init(address=a.address, log_to_driver=False)
    else:
        ray.init(num_cpus=max(2, a.runners + 1), include_dashboard=False, log_to_driver=False)
    register_env("tending", make_env)
    if a.batch is None:
        a.batch = 2400
    window = max(1, a.batch // EPISODE_STEPS)
    if a.model == "smappo":
        import ast

        from tending.rllib import smappo_ppo_config

        torch.set_num_threads(1)
        extra = {}
        for kv in a.train_set:
            k, v = kv.split("=", 1)
            extra[k] = ast.literal_eval(v)
        config = (
            smappo_ppo_config(a.setup, env_runners=a.runners)
            .callbacks(on_episode_end=parts_logger(window))
            .reporting(metrics_num_episodes_for_smoothing=window)
            .training(train_batch_size_per_learner=a.batch, **extra)
        )
    else:
        config = None
    config = config or (
        PPOConfig()
        .environment("tending", env_config={"setup": a.setup, "seed": 0})
        .multi_agent(policies={"shared"}, policy_mapping_fn=lambda agent_id, *args, **kw: "shared")
        .rl_module(rl_module_spec=MultiRLModuleSpec(rl_module_specs={"shared": RLModuleSpec()}))
        .env_runners(num_env_runners=a.runners, num_envs_per_env_runner=1)
        # Each iteration's figures: the mean over about one batch of episodes.
        .callbacks(on_episode_end=parts_logger(window))
        .reporting(metrics_num_episodes_for_smoothing=window)
        .training(train_batch_size_per_learner=a.batch, minibatch_size=512, num_epochs=4, lr=3e-4)
    )
    t0 = time.perf_counter()
    algo = config.build_algo()
    t_build = time.perf_counter() - t0
    print(json.dumps({"build_seconds": round(t_build, 1), **runner_nodes(algo, ray)}), flush=True)
    rows = []
    run = RunDir(a.out, algo, a) if a.out else None
    if run and a.resume:
        rows = run.restore()
    t_prev = rows[-1]["wall_seconds"] if rows else 0.0
    steps_prev = rows[-1]["env_steps_lifetime"] if rows else 0
    # after --resume: RLlib's lifetime counters may start again from 0; carry the run's on
    offset = None if rows else (0, 0)
    while len(rows) < a.iters:
        t = time.perf_counter()
        r = algo.train()
        dt = time.perf_counter() - t
        er = r.get("env_runners", {})
        timers = r.get("timers", {})
        row = {
            "iter": len(rows) + 1,
            "seconds": round(dt, 1),
            "agent_steps": er.get("num_agent_steps_sampled_lifetime", {}),
            "env_steps_lifetime": er.get("num_env_steps_sampled_lifetime"),
            "episode_return_mean": er.get("episode_return_mean"),
            "parts_delivered_mean": er.get("parts_delivered"),
            "sample_seconds": _num(timers.get("env_runner_sampling_timer")),
            "learn_seconds": _num(timers.get("learner_update_timer")),
        }
        if isinstance(row["agent_steps"], dict):
            row["agent_steps"] = int(sum(row["agent_steps"].values()))
        if offset is None:
            fresh = (row["env_steps_lifetime"] or 0) < steps_prev
            offset = (steps_prev, rows[-1]["agent_steps"]) if fresh else (0, 0)
        row["env_steps_lifetime"] = (row["env_steps_lifetime"] or 0) + offset[0]
        row["agent_steps"] = (row["agent_steps"] or 0) + offset[1]
        steps = row["env_steps_lifetime"]
        row["env_steps_per_s"] = round((steps - steps_prev) / dt, 1)
        steps_prev = steps
        row["wall_seconds"] = round(t_prev + time.perf_counter() - t0, 1)
        if run:
            run.after_iteration(row)
        rows.append(row)
        print(json.dumps(row), flush=True)
        if a.minutes is not None and time.perf_counter() - t0 > 60 * a.minutes:
            break
    if run and rows and rows[-1].get("eval_parts") is None:
        run.checkpoint(rows[-1])
        run.write_progress(rows)
    t_train = time.perf_counter() - t0

    module = algo.get_module("shared")
    if a.model == "smappo":
        from tending.rllib import export_policy

        import tempfile

        with tempfile.TemporaryDirectory() as tmp:
            actor = export_policy(module, a.export or os.path.join(tmp, "policy.safetensors"))
        if a.export:
            print(f"exported the policy to {a.export} (tending eval --checkpoint {a.export})")
        state = {}

        def learned(env, obs, genv, gobs):
            # the exported actor on the Dict observation, one GRU state per robot
            if genv.metrics()["steps"] == 0:
                state.clear()
            arrs = dict(zip(("self", "machines", "storages", "peers"), genv.observe_arrays()))
            acts, state["h"] = actor.act(arrs, state.get("h"))
            return {ag: int(acts[i]) for i, ag in enumerate(env.agents)}
    else:
        def learned(env, obs, genv, gobs):
            x = torch.as_tensor(np.stack([obs[a] for a in env.agents]))
            with torch.no_grad():
                logits = module.forward_inference({"obs": x})["action_dist_inputs"]
            acts = logits.argmax(-1).numpy()
            return {a: int(acts[i]) for i, a in enumerate(env.agents)}

    rng = np.random.default_rng(0)

    def random_policy(env, obs, genv, gobs):
        return {a: int(rng.integers(5)) for a in env.agents}

    def greedy(env, obs, genv, gobs):
        return genv.greedy_actions(gobs)

    ev = {
        name: evaluate(p, a.setup, a.eval_episodes)
        for name, p in [("ppo (rllib)", learned), ("random", random_policy), ("greedy", greedy)]
    }
    for name, (parts, contacts) in ev.items():
        print(f"{name:>12}: {parts:6.1f} parts delivered, {contacts:6.1f} contacts per episode")
    out = {
        "setup": a.setup,
        "runners": a.runners,
        "batch": a.batch,
        "ray": ray.__version__,
        "torch": torch.__version__,
        "build_seconds": round(t_build, 1),
        "wall_seconds": round(t_train, 1),  # build + training
        "iterations": rows,
        "eval": {k: {"parts_delivered": v[0], "contacts": v[1]} for k, v in ev.items()},
    }
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(out, fh, indent=1)
    if a.md:
        with open(a.md, "a") as fh:
            png = a.png and os.path.relpath(a.png, os.path.dirname(os.path.abspath(a.md)))
            fh.write(markdown(out, png))
    if a.csv:
        write_csv(a.csv, rows)
    if a.png:
        plot(a.png, out)
    algo.stop()
    ray.shutdown()


def _num(v):
    """A timer of RLlib's result dict as seconds (it may be a number or a dict of stats)."""
    if isinstance(v, dict):
        v = v.get("mean", next(iter(v.values()), None))
    return None if v is None else round(float(v), 2)


def runner_nodes(algo, ray):
    """The Ray node and host each remote env runner lives on."""
    import socket

    def where(er):
        return ray.get_runtime_context().get_node_id(), socket.gethostname(), os.getpid()

    try:
        found = algo.env_runner_group.foreach_env_runner(where, local_env_runner=False)
    except Exception as e:  # noqa: BLE001 - no remote runners, or an API change
        return {"runner_nodes": f"n/a ({type(e).__name__})"}
    nodes = [n for n, _, _ in found]
    return {
        "runner_nodes": [n[:12] for n in nodes],
        "runners_per_node": {n[:12]: nodes.count(n) for n in sorted(set(nodes))},
        "cluster_nodes": [n["NodeID"][:12] for n in ray.nodes() if n.get("Alive")],
    }


class RunDir:
    """A long run's directory: progress.csv every iteration; every `checkpoint_every`
    iterations the exported policy and trainer state, a Rust evaluation of the policy, the
    best-so-far policy, and RLlib's checkpoint (for --resume)."""

    FIELDS = ("iter", "seconds", "agent_steps", "env_steps_lifetime", "episode_return_mean",
              "parts_delivered_mean", "sample_seconds", "learn_seconds", "env_steps_per_s",
              "wall_seconds", "eval_parts", "eval_contacts")

    def __init__(self, path, algo, args):
        self.path, self.algo, self.a = path, algo, args
        os.makedirs(path, exist_ok=True)
        self.best = None

    def restore(self):
        import csv

        self.algo.restore_from_path(os.path.abspath(os.path.join(self.path, "algo")))
        with open(os.path.join(self.path, "progress.csv")) as fh:
            rows = [{k: _parse(v) for k, v in r.items()} for r in csv.DictReader(fh)]
        last_ck = max((r["iter"] for r in rows if r.get("eval_parts") is not None), default=0)
        rows = [r for r in rows if r["iter"] <= last_ck]  # what the restored algo has seen
        evals = [r["eval_parts"] for r in rows if r.get("eval_parts") is not None]
        self.best = max(evals) if evals else None
        print(f"resumed from {self.path}/algo at iteration {last_ck}", flush=True)
        return rows

    def after_iteration(self, row):
        row.setdefault("eval_parts", None)
        row.setdefault("eval_contacts", None)
        if row["iter"] % self.a.checkpoint_every == 0:
            self.checkpoint(row)
        self._append(row)

    def _append(self, row):
        import csv

        f = os.path.join(self.path, "progress.csv")
        new = not os.path.exists(f) or row["iter"] == 1
        with open(f, "w" if new else "a", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=self.FIELDS, extrasaction="ignore")
            if new:
                w.writeheader()
            w.writerow(row)

    def write_progress(self, rows):
        import csv

        with open(os.path.join(self.path, "progress.csv"), "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=self.FIELDS, extrasaction="ignore")
            w.writeheader()
            w.writerows(rows)

    def checkpoint(self, row):
        import shutil
        import subprocess

        from tending.rllib import export_policy, export_trainer_state

        pol = os.path.join(self.path, "policy.safetensors")
        info = {"trained_by": "ray.rllib PPO (tending.rllib, bench/python/rllib_example.py)",
                "iteration": row["iter"], "env_steps": row["env_steps_lifetime"]}
        export_policy(self.algo, pol, training=info)
        export_trainer_state(self.algo, os.path.join(self.path, "trainer_state.safetensors"))
        if self.a.tending_bin:
            out = subprocess.run(
                [self.a.tending_bin, "eval", "--checkpoint", pol, "--setups", self.a.setup,
                 "--seeds", "100", "--episodes", str(self.a.ckpt_eval_episodes)],
                capture_output=True, text=True, check=True).stdout
            cells = [c.strip() for c in next(
                ln for ln in out.splitlines() if ln.startswith(f"| {self.a.setup} ")).split("|")]
            row["eval_parts"] = float(cells[2].split()[0])
            row["eval_contacts"] = float(cells[3].split()[0])
            if self.best is None or row["eval_parts"] >= self.best:
                self.best = row["eval_parts"]
                shutil.copyfile(pol, os.path.join(self.path, "best.safetensors"))
        self.algo.save_to_path(os.path.abspath(os.path.join(self.path, "algo")))


def _parse(v):
    if v in ("", None):
        return None
    try:
        f = float(v)
    except ValueError:
        return v
    return int(f) if f.is_integer() and "." not in v else f


def write_csv(path, rows):
    import csv

    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]), extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)


def plot(path, out):
    """Team return and parts delivered per training episode against env steps, with the
    evaluated random and greedy parts as reference lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = out["iterations"]
    x = [r["env_steps_lifetime"] / 1000 for r in rows]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.6))
    ax1.plot(x, [r["episode_return_mean"] for r in rows])
    ax1.set(xlabel="env steps (thousands)", ylabel="episode return (mean, team)", title="return")
    ax2.plot(x, [r["parts_delivered_mean"] for r in rows], label="PPO (RLlib), training episodes")
    ev = [(r["env_steps_lifetime"] / 1000, r["eval_parts"]) for r in rows
          if r.get("eval_parts") is not None]
    if ev:
        ax2.plot(*zip(*ev), "o-", ms=3, label="exported policy, tending eval (argmax)")
    for name, style in [("random", ":"), ("greedy", "--")]:
        ax2.axhline(out["eval"][name]["parts_delivered"], ls=style, c="grey", label=name)
    ax2.set(xlabel="env steps (thousands)", ylabel="parts delivered per episode",
            title="parts delivered")
    ax2.legend(fontsize=8)
    fig.suptitle(f"RLlib PPO, shared policy, {out['setup']}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)


def markdown(out, png=None, rows_shown=12):
    """The figures as a markdown section: about `rows_shown` iterations of the table (every
    iteration is in the --csv/--json files), the plot if written, the evaluation."""
    rows = out["iterations"]
    lines = [
        "",
        "## RLlib example (`bench/python/rllib_example.py`)",
        "",
        f"PPO (Ray RLlib {out['ray']}, PyTorch {out['torch']}, new API stack) with one policy "
        f"shared by all robots, on {out['setup']} with the padded flat observation; "
        f"{out['runners']} env runners (Ray actors) sampling `tending.parallel_env` through "
        f"RLlib's `ParallelPettingZooEnv`; {out['batch']} env steps per batch, 4 epochs, "
        f"minibatch 512, lr 3e-4. {len(rows)} iterations, "
        f"{int(rows[-1]['env_steps_lifetime']):,} env steps, {out.get('wall_seconds', 'n/a')} s "
        f"wall time (algorithm build: {out['build_seconds']} s).",
        "",
        "| iteration | seconds | agent-steps sampled (lifetime) | env steps (lifetime) "
        "| episode return (mean, team) | parts delivered (mean, training episodes) |",
        "|---|---|---|---|---|---|",
    ]
    step = max(1, len(rows) // rows_shown)
    fmt = lambda v: "n/a" if v is None else f"{v:.1f}"  # noqa: E731
    for r in rows:
        if r["iter"] == 1 or r["iter"] % step == 0 or r is rows[-1]:
            lines.append(
                f"| {r['iter']} | {r['seconds']} | {r['agent_steps']} | {int(r['env_steps_lifetime'])} "
                f"| {fmt(r['episode_return_mean'])} | {fmt(r.get('parts_delivered_mean'))} |"
            )
    if png:
        lines += ["", f"![RLlib PPO learning curve]({png})"]
    lines += [
        "",
        "Evaluation after training (argmax actions, 200-step episodes, mean over "
        "episodes with seeds 1000..):",
        "",
        "| policy | parts delivered | contacts |",
        "|---|---|---|",
    ]
    for k, v in out["eval"].items():
        lines.append(f"| {k} | {v['parts_delivered']:.1f} | {v['contacts']:.1f} |")
    lines.append("")
    return "\n".join(lines)

if __name__ == "__main__":
    main()
