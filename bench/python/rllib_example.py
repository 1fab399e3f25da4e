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
    ap.add_argument("--batch", type=int, default=2400,
                    help="env steps per training batch (x robots = agent-steps)")
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
    window = max(1, a.batch // EPISODE_STEPS)
    if a.model == "smappo":
        from tending.rllib import smappo_ppo_config

        torch.set_num_threads(1)
        config = (
            smappo_ppo_config(a.setup, env_runners=a.runners)
            .callbacks(on_episode_end=parts_logger(window))
            .reporting(metrics_num_episodes_for_smoothing=window)
            .training(train_batch_size_per_learner=a.batch)
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
    rows = []
    for it in range(a.iters):
        t = time.perf_counter()
        r = algo.train()
        dt = time.perf_counter() - t
        er = r.get("env_runners", {})
        row = {
            "iter": it + 1,
            "seconds": round(dt, 1),
            "agent_steps": er.get("num_agent_steps_sampled_lifetime", {}),
            "env_steps_lifetime": er.get("num_env_steps_sampled_lifetime"),
            "episode_return_mean": er.get("episode_return_mean"),
            "parts_delivered_mean": er.get("parts_delivered"),
        }
        if isinstance(row["agent_steps"], dict):
            row["agent_steps"] = int(sum(row["agent_steps"].values()))
        rows.append(row)
        print(json.dumps(row), flush=True)
        if a.minutes is not None and time.perf_counter() - t0 > 60 * a.minutes:
            break
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


def write_csv(path, rows):
    import csv

    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def plot(path, out):
    """Team return and parts delivered per training episode against env steps, with the
    evaluated random and greedy parts as reference lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = out["iterations"]
    x = [r["env_steps_lifetime"] for r in rows]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.6))
    ax1.plot(x, [r["episode_return_mean"] for r in rows])
    ax1.set(xlabel="env steps", ylabel="episode return (mean, team)", title="return")
    ax2.plot(x, [r["parts_delivered_mean"] for r in rows], label="PPO (RLlib), training episodes")
    for name, style in [("random", ":"), ("greedy", "--")]:
        ax2.axhline(out["eval"][name]["parts_delivered"], ls=style, c="grey", label=name)
    ax2.set(xlabel="env steps", ylabel="parts delivered per episode", title="parts delivered")
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
