"""tending.rllib: the RLlib RLModule is tending.smappo_torch's actor and critic, and what
PPO trains with it exports to a checkpoint that `tending eval` runs.

A smoke test only (one PPO iteration of 2,400 env steps, one epoch): that it learns is the
Ray-cluster run's job (issue 48). ray[rllib] and torch are not installed by CI: these tests
skip, saying so, when either is absent.
"""

from pathlib import Path

import numpy as np
import pytest
from conftest import rust_eval_row

torch = pytest.importorskip(
    "torch", reason="torch is not installed (an optional extra): tending.rllib needs it")
pytest.importorskip(
    "ray.rllib", reason="ray[rllib] is not installed (bench/python/requirements-rllib.txt): "
    "tending.rllib needs it")
from ray.rllib.core.columns import Columns  # noqa: E402

import tending  # noqa: E402
from tending import smappo_torch as st  # noqa: E402
from tending.rllib import (  # noqa: E402
    GROUPS, SmappoRLModule, TendingMultiAgentEnv, export_policy, export_trainer_state, smappo_ppo_config)

ROOT = Path(__file__).resolve().parents[2]


def module_for(env, **model_config):
    a = env.possible_agents[0]
    return SmappoRLModule(observation_space=env.observation_spaces[a], action_space=env.action_spaces[a],
                          model_config={"max_seq_len": 10, **model_config})


def batch_of(obs, agents, state):
    """RLlib's layout for a stateful module: (B, T=1, ...) observations, (B, ...) states."""
    stack = lambda xs: torch.from_numpy(np.stack(xs))[:, None]  # noqa: E731
    o = {g: stack([obs[a][g] for a in agents]) for g in GROUPS}
    if "team" in obs[agents[0]]:
        o["team"] = {g: stack([obs[a]["team"][g] for a in agents]) for g in GROUPS}
    return {Columns.OBS: o, Columns.STATE_IN: state}


@pytest.mark.parametrize("centralised", [True, False])
def test_module_runs_the_rust_networks(centralised):
    """Three steps of 6.4_2: the module's logits and states are the Actor's, its values the
    centralised Critic's over the env's robots (or, decentralised, over the robot alone)."""
    torch.manual_seed(0)
    env = TendingMultiAgentEnv({"setup": "6.4_2", "centralised_critic": centralised})
    m = module_for(env, checkpoint=str(ROOT / "policy/pretrained/smappo_moves_6.4_2.safetensors"))
    ref = st.Actor.load(ROOT / "policy/pretrained/smappo_moves_6.4_2.safetensors")
    for k, v in ref.state_dict().items():
        assert torch.equal(v, m.actor.state_dict()[k]), k
    obs, _ = env.reset(seed=0)
    agents = list(obs)
    n = len(agents)
    state = {k: torch.from_numpy(np.stack([v] * n)) for k, v in m.get_initial_state().items()}
    h_ref = vh_ref = None
    with torch.no_grad():
        for _ in range(3):
            batch = batch_of(obs, agents, state)
            out = m.forward_exploration(batch)
            values = m.compute_values(batch)[:, 0]
            arrs = {g: torch.from_numpy(np.stack([obs[a][g] for a in agents])) for g in GROUPS}
            logits, h_ref = ref(arrs, h_ref)
            team = {g: v[None] for g, v in arrs.items()} if centralised else {g: v[:, None] for g, v in arrs.items()}
            v_ref, vh_ref = m.critic(team, vh_ref)
            assert torch.allclose(out[Columns.ACTION_DIST_INPUTS][:, 0], logits, atol=1e-5)
            assert torch.allclose(out[Columns.STATE_OUT]["h"], h_ref, atol=1e-5)
            assert torch.allclose(values, v_ref.reshape(n), atol=1e-5)
            assert torch.allclose(out[Columns.STATE_OUT]["vh"], vh_ref.reshape(n, -1), atol=1e-5)
            state = out[Columns.STATE_OUT]
            acts = logits.argmax(-1).tolist()
            obs, *_ = env.step(dict(zip(agents, acts)))


def test_value_norm_is_mappos():
    """The module's ValueNorm is learn/src/valuenorm.rs's (MAPPO's): its reference numbers for
    two updates with beta 0.9, the variance floor, and compute_values denormalising the
    critic's output (normalised while the learner's loss runs)."""
    env = TendingMultiAgentEnv({"setup": "6.4_2"})
    m = module_for(env, value_norm=True)
    mean, var = m.vn_mean_var()  # never updated: mean 0, variance at its floor
    assert mean.item() == 0.0 and abs(var.item() - 1e-2) < 1e-15
    m.VN_BETA = 0.9
    m.vn_update(torch.tensor([1.0, 3.0]))
    mean, var = m.vn_mean_var()
    assert abs(mean.item() - 2.0) < 1e-12 and abs(var.item() - 1.0) < 1e-12
    assert abs(m.vn_normalize(torch.tensor([3.0])).item() - 1.0) < 1e-6
    m.vn_update(torch.tensor([4.0]))
    mean, var = m.vn_mean_var()
    assert abs(mean.item() - 3.0526315789) < 1e-9 and abs(var.item() - 1.4709141274) < 1e-9
    obs, _ = env.reset(seed=0)
    agents = list(obs)
    state = {k: torch.from_numpy(np.stack([v] * len(agents))) for k, v in m.get_initial_state().items()}
    batch = batch_of(obs, agents, state)
    with torch.no_grad():
        m._values_normalised = True
        raw = m.compute_values(batch)
        m._values_normalised = False
        v = m.compute_values(batch)
    assert torch.allclose(v, raw * var.sqrt().float() + mean.float(), atol=1e-5)
    assert "vn_stats" in m.state_dict()  # carried to the env runners and into RLlib checkpoints


def test_ppo_iteration_exports_a_checkpoint_tending_eval_runs(tmp_path, tending_bin):
    import ray

    torch.set_num_threads(1)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        algo = smappo_ppo_config("6.4_2", env_runners=0).training(num_epochs=1).build_algo()
        before = {k: v.clone() for k, v in algo.get_module("shared").actor.state_dict().items()}
        r = algo.train()
        assert r["env_runners"]["num_env_steps_sampled_lifetime"] >= 800
        path, state = tmp_path / "rllib.safetensors", tmp_path / "rllib_state.safetensors"
        actor = export_policy(algo, path)
        export_trainer_state(algo, state)
        algo.stop()
    finally:
        ray.shutdown()
    # trained: the weights moved; exported: they load back as they were
    assert any(not torch.equal(before[k], v) for k, v in actor.state_dict().items())
    back = st.Actor.load(path)
    for k, v in actor.state_dict().items():
        assert torch.equal(v, back.state_dict()[k]), k
    st.Critic.load(state)
    # the Rust evaluation of the exported file equals the torch-side one
    row = rust_eval_row(tending_bin, path, tmp_path)
    env = tending.parallel_env("6.4_2", seed=0)
    env.reset(seed=0)
    h = None
    while env.agents:
        own, m, k, pe = env.observe_arrays()
        acts, h = back.act({"self": own, "machines": m, "storages": k, "peers": pe}, h)
        env.step(dict(zip(env.agents, acts.tolist())))
    got = env.metrics()
    assert (int(float(row["parts_delivered"])), int(float(row["collisions"]))) == (
        got["parts_delivered"], got["collisions"])
