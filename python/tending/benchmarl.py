"""A BenchMARL task for tending: any setup, any BenchMARL algorithm with discrete actions.

Needs benchmarl (``pip install './python[torchrl]'``); ``import tending`` alone never
imports it.

::

    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig
    import tending.benchmarl

    task = tending.benchmarl.task("6.4_2")          # or "tending/6.4_2", any N.M_K
    Experiment(task=task, algorithm_config=MappoConfig.get_from_yaml(),
               model_config=MlpConfig.get_from_yaml(), seed=0,
               config=ExperimentConfig.get_from_yaml()).run()

Importing this module also registers :class:`TendingTask` (one member per setup of the
paper) with BenchMARL: ``benchmarl.environments.task_config_registry["tending/6.4_2"]``.
A task's config (every key optional): ``setup`` (default: the task's name),
``config`` (the simulator config, as :func:`tending.parallel_env` takes it),
``diagonal_actions``. BenchMARL's ``num_envs`` (``on_policy_n_envs_per_worker`` etc.) is the
number of envs stepped together in Rust. The env is :class:`tending.torchrl.TendingEnv`.

``log_info`` adds to BenchMARL's loggers, per collected batch, the mean over the episodes
that ended in it of ``collection/tending/parts_delivered``, ``.../collisions``,
``.../mu`` and ``.../team_reward`` (the episode's rewards summed over robots).
"""

from __future__ import annotations

import copy
from typing import Callable, Dict, List, Optional

from benchmarl.environments import Task, TaskClass
from tensordict import TensorDictBase
from torchrl.data import Composite
from torchrl.envs import EnvBase

from .torchrl import INFO_KEYS, TendingEnv

ENV_NAME = "tending"
# The paper's setups (sim/src/layout.rs every_paper_setup_fits); any other N.M_K works
# through task().
PAPER_SETUPS = (
    "2.2_2", "4.2_2", "6.4_2", "8.6_2", "10.6_4", "12.8_4", "14.10_4", "18.12_6",
    "24.16_8", "30.20_10", "36.24_12", "42.28_14", "100.16_2",
)


class TendingClass(TaskClass):
    """BenchMARL's task class for tending: builds :class:`tending.torchrl.TendingEnv`."""

    def get_env_fun(self, num_envs: int, continuous_actions: bool, seed: Optional[int],
                    device) -> Callable[[], EnvBase]:
        if continuous_actions:
            raise ValueError("tending's BenchMARL task has discrete actions only")
        cfg = copy.deepcopy(self.config)
        setup = cfg.pop("setup", None) or self.name
        return lambda: TendingEnv(setup=setup, num_envs=num_envs, seed=seed, device=device,
                                  categorical_actions=True, **cfg)

    def supports_continuous_actions(self) -> bool:
        return False

    def supports_discrete_actions(self) -> bool:
        return True

    def has_render(self, env: EnvBase) -> bool:
        return False

    def max_steps(self, env: EnvBase) -> int:
        return _base(env).episode_steps

    def group_map(self, env: EnvBase) -> Dict[str, List[str]]:
        return _base(env).group_map

    def observation_spec(self, env: EnvBase) -> Composite:
        spec = env.full_observation_spec_unbatched.clone()
        for group in self.group_map(env):
            if "info" in spec[group]:
                del spec[(group, "info")]
        return spec

    def info_spec(self, env: EnvBase) -> Optional[Composite]:
        spec = env.full_observation_spec_unbatched.clone()
        for group in self.group_map(env):
            del spec[(group, "observation")]
        return spec

    def state_spec(self, env: EnvBase) -> Optional[Composite]:
        return None

    def action_spec(self, env: EnvBase) -> Composite:
        return env.full_action_spec_unbatched

    def action_mask_spec(self, env: EnvBase) -> Optional[Composite]:
        return None

    @staticmethod
    def env_name() -> str:
        return ENV_NAME

    @staticmethod
    def log_info(batch: TensorDictBase) -> Dict[str, float]:
        return {f"collection/{ENV_NAME}/{k}": v for k, v in episode_stats(batch).items()}


def episode_stats(batch: TensorDictBase, group: str = "agents") -> Dict[str, float]:
    """Means over the episodes that ended in ``batch`` (a collected batch or a rollout, with
    a ``next`` entry) of the parts delivered, collisions, MU and team reward; empty if none
    ended."""
    done = batch.get(("next", "done")).squeeze(-1)
    if not done.any():
        return {}
    nxt = batch.get("next")
    out = {k: nxt.get((group, "info", k))[done][..., 0, 0].float().mean().item()
           for k in INFO_KEYS}
    ep = nxt.get((group, "episode_reward"), None)
    if ep is not None:
        out["team_reward"] = ep[done].sum(-2).float().mean().item()
    return out


def episode_rows(batch: TensorDictBase, group: str = "agents") -> List[Dict[str, float]]:
    """One dict per episode that ended in ``batch``: parts_delivered, collisions, mu and
    (with BenchMARL's RewardSum transform) team_reward."""
    done = batch.get(("next", "done")).squeeze(-1)
    if not done.any():
        return []
    nxt = batch.get("next")
    cols = {k: nxt.get((group, "info", k))[done][..., 0, 0].tolist() for k in INFO_KEYS}
    ep = nxt.get((group, "episode_reward"), None)
    if ep is not None:
        cols["team_reward"] = ep[done].sum(-2)[..., 0].tolist()
    n = len(cols[INFO_KEYS[0]])
    return [{k: v[i] for k, v in cols.items()} for i in range(n)]


def _base(env: EnvBase) -> TendingEnv:
    """The TendingEnv under BenchMARL's transforms."""
    while not isinstance(env, TendingEnv):
        inner = getattr(env, "base_env", None)
        if inner is None or inner is env:
            raise TypeError(f"not a tending env: {env!r}")
        env = inner
    return env


class _TendingTaskBase(Task):
    @staticmethod
    def associated_class():
        return TendingClass

    def get_from_yaml(self, path: Optional[str] = None) -> TaskClass:
        """The task with its default config (no yaml is shipped inside BenchMARL for it);
        from ``path`` if given."""
        if path is not None:
            from benchmarl.utils import _read_yaml_config

            return self.get_task(config=_read_yaml_config(path))
        return self.get_task(config={"setup": self.name})


# One member per paper setup, named by it: TendingTask["6.4_2"].
TendingTask = _TendingTaskBase("TendingTask", list(PAPER_SETUPS))


def task(name: str = "6.4_2", **config) -> TendingClass:
    """The BenchMARL task for setup ``name`` (``"6.4_2"`` or ``"tending/6.4_2"``, any
    ``N.M_K``), with optional config keys ``config`` (simulator) and ``diagonal_actions``."""
    if not isinstance(name, str):
        raise TypeError(f"name: expected a setup string such as '6.4_2', got {name!r}")
    setup = name.split("/", 1)[1] if name.startswith(ENV_NAME + "/") else name
    cfg = {"setup": setup, **config}
    if setup in TendingTask.__members__:
        return TendingTask[setup].get_task(config=cfg)
    return TendingClass(name=setup, config=cfg)


def register() -> None:
    """Add :class:`TendingTask` to BenchMARL's task lists (done on import; idempotent)."""
    import benchmarl.environments as envs

    if TendingTask not in envs.tasks:
        envs.tasks.append(TendingTask)
    for member in TendingTask:
        envs.task_config_registry[f"{ENV_NAME}/{member.name}"] = member


register()

__all__ = ["PAPER_SETUPS", "TendingClass", "TendingTask", "episode_rows", "episode_stats",
           "register", "task"]
