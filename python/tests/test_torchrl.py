"""The TorchRL env (tending.torchrl) and the BenchMARL task (tending.benchmarl).

torch, torchrl and benchmarl are an optional extra (`pip install './python[torchrl]'`, a
4-5 GB install) that CI does not install: these tests skip, saying so, when they are
absent; `import tending` must not need them (checked always)."""

import subprocess
import sys

import numpy as np
import pytest

import tending

SKIP = "the optional torchrl extra is not installed (pip install './python[torchrl]')"


def need_torchrl():
    pytest.importorskip("torch", reason=f"torch: {SKIP}")
    pytest.importorskip("tensordict", reason=f"tensordict: {SKIP}")
    pytest.importorskip("torchrl", reason=f"torchrl: {SKIP}")
    from tending import torchrl as ttrl

    return ttrl


def test_import_tending_does_not_import_torch():
    code = "import sys, tending; sys.exit(1 if 'torch' in sys.modules else 0)"
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


def test_check_env_specs():
    ttrl = need_torchrl()
    from torchrl.envs.utils import check_env_specs

    for categorical in (True, False):
        env = ttrl.TendingEnv("6.4_2", num_envs=3, seed=1, categorical_actions=categorical)
        check_env_specs(env, break_when_any_done="both")
    env = ttrl.TendingEnv("2.2_2", num_envs=2, seed=0)  # one peer per robot
    check_env_specs(env)


def test_layout_and_shapes():
    ttrl = need_torchrl()
    import torch

    env = ttrl.TendingEnv("14.10_4", num_envs=2, seed=0)
    assert env.batch_size == torch.Size([2]) and env.obs_dim == 3 + 30 + 8 + 39
    td = env.rollout(3)
    assert td["agents", "observation"].shape == (2, 3, 14, 80)
    assert td["agents", "observation"].dtype == torch.float32
    assert td["next", "agents", "reward"].shape == (2, 3, 14, 1)
    assert td["agents", "action"].shape == (2, 3, 14)
    for key in ("done", "terminated", "truncated"):
        assert td["next", key].shape == (2, 3, 1)
        assert td["next", "agents", key].shape == (2, 3, 14, 1)
    assert env.group_map == {"agents": [f"robot_{i}" for i in range(14)]}


def test_rollout_equals_the_pettingzoo_env_across_an_episode_end():
    """Env 0 of the batch is tending.parallel_env(obs_layout='flat') with the same seed:
    step returns an episode's final observation with done; the reset that follows (the
    `_reset` mask step_and_maybe_reset sends) returns the next episode's first one."""
    ttrl = need_torchrl()
    import torch

    seed, steps = 5, 203
    env = ttrl.TendingEnv("6.4_2", num_envs=2, seed=seed)
    pz = tending.parallel_env("6.4_2", seed=seed, obs_layout="flat")
    rng = np.random.default_rng(0)
    actions = torch.from_numpy(rng.integers(0, 5, size=(2, steps, 6)))
    t = [0]

    def policy(td):
        td["agents", "action"] = actions[:, t[0]]
        t[0] += 1
        return td

    td = env.rollout(steps, policy=policy, break_when_any_done=False)
    obs, _ = pz.reset()
    episode_end = None
    for k in range(steps):
        np.testing.assert_array_equal(td["agents", "observation"][0, k].numpy(),
                                      np.stack([obs[a] for a in pz.agents]))
        agents = pz.agents
        obs, rew, term, trunc, infos = pz.step(
            {a: int(actions[0, k, i]) for i, a in enumerate(agents)})
        nxt = td["next"][0, k]
        np.testing.assert_array_equal(nxt["agents", "observation"].numpy(),
                                      np.stack([obs[a] for a in agents]))
        np.testing.assert_array_equal(nxt["agents", "reward"][:, 0].numpy(),
                                      np.array([rew[a] for a in agents], np.float32))
        done = all(trunc.values())
        assert bool(nxt["done"]) == done == bool(nxt["truncated"])
        assert bool(nxt["agents", "done"].all()) == done and not nxt["terminated"].any()
        m = infos[agents[0]]["metrics"]
        if done:
            episode_end = k
            assert nxt["agents", "info", "parts_delivered"][0, 0] == m["parts_delivered"]
            assert nxt["agents", "info", "collisions"][0, 0] == m["collisions"]
            assert nxt["agents", "info", "mu"][0, 0] == pytest.approx(m["mu"])
            obs, _ = pz.reset()  # the next episode: episode_seed(seed, 0, 1)
        else:
            assert not nxt["agents", "info", "parts_delivered"].any()
    assert episode_end == env.episode_steps - 1


