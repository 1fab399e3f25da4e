"""N environments stepped in Rust in one call (``tending._native.VecSim``)."""

from __future__ import annotations

import numpy as np

from . import _native
from ._args import check_seed, check_setup, config_args


class TendingVectorEnv:
    """``n_envs`` environments of one setup, stepped together on Rust threads with the GIL
    released. Everything is numpy arrays shaped ``(n_envs, n_robots, ...)``; there are no
    per-agent Python objects. Observation groups as in :class:`tending.TendingParallelEnv`:
    ``{"self": (E,N,3), "machines": (E,N,M,3), "storages": (E,N,K,2), "peers": (E,N,N-1,3)}``.
    The arrays are fresh each call (written in place by Rust, no copy afterwards), so
    keeping them is safe.

    All episodes last ``episode_steps``. An env whose episode ends is reset within the
    same ``step`` (``truncated`` is True for its robots): the returned observation is the
    first of its next episode, and the last of the finished one is in
    ``infos["final_obs"]``, its metrics in ``infos["final_metrics"][e]``. Env ``e``'s
    episode ``k`` is laid out from ``episode_seed(seed, e, k)``.
    """

    def __init__(self, setup: str = "14.10_4", n_envs: int = 8, seed: int = 0, config=None,
                 diagonal_actions: bool = False):
        setup = check_setup(setup)
        seed = check_seed(seed)
        if isinstance(n_envs, bool) or not isinstance(n_envs, int) or n_envs < 1:
            raise ValueError(f"n_envs: expected an int >= 1, got {n_envs!r}")
        if not isinstance(diagonal_actions, bool):
            raise TypeError(f"diagonal_actions: expected a bool, got {diagonal_actions!r}")
        toml, js = config_args(config)
        self._v = _native.VecSim(setup, n_envs, seed, toml, js, diagonal_actions)
        self.setup = setup
        self.n_envs = n_envs
        self.n_robots = self._v.robots_per_env
        self.episode_steps = self._v.episode_steps
        self.room_size = self._v.room_size
        self.n_actions = self._v.n_actions

    @staticmethod
    def _dict(arrs):
        return dict(zip(("self", "machines", "storages", "peers"), arrs))

    def reset(self, seed: int | None = None):
        """Reset every env; returns (observations, infos)."""
        if seed is not None:
            seed = check_seed(seed)
        return self._dict(self._v.reset(seed)), {}

    def step(self, actions):
        """``actions``: integers 0..n_actions shaped (n_envs, n_robots) (or flat). Returns
        (observations, rewards (E,N) float32, terminated (E,N), truncated (E,N), infos)."""
        obs, rewards, done, final, metrics = self._v.step(actions)
        terminated = np.zeros(rewards.shape, dtype=bool)
        truncated = np.repeat(done[:, None], self.n_robots, axis=1)
        infos = {}
        if final is not None:
            infos["final_obs"] = self._dict(final)
            infos["final_metrics"] = metrics
        return self._dict(obs), rewards, terminated, truncated, infos

    def greedy_actions(self, observations):
        """The scripted greedy baseline's actions for ``observations``, (E, N) uint8."""
        return self._v.greedy_actions(
            observations["self"], observations["machines"], observations["storages"],
            observations["peers"],
        )

    def metrics(self) -> list[dict]:
        """Every env's current-episode metrics."""
        return self._v.metrics()

    def close(self):
        pass


def vector_env(setup: str = "14.10_4", n_envs: int = 8, seed: int = 0, config=None,
               diagonal_actions: bool = False) -> TendingVectorEnv:
    """``n_envs`` environments stepped in Rust in one call; see :class:`TendingVectorEnv`."""
    return TendingVectorEnv(setup=setup, n_envs=n_envs, seed=seed, config=config,
                            diagonal_actions=diagonal_actions)
