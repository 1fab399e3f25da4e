"""Robots, machines and storage areas join and leave between steps."""

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

import tending


def test_add_and_remove_robots_between_steps():
    env = tending.parallel_env("6.4_2", seed=3)
    obs, _ = env.reset()
    for _ in range(5):
        obs, *_ = env.step(env.greedy_actions(obs))
    new = env.add_robot()
    assert new == "robot_6" and env.agents[-1] == new and new in env.possible_agents
    obs = env.observe()
    assert set(obs) == set(env.agents) and len(env.agents) == 7
    assert obs[new]["peers"].shape == (6, 3) and obs["robot_0"]["peers"].shape == (6, 3)
    assert env.observation_space(new).contains(obs[new])
    obs, rew, _, _, infos = env.step(env.greedy_actions(obs))
    assert set(rew) == set(infos) == set(env.agents)

    env.remove_robot("robot_2")
    assert "robot_2" not in env.agents and len(env.agents) == 6
    obs = env.observe()
    assert set(obs) == set(env.agents)
    assert obs["robot_0"]["peers"].shape == (5, 3)
    with pytest.raises(ValueError, match="robot_2"):
        env.step({a: 0 for a in env.agents} | {"robot_2": 0})
    # The next step reports the removed robot once, terminated, with its last observation.
    obs, rew, term, trunc, infos = env.step(env.greedy_actions(obs))
    assert term["robot_2"] is True and rew["robot_2"] == 0.0 and infos["robot_2"] == {"removed": True}
    assert obs["robot_2"]["peers"].shape == (6, 3)
    assert not any(term[a] for a in env.agents)
    obs, rew, term, *_ = env.step(env.greedy_actions(env.observe()))
    assert "robot_2" not in term
    while env.agents:
        obs, *_ = env.step(env.greedy_actions(obs))
    assert env.metrics()["steps"] == 200
    # A reset brings back the setup's robots, named from robot_0 again.
    env.reset()
    assert env.agents == [f"robot_{i}" for i in range(6)]


def test_robot_added_at_a_position_and_refused_where_it_does_not_fit():
    env = tending.parallel_env("2.2_2", seed=0)
    env.reset()
    # A corner spot away from everything? Try a few; the sim refuses overlaps.
    name = None
    for x, y in [(-1.0, -1.0), (1.0, 1.0), (-1.0, 1.0), (1.0, -1.0)]:
        try:
            name = env.add_robot((x, y))
            break
        except tending.SimError:
            pass
    assert name is not None
    own = env.observe()[name]["self"]
    assert own[:2] == pytest.approx([x, y])
    with pytest.raises(tending.SimError, match="add_robot"):
        env.add_robot((5.0, 5.0))  # outside the 2.3 m room
    with pytest.raises(tending.SimError, match="add_robot"):
        env.add_robot((x, y))  # on top of the robot just added


def test_machines_and_storages_come_and_go_and_metrics_stay_consistent():
    env = tending.parallel_env("6.4_2", seed=1)
    obs, _ = env.reset()
    for _ in range(40):
        obs, *_ = env.step(env.greedy_actions(obs))
    mid = env.add_machine()
    sid = env.add_storage()
    assert mid in env.machine_ids and sid in env.storage_ids
    obs = env.observe()
    assert obs["robot_0"]["machines"].shape == (5, 3)
    assert obs["robot_0"]["storages"].shape == (3, 2)
    env.remove_machine(env.machine_ids[0])
    assert env.observe()["robot_0"]["machines"].shape == (4, 3)
    with pytest.raises(tending.SimError, match="no machine with id 999"):
        env.remove_machine(999)
    while env.agents:
        obs, _, _, _, infos = env.step(env.greedy_actions(env.observe()))
    m = infos["robot_0"]["metrics"]
    assert 0 < m["mu"] <= 1 and m["p_max"] > 0


def test_last_robot_cannot_be_removed():
    env = tending.parallel_env("1.1_1")
    env.reset()
    with pytest.raises(tending.SimError, match="last robot"):
        env.remove_robot("robot_0")


def test_flat_layout_refuses_growth_beyond_its_maximum():
    env = tending.parallel_env("2.2_2", obs_layout="flat", flat_max=(2, 2, 2))
    env.reset()
    env.add_robot()  # 3 robots: 2 peers each, still fits
    assert env.observe()["robot_0"].shape == (3 + 6 + 4 + 6,)
    env.add_robot()
    with pytest.raises(ValueError, match="flat"):
        env.observe()


class Churn(tending.TendingParallelEnv):
    """A wrapper a user would write: at the start of some steps a robot joins (it stays
    put this step: its policy has not seen it yet) or the oldest leaves. PettingZoo's API
    test must still pass with agents that change mid-episode."""

    def step(self, actions):
        t = self._sim.steps()
        if t and t % 20 == 0:
            self.add_robot()
        if t and t % 30 == 0 and len(self.agents) > 2:
            self.remove_robot(self.agents[0])
        actions = {a: actions.get(a, 0) for a in self.agents}
        return super().step(actions)


def test_parallel_api_with_robots_joining_and_leaving():
    env = Churn("6.4_2", seed=2)
    parallel_api_test(env, num_cycles=300)
    assert len(env.possible_agents) > 6
    # The churn happened: 9 robots joined (ids 6..14) in the last episode.
    assert env.possible_agents[-1] == "robot_14" and env._sim.counts()[0] > 2