def test_partial_reset_of_running_envs_is_refused_and_seed_restarts():
    ttrl = need_torchrl()
    import torch

    env = ttrl.TendingEnv("6.4_2", num_envs=2, seed=3)
    td = env.reset()
    first = td["agents", "observation"].clone()
    env.rand_step(td)
    from tensordict import TensorDict

    with pytest.raises(RuntimeError, match="mid-episode"):
        env.reset(TensorDict({"_reset": torch.tensor([[True], [False]])}, batch_size=[2]))
    assert torch.equal(env.reset()["agents", "observation"], first)  # restart at episode 0
    env.set_seed(4)
    assert not torch.equal(env.reset()["agents", "observation"], first)


def test_greedy_through_the_torchrl_env_delivers_parts():
    ttrl = need_torchrl()

    env = ttrl.TendingEnv("6.4_2", num_envs=2, seed=0)
    td = env.rollout(env.episode_steps,
                     policy=lambda td: td.set(("agents", "action"), env.greedy_actions()))
    assert td["next", "done"][:, -1].all()
    assert (td["next", "agents", "info", "parts_delivered"][:, -1] > 10).all()


def test_benchmarl_task():
    need_torchrl()
    pytest.importorskip("benchmarl", reason=f"benchmarl: {SKIP}")
    import benchmarl.environments as envs
    from tending import benchmarl as tb

    assert envs.task_config_registry["tending/6.4_2"] is tb.TendingTask["6.4_2"]
    task = tb.task("tending/9.6_3")
    assert task.name == "9.6_3" and task.env_name() == "tending"
    env = task.get_env_fun(num_envs=2, continuous_actions=False, seed=0, device="cpu")()
    assert task.max_steps(env) == 200 and task.group_map(env)["agents"][0] == "robot_0"
    assert list(task.observation_spec(env)["agents"].keys()) == ["observation"]
    assert set(task.info_spec(env)["agents", "info"].keys()) == {"parts_delivered",
                                                                "collisions", "mu"}
    assert tb.TendingTask["6.4_2"].get_from_yaml().config == {"setup": "6.4_2"}


def test_benchmarl_mappo_with_the_smappo_encoder_runs():
    """The paper's encoder as a BenchMARL model, actor and critic: one short MAPPO
    iteration on 2.2_2 (one peer per robot); a config for another setup is refused naming
    the feature counts."""
    need_torchrl()
    pytest.importorskip("benchmarl", reason=f"benchmarl: {SKIP}")
    import torch
    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig

    import tending.benchmarl as tb
    from tending.benchmarl_smappo import SmappoConfig

    torch.set_num_threads(1)

    def experiment(model, tmp):
        cfg = ExperimentConfig.get_from_yaml()
        cfg.sampling_device = cfg.train_device = cfg.buffer_device = "cpu"
        cfg.max_n_frames = 800
        cfg.on_policy_collected_frames_per_batch = 800
        cfg.on_policy_n_envs_per_worker = 4
        cfg.on_policy_n_minibatch_iters = 1
        cfg.evaluation = False
        cfg.loggers = []
        cfg.checkpoint_interval = 0
        cfg.checkpoint_at_end = False
        cfg.save_folder = str(tmp)
        return Experiment(task=tb.task("2.2_2"), algorithm_config=MappoConfig.get_from_yaml(),
                          model_config=model, seed=0, config=cfg)  # critic: a copy of model

    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        e = experiment(SmappoConfig.for_setup("2.2_2"), tmp)
        before = [p.detach().clone() for p in e.policy.parameters()]
        e.run()
        assert e.total_frames == 800
        after = list(e.policy.parameters())
        assert any(not torch.equal(a, b) for a, b in zip(after, before)), "no update"
        with pytest.raises(ValueError, match="features"):
            experiment(SmappoConfig.for_setup("2.4_2"), tmp)
    with pytest.raises(ValueError, match="N.M_K"):
        SmappoConfig.for_setup("six")


