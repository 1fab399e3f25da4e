#!/usr/bin/env python3
"""Train a stock BenchMARL algorithm on a tending setup (tending.benchmarl's task) and log,
as CSV, every episode's parts delivered and team reward (training and evaluation) and every
iteration's frames per second.

    python bench/python/benchmarl_run.py --algorithm mappo --setup 6.4_2 --frames 64000 --seed 0

BenchMARL's stock MAPPO with its stock MLP (the issue-47 cross-check of our MAPPO,
docs/experiments/benchmarl_mappo.md), trained away from the evaluation layouts and then
judged on the layouts `tending eval --seeds 0,1,2 --episodes 50` plays:

    python bench/python/benchmarl_run.py --model mlp --frames 400000 --seed 0 --n-envs 10 \
        --frames-per-batch 6000 --train-seed-offset 1000 --checkpoint-every 10 --out OUT
    python bench/python/benchmarl_run.py --model mlp --seed 0 --n-envs 10 \
        --frames-per-batch 6000 --train-seed-offset 1000 --out OUT \
        --eval-only 50 --eval-seeds 0,1,2 --eval-layouts tending

Needs the package with its [torchrl] extra (pip install './python[torchrl]'). Everything not
set here is BenchMARL's own default (benchmarl/conf/experiment/base_experiment.yaml and the
algorithm's yaml); ``--set key=value`` overrides any ExperimentConfig field.

Writes into --out (default target/benchmarl/<algorithm>_<setup>_seed<seed>):
- episodes.csv: phase (train, eval, greedy), iteration, frames, wall_s, env, parts_delivered,
  collisions, mu, team_reward (the episode's rewards summed over robots);
- iterations.csv: iteration, frames, wall_s, iteration_s, frames_per_s (of the iteration:
  collection, training and evaluation), episodes, mean parts_delivered and team_reward;
- benchmarl/: BenchMARL's own CSV logs (losses, timers, rewards).
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

from benchmarl.experiment import Callback

from tending.benchmarl import TendingClass

ALGORITHMS = ("mappo", "ippo", "masac", "isac", "qmix", "vdn", "iql")
ROOT = Path(__file__).resolve().parents[2]


def algorithm_config(name: str):
    from benchmarl import algorithms as a

    return {
        "mappo": a.MappoConfig, "ippo": a.IppoConfig, "masac": a.MasacConfig,
        "isac": a.IsacConfig, "qmix": a.QmixConfig, "vdn": a.VdnConfig, "iql": a.IqlConfig,
    }[name].get_from_yaml()


def parse_value(text: str):
    import yaml

    return yaml.safe_load(text)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--algorithm", choices=ALGORITHMS, default="mappo")
    p.add_argument("--setup", default="6.4_2", help="N.M_K, e.g. 6.4_2 (or tending/6.4_2)")
    p.add_argument("--frames", type=int, default=64_000,
                   help="env steps to collect (BenchMARL frames: one per env per step)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--model", choices=("mlp", "smappo", "rust"), default="mlp",
                   help="actor and critic model: BenchMARL's MLP (MAPPO as the paper's "
                        "baseline), the paper's attention encoder "
                        "(tending.benchmarl_smappo: MAPPO with it is SMAPPO), or tending's "
                        "own SMAPPO networks (tending.benchmarl_rust: the Rust actor and "
                        "critic in torch, exported with --export)")
    p.add_argument("--init", type=Path, default=None,
                   help="with --model rust: start from this tending-policy checkpoint or "
                        "trainer state (e.g. fine-tune a `tending train` policy)")
    p.add_argument("--export", type=Path, default=None,
                   help="with --model rust: write the trained policy here as a tending-policy "
                        "checkpoint (tending eval --checkpoint, tending fleet --policy)")
    p.add_argument("--n-envs", type=int, default=None,
                   help="envs stepped together in Rust (default 32; 4 with --hparams mappo)")
    p.add_argument("--frames-per-batch", type=int, default=None,
                   help="frames per iteration (default: one 200-step episode of every env)")
    p.add_argument("--minibatch-iters", type=int, default=None,
                   help="on-policy: on_policy_n_minibatch_iters (BenchMARL's default 45)")
    p.add_argument("--optimizer-steps", type=int, default=None,
                   help="off-policy: off_policy_n_optimizer_steps (BenchMARL's default 1000)")
    p.add_argument("--lr", type=float, default=None, help="learning rate (BenchMARL's 5e-5)")
    p.add_argument("--eval-every", type=int, default=5,
                   help="evaluate every this many iterations (0: never)")
    p.add_argument("--eval-episodes", type=int, default=10)
    p.add_argument("--threads", type=int, default=1,
                   help="torch threads (1 on a 2-core machine: torch's OpenMP threads spin "
                        "and starve the simulator's rayon threads)")
    p.add_argument("--hparams", choices=("benchmarl", "mappo"), default="benchmarl",
                   help="PPO settings: BenchMARL's defaults (45 epochs of 400-frame "
                        "minibatches per batch, lr 5e-5, no entropy bonus) or MAPPO's, as "
                        "`tending train` uses them (4 envs, one 800-frame minibatch, 10 "
                        "epochs, lr 5e-4, entropy 0.01, GAE lambda 0.95, grad clip 10): "
                        "9x fewer frame-gradients per frame, see python/README.md")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="any ExperimentConfig field, e.g. --set gamma=0.95")
    p.add_argument("--algo-set", action="append", default=[], metavar="KEY=VALUE",
                   help="any field of the algorithm's config, e.g. --algo-set entropy_coef=0.01")
    p.add_argument("--out", type=Path, default=None)
    p.add_argument("--checkpoint-every", type=int, default=0, metavar="ITERS",
                   help="save BenchMARL's checkpoint (models, optimisers, collector state) "
                        "every ITERS iterations under OUT/benchmarl (0: never)")
    p.add_argument("--resume", action="store_true",
                   help="continue from the newest checkpoint under OUT/benchmarl (a run "
                        "that outlives a session: commit OUT, then --resume elsewhere); "
                        "the CSVs are appended to")
    p.add_argument("--eval-only", type=int, default=0, metavar="EPISODES",
                   help="no training: restore OUT's newest checkpoint (same flags as the run) "
                        "and evaluate its policy (argmax), the greedy script and uniform "
                        "random actions on the same EPISODES layouts for each of "
                        "--eval-seeds; writes OUT/eval.csv (OUT/eval_tending.csv with "
                        "--eval-layouts tending)")
    p.add_argument("--eval-seeds", default="0,1,2",
                   help="with --eval-only: env seeds, comma-separated")
    p.add_argument("--eval-layouts", choices=("benchmarl", "tending"), default="benchmarl",
                   help="with --eval-only: the layouts. benchmarl: EPISODES envs of env seed "
                        "20,000 + s (one episode each); tending: the layouts `tending eval "
                        "--seeds S --episodes EPISODES` runs (one env, its episodes in "
                        "sequence: episode k of seed s laid out from episode_seed(s, 0, k)), so "
                        "the rows compare with the campaign's tables (docs/experiments); "
                        "needs a training run with --train-seed-offset (see there)")
    p.add_argument("--train-seed-offset", type=int, default=0,
                   help="training and BenchMARL's own evaluation envs use env seed SEED + "
                        "this (default 0: SEED). TendingEnv's env 0 of seed s plays the layouts "
                        "`tending eval --seeds s` evaluates, so a run judged with "
                        "--eval-layouts tending on seeds 0-2 trains with an offset (e.g. 1000)")
    p.add_argument("--no-greedy", action="store_true",
                   help="skip the greedy baseline's episodes (reference rows in episodes.csv)")
    args = p.parse_args(argv)

    import torch

    torch.set_num_threads(args.threads)
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig

    import tending.benchmarl as tb
    from tending.torchrl import TendingEnv

    task = tb.task(args.setup)
    setup = task.config["setup"]
    if args.train_seed_offset:
        task = SeedOffsetTask(task, args.train_seed_offset)
    name = args.algorithm if args.model == "mlp" else f"{args.algorithm}-{args.model}"
    out = args.out or ROOT / "target" / "benchmarl" / f"{name}_{setup}_seed{args.seed}"
    out.mkdir(parents=True, exist_ok=True)
    episode_steps = TendingEnv(setup, num_envs=1).episode_steps
    if args.n_envs is None:
        args.n_envs = 4 if args.hparams == "mappo" else 32
    fpb = args.frames_per_batch or args.n_envs * episode_steps

    algo = algorithm_config(args.algorithm)
    cfg = ExperimentConfig.get_from_yaml()
    if args.hparams == "mappo":
        # MAPPO's PPO (Yu et al. 2022's defaults as `tending train` sets them: policy/src/
        # train/config.rs): the whole batch as one minibatch, 10 epochs, lr 5e-4, entropy
        # 0.01, GAE lambda 0.95, gradient norm clipped at 10.
        cfg.on_policy_minibatch_size = fpb
        cfg.on_policy_n_minibatch_iters = 10
        cfg.lr = 5e-4
        cfg.clip_grad_val = 10.0
        cfg.adam_eps = 1e-5
        if hasattr(algo, "entropy_coef"):
            algo.entropy_coef = 0.01
        if hasattr(algo, "lmbda"):
            algo.lmbda = 0.95
    cfg.sampling_device = cfg.train_device = cfg.buffer_device = "cpu"
    cfg.max_n_frames = args.frames
    cfg.on_policy_collected_frames_per_batch = cfg.off_policy_collected_frames_per_batch = fpb
    cfg.on_policy_n_envs_per_worker = cfg.off_policy_n_envs_per_worker = args.n_envs
    if args.minibatch_iters is not None:
        cfg.on_policy_n_minibatch_iters = args.minibatch_iters
    if args.optimizer_steps is not None:
        cfg.off_policy_n_optimizer_steps = args.optimizer_steps
    if args.lr is not None:
        cfg.lr = args.lr
    cfg.evaluation = args.eval_every > 0
    cfg.evaluation_interval = fpb * max(args.eval_every, 1)
    cfg.evaluation_episodes = args.eval_episodes
    cfg.render = False
    cfg.loggers = ["csv"]
    cfg.create_json = False
    cfg.checkpoint_interval = fpb * args.checkpoint_every
    cfg.checkpoint_at_end = args.checkpoint_every > 0
    if args.resume or args.eval_only:
        found = sorted((out / "benchmarl").glob("**/checkpoints/checkpoint_*.pt"),
                       key=lambda f: int(f.stem.split("_")[-1]))
        if not found:
            raise SystemExit(f"--resume/--eval-only: no checkpoint under {out / 'benchmarl'} "
                             "(runs save them with --checkpoint-every)")
        cfg.restore_file = str(found[-1])
        resume_frames = int(found[-1].stem.split("_")[-1])
        print(f"resuming from {found[-1]}")
    cfg.save_folder = str(out / "benchmarl")
    (out / "benchmarl").mkdir(exist_ok=True)
    for item in args.set:
        key, _, value = item.partition("=")
        if not hasattr(cfg, key):
            raise SystemExit(f"--set: ExperimentConfig has no field {key!r}")
        setattr(cfg, key, parse_value(value))
    for item in args.algo_set:
        key, _, value = item.partition("=")
        if not hasattr(algo, key):
            raise SystemExit(f"--algo-set: {type(algo).__name__} has no field {key!r}")
        setattr(algo, key, parse_value(value))

    if args.eval_only:
        model, critic = model_configs(args, setup, MlpConfig)
        import tempfile

        # BenchMARL writes its config and logs where it saves: a scratch folder, so the
        # committed run stays as it is.
        cfg.save_folder = tempfile.mkdtemp(prefix="benchmarl-eval-")
        cfg.loggers = []
        experiment = Experiment(task=task, algorithm_config=algo, model_config=model,
                                critic_model_config=critic, seed=args.seed, config=cfg)
        evaluate(experiment.policy, setup, episode_steps, args.eval_only,
                 [int(x) for x in args.eval_seeds.split(",")], resume_frames, out,
                 layouts=args.eval_layouts)
        return

    log = CsvLog(out, append_from=resume_frames if args.resume else None)
    if not args.no_greedy and not args.resume:
        # The scripted greedy baseline through the same env: the reference to beat.
        env = TendingEnv(setup, num_envs=args.eval_episodes, seed=args.seed + 10_000)
        td = env.rollout(episode_steps, break_when_any_done=False,
                         policy=lambda td: td.set(("agents", "action"), env.greedy_actions()))
        rows = list(_rollout_rows(td.unbind(0)))
        log.episodes([["greedy", 0, 0, 0.0, e, *row] for e, row in enumerate(rows)])
        greedy = sum(r[0] for r in rows) / len(rows)
        print(f"greedy: {greedy:.1f} parts per episode ({args.eval_episodes} episodes)")

    log.start = time.perf_counter() - log.resumed_wall
    model, critic = model_configs(args, setup, MlpConfig)
    experiment = Experiment(task=task, algorithm_config=algo, model_config=model,
                            critic_model_config=critic, seed=args.seed, config=cfg,
                            callbacks=[log])
    experiment.run()
    if args.export is not None:
        from tending.benchmarl_rust import export_policy

        export_policy(experiment, args.export, training={
            "trained_by": "BenchMARL (bench/python/benchmarl_run.py --model rust)",
            "algorithm": args.algorithm, "setup": setup, "frames": experiment.total_frames,
            "seed": args.seed, "hparams": args.hparams})
        print(f"exported the policy to {args.export} (tending eval --checkpoint {args.export})")
    wall = time.perf_counter() - log.start
    print(f"{args.algorithm} on {setup}: {experiment.total_frames} frames in {wall:.0f} s "
          f"(training wall time, across resumptions) "
          f"({experiment.total_frames / wall:.0f} frames/s overall, torch threads "
          f"{torch.get_num_threads()}); CSV in {out}")


def model_configs(args, setup, MlpConfig):
    """(actor model config, critic model config or None) for --model."""
    if args.export is not None and args.model != "rust":
        raise SystemExit("--export needs --model rust (the other models are not tending's networks)")
    if args.model == "smappo":
        from tending.benchmarl_smappo import SmappoConfig

        model = SmappoConfig.for_setup(setup)
        return model, model
    if args.model == "rust":
        from tending.benchmarl_rust import RustSmappoConfig

        model = RustSmappoConfig.for_setup(setup, checkpoint=args.init)
        return model, model
    return MlpConfig.get_from_yaml(), None


def evaluate(policy, setup, steps, episodes, seeds, frames, out, layouts="benchmarl"):
    """The restored policy (argmax), the greedy script and uniform random actions on the
    same layouts. layouts "benchmarl": one env per episode, env seed 20,000 + s (none of
    training's or its evaluations' seeds); "tending": one env playing EPISODES episodes in
    sequence from seed s, the layouts of `tending eval --seeds s --episodes EPISODES`."""
    import torch
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from tending.torchrl import TendingEnv

    rows = []
    for s in seeds:
        for name in ("policy", "greedy", "random"):
            if layouts == "tending":
                env = TendingEnv(setup, num_envs=1, seed=s)
                n_steps = steps * episodes
            else:
                env = TendingEnv(setup, num_envs=episodes, seed=20_000 + s)
                n_steps = steps
            torch.manual_seed(s)
            if name == "policy":
                with set_exploration_type(ExplorationType.DETERMINISTIC), torch_no_grad():
                    td = env.rollout(n_steps, policy=policy, break_when_any_done=False)
            elif name == "greedy":
                td = env.rollout(n_steps, break_when_any_done=False, policy=lambda t, e=env:
                                 t.set(("agents", "action"), e.greedy_actions()))
            else:
                td = env.rollout(n_steps, break_when_any_done=False)
            found = list(_all_episode_rows(td.unbind(0)))
            assert len(found) == episodes, (name, s, len(found))
            for e, r in enumerate(found):
                rows.append([name, frames, s, e, *r])
    suffix = "" if layouts == "benchmarl" else f"_{layouts}"
    path = out / f"eval{suffix}.csv"
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["method", "frames", "seed", "episode", "parts_delivered", "collisions",
                    "mu", "team_reward"])
        w.writerows(rows)
    print(f"{setup}, checkpoint at {frames} frames, {episodes} episodes x seeds {seeds} "
          f"({layouts} layouts):")
    for name in ("policy", "greedy", "random"):
        mine = [r for r in rows if r[0] == name]
        mean = [sum(r[k] for r in mine) / len(mine) for k in (4, 5, 6, 7)]
        print(f"  {name:7s} parts {mean[0]:6.2f}  contact steps {mean[1]:7.1f}  MU {mean[2]:.3f}"
              f"  team reward {mean[3]:8.2f}")
    print(f"wrote {path}")


def _all_episode_rows(rollouts):
    """(parts_delivered, collisions, mu, team_reward) of every episode that ended in each
    env's trajectory, in order."""
    for td in rollouts:
        done = td.get(("next", "done")).reshape(-1)
        info = td.get(("next", "agents", "info"))
        reward = td.get(("next", "agents", "reward"))
        start = 0
        for last in done.nonzero()[:, 0].tolist():
            yield (float(info["parts_delivered"][last, 0, 0]),
                   float(info["collisions"][last, 0, 0]),
                   round(float(info["mu"][last, 0, 0]), 4),
                   round(float(reward[start:last + 1].sum()), 3))
            start = last + 1


