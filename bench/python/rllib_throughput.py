"""Throughput of tending's SMAPPO in RLlib (`tending.rllib`) against the number of env
runners, on a running Ray cluster (docs/bench/rllib_cluster.md).

For each runner count: the algorithm is built on the cluster (`ray.init(address=...)`), the
node of every env runner is reported, then

- sampling alone: `--rounds` rounds in which the runners together collect one training batch
  (`train_batch_size_per_learner` env steps, split evenly) in parallel, timed from the
  driver: env steps/s of the runners;
- end to end: `--iters` PPO iterations (`algo.train()`: sample, learn, sync weights) after
  a warm-up one, timed: env steps/s of training as a user sees it.

    RAY_AUTH_MODE=token python bench/python/rllib_throughput.py --address 192.0.2.2:6379 \\
        --runners 1,2,4 --json docs/bench/rllib_throughput.json
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import time


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--address", default="auto")
    ap.add_argument("--setup", default="6.4_2")
    ap.add_argument("--runners", default="1,2,4")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--iters", type=int, default=2)
    ap.add_argument("--json", default=None)
    a = ap.parse_args()

    import ray
    import torch

    from tending.rllib import smappo_ppo_config

    torch.set_num_threads(1)
    ray.init(address=a.address, log_to_driver=False)
    out = {"setup": a.setup, "ray": ray.__version__, "torch": torch.__version__,
           "cpus_here": os.cpu_count(), "cluster": [
               {"node": n["NodeID"][:12], "cpus": n["Resources"].get("CPU")}
               for n in ray.nodes() if n.get("Alive")], "runs": []}
    print(json.dumps(out), flush=True)
    for n in [int(x) for x in a.runners.split(",")]:
        algo = smappo_ppo_config(a.setup, env_runners=n).build_algo()
        batch = algo.config.train_batch_size_per_learner

        def where(er):
            return ray.get_runtime_context().get_node_id()[:12], socket.gethostname(), os.getpid()

        nodes = algo.env_runner_group.foreach_env_runner(where, local_env_runner=False)
        per = -(-batch // n)

        def sample(er, per=per):
            return sum(e.env_steps() for e in er.sample(num_timesteps=per))

        algo.env_runner_group.foreach_env_runner(sample, local_env_runner=False)  # warm-up
        t = time.perf_counter()
        steps = 0
        for _ in range(a.rounds):
            steps += sum(algo.env_runner_group.foreach_env_runner(sample, local_env_runner=False))
        t_sample = time.perf_counter() - t
        its, prev = [], None
        for _ in range(a.iters + 1):  # the first one (warm-up) only sets the step counter
            t = time.perf_counter()
            r = algo.train()
            dt = time.perf_counter() - t
            life = r["env_runners"]["num_env_steps_sampled_lifetime"]
            if prev is not None:
                its.append({"seconds": round(dt, 1), "env_steps": int(life - prev)})
            prev = life
        row = {
            "runners": n,
            "runner_nodes": [x[0] for x in nodes],
            "batch_env_steps": batch,
            "sample_env_steps": steps,
            "sample_seconds": round(t_sample, 1),
            "sample_env_steps_per_s": round(steps / t_sample, 1),
            "train_iterations": its,
            "train_env_steps_per_s": round(
                sum(i["env_steps"] for i in its) / sum(i["seconds"] for i in its), 1),
        }
        out["runs"].append(row)
        print(json.dumps(row), flush=True)
        algo.stop()
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(out, fh, indent=1)
    ray.shutdown()


if __name__ == "__main__":
    main()
