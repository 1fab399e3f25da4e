"""PettingZoo's own API and seed tests, Gymnasium space checks, determinism."""

import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.utils.env_checker import data_equivalence
from pettingzoo.test import parallel_api_test, parallel_seed_test

import tending

SETUPS = ["2.2_2", "6.4_2", "14.10_4", "1.1_1"]


@pytest.mark.parametrize("setup", SETUPS)
def test_parallel_api(setup):
    parallel_api_test(tending.parallel_env(setup, seed=1), num_cycles=300)


def test_parallel_api_flat():
    parallel_api_test(tending.parallel_env("6.4_2", seed=1, obs_layout="flat"), num_cycles=300)


@pytest.mark.parametrize("setup", ["2.2_2", "6.4_2", "14.10_4"])
def test_parallel_seed(setup):
    parallel_seed_test(lambda: tending.parallel_env(setup, seed=5), num_cycles=250)


@pytest.mark.parametrize("layout", ["dict", "flat"])
@pytest.mark.parametrize("setup", ["1.1_1", "6.4_2", "14.10_4"])
def test_observations_are_in_their_spaces_for_a_whole_episode(setup, layout):
    env = tending.parallel_env(setup, seed=2, obs_layout=layout)
    obs, infos = env.reset()
    for a in env.agents:
        assert isinstance(env.action_space(a), spaces.Discrete) and env.action_space(a).n == 5
    sp = env.observation_space(env.agents[0])
    assert isinstance(sp, spaces.Dict if layout == "dict" else spaces.Box)
    rng = np.random.default_rng(0)
    steps = 0
    while env.agents:
        for a, o in obs.items():
            assert env.observation_space(a).contains(o), (a, o)
        acts = {a: int(rng.integers(5)) for a in env.agents}
        obs, rew, term, trunc, infos = env.step(acts)
        for a in rew:
            assert isinstance(rew[a], float) and np.isfinite(rew[a])
            assert term[a] is False
        steps += 1
    assert steps == env.episode_steps == 200
    assert all(trunc.values())


def test_dict_observation_shapes_follow_the_setup():
    env = tending.parallel_env("14.10_4")
    obs, _ = env.reset()
    assert env.agents == [f"robot_{i}" for i in range(14)]
    o = obs["robot_3"]
    assert o["self"].shape == (3,) and o["machines"].shape == (10, 3)
    assert o["storages"].shape == (4, 2) and o["peers"].shape == (13, 3)
    assert all(v.dtype == np.float32 for v in o.values())
    sp = env.observation_space("robot_3")
    assert sp["peers"].shape == (13, 3)


def test_flat_layout_is_the_padded_concatenation():
    d = tending.parallel_env("6.4_2", seed=4)
    f = tending.parallel_env("6.4_2", seed=4, obs_layout="flat", flat_max=(6, 3, 9))
    od, _ = d.reset()
    of, _ = f.reset()
    assert f.observation_space("robot_0").shape == (3 + 6 * 3 + 3 * 2 + 9 * 3,)
    for a in d.agents:
        o = od[a]
        want = np.concatenate([
            o["self"],
            np.pad(o["machines"], ((0, 2), (0, 0))).ravel(),
            np.pad(o["storages"], ((0, 1), (0, 0))).ravel(),
            np.pad(o["peers"], ((0, 4), (0, 0))).ravel(),
        ])
        np.testing.assert_array_equal(of[a], want)


def run_episode(env, seed, actions_seed):
    rng = np.random.default_rng(actions_seed)
    obs, _ = env.reset(seed=seed)
    trace = [obs]
    while env.agents:
        obs, rew, _, _, infos = env.step({a: int(rng.integers(5)) for a in env.agents})
        trace.append((obs, rew, {a: {k: v for k, v in i.items()} for a, i in infos.items()}))
    return trace, env.metrics()


def test_same_seed_same_episode_and_different_seed_differs():
    e1 = tending.parallel_env("14.10_4", seed=0)
    e2 = tending.parallel_env("14.10_4", seed=123)
    t1, m1 = run_episode(e1, 7, 0)
    t2, m2 = run_episode(e2, 7, 0)
    assert data_equivalence(t1, t2) and m1 == m2
    t3, m3 = run_episode(e2, 8, 0)
    assert not data_equivalence(t1[0], t3[0])


def test_reset_without_seed_walks_the_episode_sequence():
    env = tending.parallel_env("6.4_2", seed=11)
    first = [env.reset()[0] for _ in range(3)]
    again = [env.reset(seed=11)[0]] + [env.reset()[0] for _ in range(2)]
    assert data_equivalence(first, again)
    assert not data_equivalence(first[0], first[1])


