"""The VMAS twin of the tending scenario (bench/python/vmas_tending.py): spaces, a batched
step, and the pick/place rules.

torch and vmas are optional (the torchrl extra plus `pip install vmas`), not installed by
CI: the tests skip, saying so, when either is absent."""

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SKIP = "needs torch and vmas (pip install './python[torchrl]' vmas==1.5.2)"


@pytest.fixture(scope="module")
def vt():
    pytest.importorskip("torch", reason=f"torch absent: {SKIP}")
    pytest.importorskip("vmas", reason=f"vmas absent: {SKIP}")
    sys.path.insert(0, str(ROOT / "bench" / "python"))
    try:
        import vmas_tending
    finally:
        sys.path.pop(0)
    return vmas_tending


def make(vt, n_envs=3, **kw):
    import torch
    from vmas import make_env

    torch.manual_seed(0)
    return make_env(vt.TendingScenario(), num_envs=n_envs, continuous_actions=False,
                    max_steps=200, seed=0, device="cpu", setup="6.4_2", **kw)


def stay(env):
    import torch

    return [torch.zeros(env.num_envs, dtype=torch.long) for _ in env.agents]


def test_spaces_and_one_step(vt):
    import torch

    env = make(vt)
    obs = env.reset()
    assert len(env.agents) == 6
    assert all(sp.n == 5 for sp in env.action_space.spaces)
    # full: own 5 + machines 4x4 + storages 2x2 + peers 5x3
    assert [o.shape for o in obs] == [torch.Size([3, 40])] * 6
    actions = [torch.randint(0, 5, (3,)) for _ in env.agents]
    obs, rews, dones, infos = env.step(actions)
    assert [r.shape for r in rews] == [torch.Size([3])] * 6
    assert all(torch.isfinite(r).all() for r in rews)
    assert not dones.any()
    assert set(infos[0]) == {"parts_delivered", "collisions", "mu"}
    # The "tending" layout is TendingEnv's flat vector: 3 + 3M + 2K + 3(N-1).
    env = make(vt, obs_layout="tending")
    assert env.reset()[0].shape == (3, 3 + 12 + 4 + 15)


def test_moves_are_the_papers(vt):
    env = make(vt)
    env.reset()
    a = env.agents[0]
    for action, sign in ((2, (1, 0)), (1, (-1, 0)), (4, (0, 1)), (3, (0, -1))):
        env.reset()
        acts = stay(env)
        acts[0][:] = action
        env.step(acts)
        v = a.state.vel[0].tolist()
        assert v == pytest.approx([0.3 * sign[0], 0.3 * sign[1]], abs=0.05), (action, v)


def test_robot_at_ready_machine_picks_then_places(vt):
    import torch

    env = make(vt)
    env.reset()
    sc = env.scenario
    r, mh = sc.sizes["robot_radius"], sc.sizes["machine_half"]
    robot = env.agents[0]
    # Robot 0 beside machine 0 of env 1 (surface gap 0.03 m, inside the 0.08 m reach).
    spot = sc.m_pos[1, 0] + torch.tensor([mh[0] + r + 0.03, 0.0])
    robot.set_pos(spot, batch_index=1)
    assert sc.ready[1, 0] and not sc.has_part[1, 0]
    _, rews, _, _ = env.step(stay(env))
    assert sc.has_part[1, 0], "a robot within reach of a ready machine must pick its part"
    assert not sc.ready[1, 0] and int(sc.timer[1, 0]) == sc.c["prep_steps"]
    assert float(rews[0][1]) >= sc.c["pick"] - 1.0
    # The machine makes the next part only after prep_steps: the next step picks nothing.
    env.step(stay(env))
    assert not sc.ready[1, 0]
    # Carried to a storage, the part is delivered.
    sh = sc.sizes["storage_half"]
    robot.set_pos(sc.s_pos[1, 0] + torch.tensor([0.0, sh[1] + r + 0.03]), batch_index=1)
    _, rews, _, _ = env.step(stay(env))
    assert not sc.has_part[1, 0] and float(sc.delivered[1]) == 1
    assert float(rews[0][1]) >= sc.c["place"] - 1.0