def test_benchmarl_run_trains_checkpoints_and_evaluates_beside_greedy(tmp_path):
    """bench/python/benchmarl_run.py end to end on 2.2_2: two iterations with MAPPO's PPO
    settings, a checkpoint, then --eval-only: the restored policy and greedy on the same
    layouts, one row per episode each; bad field names are refused by name."""
    need_torchrl()
    pytest.importorskip("benchmarl", reason=f"benchmarl: {SKIP}")
    import csv
    import importlib.util
    import sys
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "bench" / "python" / "benchmarl_run.py"
    spec = importlib.util.spec_from_file_location("benchmarl_run", path)
    run = importlib.util.module_from_spec(spec)
    sys.modules["benchmarl_run"] = run  # BenchMARL pickles the run's callback by module name
    spec.loader.exec_module(run)
    base = ["--algorithm", "mappo", "--model", "smappo", "--hparams", "mappo", "--setup",
            "2.2_2", "--frames", "1600", "--out", str(tmp_path)]
    run.main(base + ["--eval-every", "0", "--checkpoint-every", "1", "--no-greedy"])
    with open(tmp_path / "iterations.csv") as f:
        its = list(csv.DictReader(f))
    assert [int(r["frames"]) for r in its] == [800, 1600]
    run.main(base + ["--eval-only", "3", "--eval-seeds", "0,1"])
    with open(tmp_path / "eval.csv") as f:
        rows = list(csv.DictReader(f))
    for method in ("policy", "greedy"):
        mine = [r for r in rows if r["method"] == method]
        assert len(mine) == 6, method
        assert all(int(r["frames"]) == 1600 for r in mine)
    greedy_parts = sum(float(r["parts_delivered"]) for r in rows if r["method"] == "greedy")
    assert greedy_parts > 0, "greedy delivers on 2.2_2"
    with pytest.raises(SystemExit, match="no_such_field"):
        run.main(base + ["--algo-set", "no_such_field=1"])
    with pytest.raises(SystemExit, match="no checkpoint"):
        run.main(base[:-1] + [str(tmp_path / "empty"), "--eval-only", "2"])


def test_benchmarl_run_evaluates_on_the_layouts_tending_eval_plays(tmp_path, request):
    """--eval-layouts tending plays, per eval seed s, episodes 0.. of one env of seed s:
    the layouts `tending eval --seeds s` plays, so its greedy rows equal `tending eval
    --policy greedy`'s (parts, contacts, MU per seed); --train-seed-offset trains elsewhere
    (docs/experiments/benchmarl_mappo.md)."""
    need_torchrl()
    pytest.importorskip("benchmarl", reason=f"benchmarl: {SKIP}")
    tending_bin = request.getfixturevalue("tending_bin")  # only once the extra is there
    import csv
    import importlib.util
    import subprocess
    import sys
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "bench" / "python" / "benchmarl_run.py"
    spec = importlib.util.spec_from_file_location("benchmarl_run", path)
    run = importlib.util.module_from_spec(spec)
    sys.modules["benchmarl_run"] = run
    spec.loader.exec_module(run)
    base = ["--algorithm", "mappo", "--model", "mlp", "--hparams", "mappo", "--setup", "2.2_2",
            "--train-seed-offset", "1000", "--out", str(tmp_path / "run")]
    run.main(base + ["--frames", "800", "--eval-every", "0", "--checkpoint-every", "1",
                     "--no-greedy"])
    run.main(base + ["--eval-only", "3", "--eval-seeds", "0,1", "--eval-layouts", "tending"])
    with open(tmp_path / "run" / "eval_tending.csv") as f:
        rows = list(csv.DictReader(f))
    for method in ("policy", "greedy", "random"):
        assert len([r for r in rows if r["method"] == method]) == 6, method
    p = subprocess.run([tending_bin, "eval", "--policy", "greedy", "--setups", "2.2_2",
                        "--seeds", "0,1", "--episodes", "3", "--out", str(tmp_path / "rust")],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    with open(tmp_path / "rust" / "results.csv") as f:
        rust = {r["seed"]: r for r in csv.DictReader(f)}
    for seed in ("0", "1"):
        mine = [r for r in rows if r["method"] == "greedy" and r["seed"] == seed]
        for key in ("parts_delivered", "collisions", "mu"):
            py = sum(float(r[key]) for r in mine) / len(mine)
            assert py == pytest.approx(float(rust[seed][key]), abs=1e-3), (seed, key)
