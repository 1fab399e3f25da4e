"""Train a shared PPO policy with Ray RLlib on the tending env for a few iterations: the
scale-out path (RLlib's env runners are Ray actors, so the same script runs on a cluster
with more `--runners`).

Every robot is an agent of one shared policy (parameter sharing, as in the paper's MAPPO
and SMAPPO). The observation is the padded flat layout (`obs_layout="flat"`), which
RLlib's default MLP encoder takes as is; the per-group Dict layout would need a custom
RLModule (a set encoder like SMAPPO's), out of scope for an example.

After training, the learned policy's greedy (argmax) actions are run for a few episodes
in the env and its parts delivered are printed next to random actions and the scripted
greedy baseline, so the figures say honestly how far a few iterations get.

Usage (bench/python/run.sh does it): python bench/python/rllib_example.py --iters 10
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

import tending


def make_env(cfg):
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv

    return ParallelPettingZooEnv(
        tending.parallel_env(cfg.get("setup", "6.4_2"), seed=cfg.get("seed", 0), obs_layout="flat")
    )


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
    ap.add_argument("--runners", type=int, default=2, help="RLlib env runners (Ray actors)")
    ap.add_argument("--batch", type=int, default=2400,
                    help="env steps per training batch (x robots = agent-steps)")
    ap.add_argument("--eval-episodes", type=int, default=5)
    ap.add_argument("--json", default=None, help="write the figures here")
    ap.add_argument("--md", default=None, help="append a markdown section of the figures here")
    a = ap.parse_args()

    import ray
    import torch
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec
    from ray.tune.registry import register_env

    ray.init(num_cpus=max(2, a.runners + 1), include_dashboard=False, log_to_driver=False)
    register_env("tending", make_env)
    config = (
        PPOConfig()
        .environment("tending", env_config={"setup": a.setup, "seed": 0})
        .multi_agent(policies={"shared"}, policy_mapping_fn=lambda agent_id, *args, **kw: "shared")
        .rl_module(rl_module_spec=MultiRLModuleSpec(rl_module_specs={"shared": RLModuleSpec()}))
        .env_runners(num_env_runners=a.runners, num_envs_per_env_runner=1)
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
        }
        if isinstance(row["agent_steps"], dict):
            row["agent_steps"] = int(sum(row["agent_steps"].values()))
        rows.append(row)
        print(json.dumps(row), flush=True)

    module = algo.get_module("shared")

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
        "iterations": rows,
        "eval": {k: {"parts_delivered": v[0], "contacts": v[1]} for k, v in ev.items()},
    }
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(out, fh, indent=1)
    if a.md:
        with open(a.md, "a") as fh:
            fh.write(markdown(out))
    algo.stop()
    ray.shutdown()


def markdown(out):
    lines = [
        "",
        "## RLlib example (`bench/python/rllib_example.py`)",
        "",
        f"PPO (Ray RLlib {out['ray']}, PyTorch {out['torch']}, new API stack) with one policy "
        f"shared by all robots, on {out['setup']} with the padded flat observation; "
        f"{out['runners']} env runners (Ray actors) sampling `tending.parallel_env` through "
        f"RLlib's `ParallelPettingZooEnv`; {out['batch']} env steps per batch, 4 epochs, "
        f"minibatch 512. Algorithm build: {out['build_seconds']} s.",
        "",
        "| iteration | seconds | agent-steps sampled (lifetime) | env steps (lifetime) | episode return (mean, team) |",
        "|---|---|---|---|---|",
    ]
    for r in out["iterations"]:
        ret = r["episode_return_mean"]
        ret = "n/a" if ret is None else f"{ret:.1f}"
        lines.append(f"| {r['iter']} | {r['seconds']} | {r['agent_steps']} | {r['env_steps_lifetime']} | {ret} |")
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
