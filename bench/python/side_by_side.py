#!/usr/bin/env python3
"""Our Rust tending simulator side by side with its VMAS twin (issue 37): env-stepping
throughput, then the same stock BenchMARL MAPPO run on each, one after the other.

    nice -n 19 target/venv-torchrl/bin/python bench/python/side_by_side.py --frames 128000

1. Env stepping: TorchRL ``rollout`` with random actions of ``tending.torchrl.TendingEnv``
   and of TorchRL's ``VmasEnv`` over ``vmas_tending.TendingScenario``, at each of
   ``--fps-envs`` batched envs and ``--fps-threads`` torch threads, ``--fps-steps`` steps
   (episode resets included), the median of ``--fps-reps`` runs.
2. Training: BenchMARL's stock MAPPO config and MLP model (its yaml defaults: 45 minibatch
   passes of 400 frames per batch, lr 5e-5, ...), ``--n-envs`` envs, one 200-step episode
   of each env per batch, ``--frames`` frames, ``--seed``, evaluation off, on
   ``tending/<setup>`` and then on ``vmas_tending/<setup>`` with ``obs_layout="tending"``
   (both give MAPPO the same 3 + 3M + 2K + 3(N-1) features). Per iteration: wall time,
   collection time, frames/s, and the mean over that batch's finished episodes of the team
   reward (rewards summed over robots and steps), parts delivered, collisions and MU.

Writes into --out (default results/benchmarl/side_by_side/<setup>_seed<seed>):
fps.csv, iterations.csv (both sims), summary.csv, side_by_side.png; BenchMARL's own logs
under <sim>/benchmarl (not needed afterwards). ``--plot-only`` redraws the PNG from the
CSVs; ``--skip-fps``, ``--only tending|vmas`` run a part.
"""

from __future__ import annotations

import argparse
import csv
import statistics
import sys
import time
from pathlib import Path

from benchmarl.experiment import Callback

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(Path(__file__).resolve().parent))

SIMS = ("tending", "vmas")
LABEL = {"tending": "tending (Rust, ours)", "vmas": "VMAS twin (torch)"}
ITER_FIELDS = ["sim", "iteration", "frames", "wall_s", "iteration_s", "collect_s",
               "frames_per_s", "episodes", "team_reward", "parts_delivered", "collisions", "mu"]


def make_task(sim: str, setup: str):
    if sim == "tending":
        import tending.benchmarl as tb

        return tb.task(setup)
    import vmas_tending

    return vmas_tending.task(setup, obs_layout="tending")


def measure_fps(args, out: Path):
    """Random-action TorchRL rollouts of both envs; rows of fps.csv."""
    import torch

    rows = []
    for threads in args.fps_threads:
        torch.set_num_threads(threads)
        for n_envs in args.fps_envs:
            for sim in SIMS:
                env = make_task(sim, args.setup).get_env_fun(n_envs, False, args.seed, "cpu")()
                n_agents = env.action_spec["agents", "action"].shape[-1]
                env.rollout(20, break_when_any_done=False)  # warm-up
                times = []
                for _ in range(args.fps_reps):
                    t0 = time.perf_counter()
                    env.rollout(args.fps_steps, break_when_any_done=False)
                    times.append(time.perf_counter() - t0)
                dt = statistics.median(times)
                fps = n_envs * args.fps_steps / dt
                rows.append([sim, threads, n_envs, n_agents, args.fps_steps, f"{dt:.3f}",
                             f"{fps:.0f}", f"{fps * n_agents:.0f}"])
                print(f"fps: {sim:8s} threads {threads} envs {n_envs:3d}: {fps:9.0f} frames/s "
                      f"({fps * n_agents:.0f} agent-steps/s)", flush=True)
                env.close()
    torch.set_num_threads(args.threads)
    with open(out / "fps.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["sim", "torch_threads", "n_envs", "n_agents", "steps", "median_s",
                    "frames_per_s", "agent_steps_per_s"])
        w.writerows(rows)


class IterLog(Callback):
    """One row of iterations.csv per collected batch (file opened per write: BenchMARL
    pickles its callbacks)."""

    def __init__(self, out: Path, sim: str):
        super().__init__()
        self.out, self.sim = out, sim
        self.start = self.last = self.last_train = time.perf_counter()
        self.iteration = 0

    def __getstate__(self):
        return {k: v for k, v in self.__dict__.items() if k != "experiment"}

    def on_batch_collected(self, batch):
        import tending.benchmarl as tb

        now = time.perf_counter()
        rows = tb.episode_rows(batch)

        def mean(k):
            return sum(r[k] for r in rows) / len(rows) if rows else float("nan")

        n, dt = batch.numel(), now - self.last
        row = [self.sim, self.iteration, self.experiment.total_frames, f"{now - self.start:.2f}",
               f"{dt:.2f}", f"{now - self.last_train:.2f}", f"{n / dt:.1f}", len(rows),
               f"{mean('team_reward'):.2f}", f"{mean('parts_delivered'):.2f}",
               f"{mean('collisions'):.1f}", f"{mean('mu'):.4f}"]
        with open(self.out / "iterations.csv", "a", newline="") as f:
            csv.writer(f).writerow(row)
        print(f"{self.sim} iter {self.iteration}: {self.experiment.total_frames} frames, "
              f"{now - self.start:.0f} s, collect {now - self.last_train:.1f} s, "
              f"{n / dt:.0f} frames/s, team reward {mean('team_reward'):.1f}, "
              f"parts {mean('parts_delivered'):.2f}", flush=True)
        self.iteration += 1
        self.last = now

    def on_train_end(self, training_td, group):
        self.last_train = time.perf_counter()