def torch_no_grad():
    import torch

    return torch.no_grad()


class SeedOffsetTask(TendingClass):
    """A tending BenchMARL task whose envs (training and BenchMARL's evaluation) get env
    seed ``seed + offset`` (module level: BenchMARL pickles the task into config.pkl)."""

    def __init__(self, task, offset):
        super().__init__(name=task.name, config=task.config)
        self.offset = offset

    def get_env_fun(self, num_envs, continuous_actions, seed, device):
        return super().get_env_fun(num_envs, continuous_actions, (seed or 0) + self.offset,
                                   device)


class CsvLog(Callback):
    """Appends every finished episode to episodes.csv and every iteration to
    iterations.csv (files opened per write: BenchMARL pickles its callbacks)."""

    def __init__(self, out: Path, append_from: int | None = None):
        super().__init__()
        self.out = out
        self.start = time.perf_counter()
        self.last = None
        self.iteration = 0
        self.resumed_wall = 0.0
        if append_from is not None:
            # A resumed run continues from its checkpoint's frame count: rows logged after
            # that checkpoint (the stopped run went on) are dropped, then the iteration
            # count and the wall clock continue from the last row kept.
            for name in ("iterations.csv", "episodes.csv"):
                with open(out / name) as f:
                    rows = list(csv.reader(f))
                col = rows[0].index("frames")
                kept = [rows[0]] + [r for r in rows[1:] if int(r[col]) <= append_from]
                self._write(name, kept, "w")
            with open(out / "iterations.csv") as f:
                rows = list(csv.reader(f))[1:]
            if rows:
                self.iteration = int(rows[-1][0]) + 1
                self.resumed_wall = float(rows[-1][2])
            return
        self._write("episodes.csv", [["phase", "iteration", "frames", "wall_s", "env",
                                      "parts_delivered", "collisions", "mu", "team_reward"]], "w")
        self._write("iterations.csv", [["iteration", "frames", "wall_s", "iteration_s",
                                        "frames_per_s", "episodes", "parts_delivered",
                                        "team_reward"]], "w")

    def __getstate__(self):
        # BenchMARL pickles its callbacks into config.pkl; the experiment (and its envs,
        # Rust objects) stays out.
        return {k: v for k, v in self.__dict__.items() if k != "experiment"}

    def _write(self, name, rows, mode="a"):
        with open(self.out / name, mode, newline="") as f:
            csv.writer(f).writerows(rows)

    def episodes(self, rows):
        self._write("episodes.csv", rows)

    def on_batch_collected(self, batch):
        import tending.benchmarl as tb

        now = time.perf_counter()
        it, frames = self.iteration, self.experiment.total_frames
        rows = tb.episode_rows(batch)
        env_of = batch.get(("next", "done")).squeeze(-1).nonzero()[:, 0].tolist()
        self.episodes([["train", it, frames, f"{now - self.start:.2f}", e, r["parts_delivered"],
                        r["collisions"], f"{r['mu']:.4f}", f"{r['team_reward']:.3f}"]
                       for e, r in zip(env_of, rows)])
        # From the previous collection's end to this one's: training, evaluation, collection
        # (the first: set-up and the first collection).
        dt = now - (self.last if self.last is not None else self.start)
        n = batch.numel()

        def mean(k):
            return sum(r[k] for r in rows) / len(rows) if rows else float("nan")

        self._write("iterations.csv", [[it, frames, f"{now - self.start:.2f}", f"{dt:.2f}",
                                        f"{n / dt:.1f}", len(rows),
                                        f"{mean('parts_delivered'):.2f}",
                                        f"{mean('team_reward'):.2f}"]])
        print(f"iter {it}: {frames} frames, {now - self.start:.0f} s, {n / dt:.0f} frames/s, "
              f"parts {mean('parts_delivered'):.1f}, team reward {mean('team_reward'):.1f}",
              flush=True)
        self.iteration += 1
        self.last = now

    def on_evaluation_end(self, rollouts):
        now = time.perf_counter()
        rows = list(_rollout_rows(rollouts))
        self.episodes([["eval", self.iteration - 1, self.experiment.total_frames,
                        f"{now - self.start:.2f}", e, *row] for e, row in enumerate(rows)])
        parts = sum(r[0] for r in rows) / max(len(rows), 1)
        print(f"  eval: parts {parts:.1f} per episode ({len(rows)} episodes)", flush=True)


def _rollout_rows(rollouts):
    """(parts_delivered, collisions, mu, team_reward) of each evaluation rollout (one env's
    steps, ending where its episode ended)."""
    for td in rollouts:
        done = td.get(("next", "done")).reshape(-1)
        if not done.any():
            continue
        last = int(done.nonzero()[0, 0])
        info = td.get(("next", "agents", "info"))[last]
        team = float(td.get(("next", "agents", "reward"))[: last + 1].sum())
        yield (float(info["parts_delivered"][0, 0]), float(info["collisions"][0, 0]),
               round(float(info["mu"][0, 0]), 4), round(team, 3))


if __name__ == "__main__":
    main()