def test_infos_carry_events_and_metrics():
    env = tending.parallel_env("6.4_2", seed=0)
    obs, _ = env.reset()
    picks = places = 0
    while env.agents:
        obs, rew, _, _, infos = env.step(env.greedy_actions(obs))
        for a, i in infos.items():
            assert set(i) == {"picked", "placed", "collisions", "metrics"}
            picks += i["picked"] >= 0
            places += i["placed"] >= 0
    m = infos["robot_0"]["metrics"]
    assert m["parts_collected"] == picks > 0
    assert m["parts_delivered"] == places > 0
    assert m["collisions"] == sum(m[f"collisions_robot_{k}"] for k in ("robot", "machine", "storage", "wall"))
    assert m["mu"] == pytest.approx(m["parts_collected"] / m["p_max"])
    assert m["steps"] == 200


def test_render_rgb_array():
    env = tending.parallel_env("6.4_2", render_mode="rgb_array", render_size=200)
    env.reset()
    img = env.render()
    assert img.shape == (200, 200, 3) and img.dtype == np.uint8
    # Robots red, ready machines green, storages blue are all on the frame.
    px = img.reshape(-1, 3)
    for colour in ([210, 40, 40], [30, 170, 60], [60, 90, 220]):
        assert (px == colour).all(axis=1).any(), colour
    env.step({a: 2 for a in env.agents})
    assert not np.array_equal(img, env.render())
    with pytest.warns(UserWarning, match="render_mode"):
        assert tending.parallel_env("6.4_2").render() is None


def test_state_is_in_state_space_and_follows_live_counts():
    env = tending.parallel_env("6.4_2", seed=0)
    env.reset()
    st = env.state()
    assert st.shape == (6 * 3 + 4,) and env.state_space.contains(st)
    env.add_robot()
    assert env.state().shape == (7 * 3 + 4,) and env.state_space.contains(env.state())


def test_diagonal_actions():
    env = tending.parallel_env("2.2_2", seed=0, diagonal_actions=True)
    assert env.action_space("robot_0").n == 9
    parallel_api_test(env, num_cycles=50)
    obs, _ = env.reset()
    before = obs["robot_0"]["self"][:2].copy()
    for _ in range(3):
        obs, *_ = env.step({"robot_0": 8, "robot_1": 0})  # right-up
    d = obs["robot_0"]["self"][:2] - before
    assert d[0] > 0.02 and d[1] > 0.02 and d[0] == pytest.approx(d[1], rel=0.2)
    plain = tending.parallel_env("2.2_2")
    plain.reset()
    with pytest.raises(ValueError, match="action 8 for robot_0 is not one of 0..5"):
        plain.step({"robot_0": 8, "robot_1": 0})
    v = tending.vector_env("2.2_2", n_envs=2, diagonal_actions=True)
    v.reset()
    v.step(np.full((2, 2), 8))
    with pytest.raises(ValueError, match="action 9"):
        v.step(np.full((2, 2), 9))


def test_velocity_actions():
    env = tending.parallel_env("6.4_2", seed=3, action_type="velocity")
    sp = env.action_space("robot_0")
    assert isinstance(sp, spaces.Box) and sp.shape == (2,) and sp.high[0] == env.k_speed
    parallel_api_test(env, num_cycles=100)
    parallel_seed_test(lambda: tending.parallel_env("6.4_2", seed=3, action_type="velocity"),
                       num_cycles=100)
    # A velocity of (k_speed, 0) is discrete action 2 (right): same trajectory and rewards.
    d = tending.parallel_env("6.4_2", seed=3)
    od, _ = d.reset(seed=4)
    ov, _ = env.reset(seed=4)
    rng = np.random.default_rng(0)
    k = env.k_speed
    table = {0: (0, 0), 1: (-k, 0), 2: (k, 0), 3: (0, -k), 4: (0, k)}
    for _ in range(50):
        acts = {a: int(rng.integers(5)) for a in d.agents}
        od, rd, *_ = d.step(acts)
        ov, rv, *_ = env.step({a: np.array(table[x], np.float32) for a, x in acts.items()})
        assert data_equivalence(od, ov) and rd == rv
    with pytest.raises(ValueError, match="robot_1.*not finite"):
        env.step({a: (np.nan, 0.0) if a == "robot_1" else (0.0, 0.0) for a in env.agents})
    with pytest.raises(ValueError, match="robot_0"):
        env.step({a: (1.0, 2.0, 3.0) for a in env.agents})
    with pytest.raises(ValueError, match="action_type"):
        tending.parallel_env("6.4_2", action_type="torque")