def train(sim: str, args, out: Path) -> dict:
    import torch
    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig

    torch.set_num_threads(args.threads)
    fpb = args.n_envs * 200
    cfg = ExperimentConfig.get_from_yaml()
    cfg.sampling_device = cfg.train_device = cfg.buffer_device = "cpu"
    cfg.max_n_frames = args.frames
    cfg.on_policy_collected_frames_per_batch = fpb
    cfg.on_policy_n_envs_per_worker = args.n_envs
    cfg.evaluation = False
    cfg.render = False
    cfg.loggers = ["csv"]
    cfg.create_json = False
    cfg.checkpoint_interval = 0
    cfg.checkpoint_at_end = False
    folder = out / sim / "benchmarl"
    folder.mkdir(parents=True, exist_ok=True)
    cfg.save_folder = str(folder)
    log = IterLog(out, sim)
    exp = Experiment(task=make_task(sim, args.setup), algorithm_config=MappoConfig.get_from_yaml(),
                     model_config=MlpConfig.get_from_yaml(), seed=args.seed, config=cfg,
                     callbacks=[log])
    log.start = log.last = log.last_train = time.perf_counter()
    exp.run()
    wall = time.perf_counter() - log.start
    print(f"{sim}: {exp.total_frames} frames in {wall:.0f} s ({exp.total_frames / wall:.0f} "
          f"frames/s)", flush=True)
    return {"sim": sim, "frames": exp.total_frames, "wall_s": round(wall, 1),
            "frames_per_s": round(exp.total_frames / wall, 1)}


def read_iterations(out: Path):
    with open(out / "iterations.csv") as f:
        return list(csv.DictReader(f))


def write_summary(out: Path, runs: list):
    rows = read_iterations(out)
    lines = []
    for run in runs:
        mine = [r for r in rows if r["sim"] == run["sim"]]
        last = mine[-1] if mine else {}
        collect = sum(float(r["collect_s"]) for r in mine[1:])  # the first includes set-up
        lines.append([run["sim"], run["frames"], run["wall_s"], run["frames_per_s"],
                      f"{collect:.1f}", last.get("team_reward", ""),
                      last.get("parts_delivered", ""), last.get("collisions", "")])
    with open(out / "summary.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["sim", "frames", "wall_s", "frames_per_s", "collect_s_after_first",
                    "final_team_reward", "final_parts_delivered", "final_collisions"])
        w.writerows(lines)


def plot(out: Path, setup: str, seed: int):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = read_iterations(out)
    total = {}  # training wall time to the last frame (iterations.csv stops at the last batch)
    if (out / "summary.csv").exists():
        with open(out / "summary.csv") as f:
            total = {r["sim"]: float(r["wall_s"]) for r in csv.DictReader(f)}
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for sim in SIMS:
        mine = [r for r in rows if r["sim"] == sim]
        if not mine:
            continue
        x = [int(r["frames"]) for r in mine]
        wall = total.get(sim, float(mine[-1]["wall_s"]))
        label = f"{LABEL[sim]}: {x[-1]:,} frames in {wall:.0f} s"
        axes[0].plot(x, [float(r["team_reward"]) for r in mine], marker="o", label=label)
        axes[1].plot(x, [float(r["parts_delivered"]) for r in mine], marker="o", label=label)
    axes[0].set_ylabel("mean episode team reward (sum over robots)")
    axes[1].set_ylabel("parts delivered per episode")
    for ax in axes:
        ax.set_xlabel("training frames (env steps)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"BenchMARL stock MAPPO (MLP), {setup}, seed {seed}: "
                 "tending simulator vs its VMAS twin")
    fig.tight_layout()
    fig.savefig(out / "side_by_side.png", dpi=110)
    print(f"plot: {out / 'side_by_side.png'}")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--setup", default="6.4_2")
    p.add_argument("--frames", type=int, default=128_000, help="training frames per simulator")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--n-envs", type=int, default=32, help="training envs (batch: 200 x this)")
    p.add_argument("--threads", type=int, default=1, help="torch threads while training")
    p.add_argument("--fps-envs", type=lambda s: [int(x) for x in s.split(",")], default=[1, 32])
    p.add_argument("--fps-threads", type=lambda s: [int(x) for x in s.split(",")], default=[1, 2])
    p.add_argument("--fps-steps", type=int, default=400)
    p.add_argument("--fps-reps", type=int, default=3)
    p.add_argument("--skip-fps", action="store_true")
    p.add_argument("--only", choices=SIMS, default=None, help="train only this simulator")
    p.add_argument("--plot-only", action="store_true")
    p.add_argument("--out", type=Path, default=None)
    args = p.parse_args(argv)
    out = args.out or ROOT / "results" / "benchmarl" / "side_by_side" / f"{args.setup}_seed{args.seed}"
    out.mkdir(parents=True, exist_ok=True)
    if args.plot_only:
        plot(out, args.setup, args.seed)
        return

    import torch

    torch.set_num_threads(args.threads)
    if not args.skip_fps:
        measure_fps(args, out)
    sims = [args.only] if args.only else list(SIMS)
    if not (out / "iterations.csv").exists() or not args.only:
        with open(out / "iterations.csv", "w", newline="") as f:
            csv.writer(f).writerow(ITER_FIELDS)
    runs = [train(sim, args, out) for sim in sims]
    write_summary(out, runs)
    plot(out, args.setup, args.seed)


if __name__ == "__main__":
    main()
