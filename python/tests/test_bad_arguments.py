"""Bad arguments raise Python exceptions that name the argument; nothing panics."""

import numpy as np
import pytest

import tending


@pytest.mark.parametrize(
    "kwargs,exc,match",
    [
        ({"setup": "14.10"}, ValueError, "setup: unknown setup name `14.10`"),
        ({"setup": "abc"}, ValueError, "setup"),
        ({"setup": "4.0_2"}, ValueError, "setup.*at least one machine"),
        ({"setup": "0.2_2"}, ValueError, "setup.*at least one robot"),
        ({"setup": "5000.10_4"}, ValueError, "setup"),
        ({"setup": 14}, TypeError, "setup: expected a string"),
        ({"seed": -1}, ValueError, "seed"),
        ({"seed": 2**64}, ValueError, "seed"),
        ({"seed": "0"}, TypeError, "seed"),
        ({"seed": 1.5}, TypeError, "seed"),
        ({"render_mode": "human"}, ValueError, "render_mode"),
        ({"obs_layout": "graph"}, ValueError, "obs_layout"),
        ({"obs_layout": "flat", "flat_max": (1, 1, 1)}, ValueError, "flat_max"),
        ({"flat_max": (1, 2)}, ValueError, "flat_max"),
        ({"render_size": 3}, ValueError, "render_size"),
        ({"config": {"task": {"k_speed": -1.0}}}, ValueError, "config"),
        ({"config": {"task": {"no_such_field": 1}}}, ValueError, "config.*no_such_field"),
        ({"config": {"world": {"episode_steps": "many"}}}, ValueError, "config"),
        ({"config": "world = ["}, ValueError, "config"),
        ({"config": "/nonexistent/x.toml"}, FileNotFoundError, "config"),
        ({"config": 3}, TypeError, "config"),
    ],
)
def test_constructor_arguments(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        tending.parallel_env(**kwargs)


def test_config_dict_toml_text_and_file_are_used(tmp_path):
    e = tending.parallel_env("2.2_2", config={"world": {"episode_steps": 7}})
    e.reset()
    n = 0
    while e.agents:
        e.step({a: 0 for a in e.agents})
        n += 1
    assert n == 7
    assert tending.parallel_env("2.2_2", config="[world]\nepisode_steps = 9\n").episode_steps == 9
    p = tmp_path / "c.toml"
    p.write_text("[task]\nprep_steps = 5\n[world]\nepisode_steps = 11\n")
    assert tending.parallel_env("2.2_2", config=str(p)).episode_steps == 11
    assert tending.parallel_env("2.2_2", config=p).episode_steps == 11


def test_step_arguments():
    env = tending.parallel_env("2.2_2")
    with pytest.raises(RuntimeError, match="reset"):
        env.step({"robot_0": 0, "robot_1": 0})
    env.reset()
    with pytest.raises(ValueError, match="no action for robot_1"):
        env.step({"robot_0": 0})
    with pytest.raises(ValueError, match="robot_7"):
        env.step({"robot_0": 0, "robot_1": 0, "robot_7": 0})
    with pytest.raises(ValueError, match="action 5 for robot_1"):
        env.step({"robot_0": 0, "robot_1": 5})
    with pytest.raises(ValueError, match="action -1 for robot_0"):
        env.step({"robot_0": -1, "robot_1": 0})
    with pytest.raises(ValueError, match="robot_0"):
        env.step({"robot_0": 1.5, "robot_1": 0})
    with pytest.raises(TypeError, match="robot_0"):
        env.step({"robot_0": "left", "robot_1": 0})
    with pytest.raises(TypeError, match="actions"):
        env.step([0, 0])
    # Refused steps changed nothing: the episode is still at step 0.
    assert env.metrics()["steps"] == 0
    with pytest.raises(ValueError, match="remove_robot"):
        env.remove_robot("robot_9")
    with pytest.raises(TypeError, match="pos"):
        env.add_robot("here")
    with pytest.raises(tending.SimError, match="add_machine"):
        env.add_machine((float("nan"), 0.0))
    with pytest.raises(TypeError, match="machine_id"):
        env.remove_machine("0")
    with pytest.raises(tending.SimError, match="remove_storage"):
        env.remove_storage(-3)


def test_vector_arguments():
    with pytest.raises(ValueError, match="n_envs"):
        tending.vector_env("2.2_2", n_envs=0)
    with pytest.raises(ValueError, match="setup"):
        tending.vector_env("2_2", n_envs=2)
    v = tending.vector_env("2.2_2", n_envs=2)
    v.reset()
    with pytest.raises(ValueError, match="actions: expected 4 actions"):
        v.step(np.zeros((2, 3), dtype=np.int64))
    with pytest.raises(ValueError, match="actions: action 9 at index 3"):
        v.step(np.array([[0, 0], [0, 9]]))
    with pytest.raises(ValueError, match="actions: action -2"):
        v.step(np.array([[0, -2], [0, 0]]))
    with pytest.raises(TypeError, match="actions: expected integers"):
        v.step(np.zeros((2, 2), dtype=np.float32))
    with pytest.raises(ValueError, match="own"):
        v.greedy_actions({"self": np.zeros(3), "machines": np.zeros(1), "storages": np.zeros(1),
                          "peers": np.zeros(1)})


def test_sim_error_is_a_value_error():
    assert issubclass(tending.SimError, ValueError)
