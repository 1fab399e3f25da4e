"""A TorchRL environment over the vector API (:class:`tending.TendingVectorEnv`).

Needs torch, torchrl and tensordict (``pip install './python[torchrl]'``); ``import tending``
alone never imports them.

:class:`TendingEnv` is a batched multi-agent ``EnvBase`` laid out as TorchRL's ``VmasEnv``
and BenchMARL's tasks expect: ``batch_size`` ``(num_envs,)``, one group ``"agents"``
holding every robot, and

- ``("agents", "observation")``: float32 ``(E, N, obs_dim)``, each robot's flat observation
  ``[self 3, machines 3M, storages 2K, peers 3(N-1)]``: the groups of
  :class:`tending.TendingParallelEnv` concatenated in that order, which is its
  ``obs_layout="flat"`` vector (obs::FlatLayout) at the setup's own counts;
- ``("agents", "action")``: int64 ``(E, N)`` in ``0..n_actions`` (``categorical_actions=True``,
  what BenchMARL uses) or one-hot ``(E, N, n_actions)``;
- ``("agents", "reward")``: float32 ``(E, N, 1)``, the simulator's per-robot rewards;
- ``done``, ``terminated``, ``truncated``: bool ``(E, 1)`` at the root and ``(E, N, 1)``
  under ``"agents"``. Episodes end only by time limit (``episode_steps``, 200 by default):
  ``truncated`` and ``done`` are True on an episode's last step, ``terminated`` never is;
- ``("agents", "info", k)`` for ``k`` in ``parts_delivered``, ``collisions``, ``mu``:
  float32 ``(E, N, 1)``, the totals of the episode that ended at this step (the same for
  every robot of an env), 0 on every other step. They are read only at an episode's end
  because reading the running totals every step costs as much as the step itself.

Episode ends: the Rust ``VecSim`` resets an env inside ``step`` when its episode ends. Here
``step`` returns that episode's final observation with ``done`` True (as TorchRL expects)
and keeps the next episode's first observation, which the following ``reset`` (with a
``_reset`` mask, as ``step_and_maybe_reset`` and the collectors send, or without one)
returns, so env ``e``'s episode ``k`` is laid out from ``episode_seed(seed, e, k)`` as in
the vector API. A ``reset`` while episodes are running (or after ``set_seed``) restarts
every env at episode 0 of the seed. All envs of one setup end their episodes on the same
step, so the collectors' masks are all-or-nothing; resetting only some running envs is
refused (the vector API resets an env only when its episode ends).
"""

from __future__ import annotations

try:
    import torch
    from tensordict import TensorDict, TensorDictBase
    from torchrl.data import Bounded, Categorical, Composite, OneHot, Unbounded
    from torchrl.envs import EnvBase
except ImportError as e:  # pragma: no cover - depends on the install
    raise ImportError(
        f"tending.torchrl needs torch, tensordict and torchrl ({e}); install them with "
        "pip install './python[torchrl]'"
    ) from None

import numpy as np

from . import _native
from .env import DIMS, _bounds
from .vector import TendingVectorEnv

GROUPS = ("self", "machines", "storages", "peers")
INFO_KEYS = ("parts_delivered", "collisions", "mu")


# Every tensor of a step's output is made here with the right shape and dtype, so the
# TensorDicts are built without tensordict's per-entry checks (a third of the step's cost).
_td = getattr(TensorDict, "_new_unsafe", None) or (
    lambda source, batch_size: TensorDict(source, batch_size=batch_size)
)


def flat_observation(obs: dict) -> np.ndarray:
    """The vector API's observation groups as one float32 ``(E, N, obs_dim)`` array:
    ``[self 3, machines 3M, storages 2K, peers 3(N-1)]`` per robot."""
    e, n = obs["self"].shape[:2]
    return np.concatenate([obs[g].reshape(e, n, -1) for g in GROUPS], axis=-1)


class TendingEnv(EnvBase):
    """``num_envs`` tending environments of one setup as one batched TorchRL env; see the
    module docstring for the keys, shapes and episode handling.

    Args:
        setup: ``"N.M_K"`` (robots.machines_storages), e.g. ``"6.4_2"``.
        num_envs: environments stepped together in Rust (the batch size).
        seed: base seed; env ``e``'s episode ``k`` uses ``episode_seed(seed, e, k)``.
        config: simulator config (dict of sections, TOML text or a ``.toml`` path).
        device: where the returned tensors live (the simulator runs on the CPU).
        categorical_actions: integer actions ``(E, N)`` (True) or one-hot ``(E, N, A)``.
        diagonal_actions: 9 actions instead of the paper's 5.
        group: the name of the agent group (``"agents"``, as VMAS and BenchMARL use).
    """

    batch_locked = True

    def __init__(self, setup: str = "6.4_2", num_envs: int = 32, seed: int | None = 0,
                 config=None, device="cpu", categorical_actions: bool = True,
                 diagonal_actions: bool = False, group: str = "agents"):
        if not isinstance(categorical_actions, bool):
            raise TypeError(f"categorical_actions: expected a bool, got {categorical_actions!r}")
        if not isinstance(group, str) or not group:
            raise ValueError(f"group: expected a non-empty string, got {group!r}")
        seed = 0 if seed is None else seed
        self._venv = TendingVectorEnv(setup=setup, n_envs=num_envs, seed=seed, config=config,
                                      diagonal_actions=diagonal_actions)
        super().__init__(device=device, batch_size=torch.Size([num_envs]))
        self.setup = self._venv.setup
        self.num_envs = num_envs
        self.n_agents = self._venv.n_robots
        self.n_actions = self._venv.n_actions
        self.episode_steps = self._venv.episode_steps
        self.room_size = self._venv.room_size
        self.categorical_actions = categorical_actions
        self.group = group
        self.agent_names = [f"robot_{i}" for i in range(self.n_agents)]
        self.group_map = {group: list(self.agent_names)}
        self._agent_shape = torch.Size([num_envs, self.n_agents])
        self.obs_counts = tuple(self._venv._v.obs_counts)  # (machines, storages, peers)
        m, k, p = self.obs_counts
        self.obs_dim = DIMS["self"] + DIMS["machines"] * m + DIMS["storages"] * k + DIMS["peers"] * p
        self._seed = seed
        self._reseed: int | None = None
        # The simulator's current observations (dict of group arrays), and which envs
        # began a new episode inside the last step (their first observation is _current).
        self._current: dict | None = None
        self._pending: np.ndarray | None = None
        self._make_specs()

    # ---- specs --------------------------------------------------------------------------

    def _make_specs(self):
        n, g, dev = self.n_agents, self.group, self.device
        m, k, p = self.obs_counts
        room = self._venv.room_size
        parts = [_bounds(room, 1, "self"), _bounds(room, m, "machines"),
                 _bounds(room, k, "storages"), _bounds(room, p, "peers")]
        low = np.concatenate([x[0].ravel() for x in parts])
        high = np.concatenate([x[1].ravel() for x in parts])
        low = torch.from_numpy(np.tile(low, (n, 1)))
        high = torch.from_numpy(np.tile(high, (n, 1)))
        obs = Bounded(low=low, high=high, shape=(n, self.obs_dim), dtype=torch.float32,
                      device=dev)
        info = Composite(
            {key: Unbounded(shape=(n, 1), dtype=torch.float32, device=dev) for key in INFO_KEYS},
            shape=(n,),
        )
        self.full_observation_spec_unbatched = Composite(
            {g: Composite({"observation": obs, "info": info}, shape=(n,))}, device=dev
        )
        if self.categorical_actions:
            act = Categorical(self.n_actions, shape=(n,), dtype=torch.int64, device=dev)
        else:
            act = OneHot(self.n_actions, shape=(n, self.n_actions), dtype=torch.int64,
                         device=dev)
        self.full_action_spec_unbatched = Composite(
            {g: Composite({"action": act}, shape=(n,))}, device=dev
        )
        self.full_reward_spec_unbatched = Composite(
            {g: Composite({"reward": Unbounded(shape=(n, 1), dtype=torch.float32, device=dev)},
                          shape=(n,))},
            device=dev,
        )

        def flags(shape):
            return Categorical(2, shape=shape, dtype=torch.bool, device=dev)

        done = {key: flags((1,)) for key in ("done", "terminated", "truncated")}
        done[g] = Composite(
            {key: flags((n, 1)) for key in ("done", "terminated", "truncated")}, shape=(n,)
        )
        self.full_done_spec_unbatched = Composite(done, device=dev)

    # ---- TorchRL hooks ------------------------------------------------------------------

    def _set_seed(self, seed: int | None):
        # Applied by the next reset, which restarts every env at episode 0 of this seed.
        if seed is not None:
            self._reseed = int(seed) % 2**64
        return None

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        e = self.num_envs
        mask = None
        if tensordict is not None:
            masks = [tensordict.get(key, None) for key in ("_reset", (self.group, "_reset"))]
            masks = [r.reshape(e, -1).any(-1) for r in masks if r is not None]
            if masks:
                mask = torch.stack(masks).any(0).cpu().numpy()
        pending = self._pending
        if self._reseed is not None:
            self._seed, self._reseed = self._reseed, None
            obs, _ = self._venv.reset(seed=self._seed)
        elif mask is None or mask.all():
            if pending is not None and pending.all():
                obs = self._current  # the episodes begun inside the last step
            else:
                obs, _ = self._venv.reset()
        else:
            running = mask & ~(pending if pending is not None else np.zeros(e, bool))
            if running.any():
                raise RuntimeError(
                    f"reset: envs {np.flatnonzero(running).tolist()} are mid-episode; the "
                    "vector API resets an env only at the end of its episode (or all envs "
                    "together: reset without a '_reset' mask)"
                )
            obs = self._current
        self._current = obs
        self._pending = None
        return self._tensordict(flat_observation(obs), None, np.zeros(e, bool), None)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get((self.group, "action"))
        if not self.categorical_actions:
            action = action.argmax(-1)
        obs, rewards, _, truncated, infos = self._venv.step(action.detach().cpu().numpy())
        self._current = obs
        done = truncated[:, 0]
        info = None
        if "final_obs" in infos:
            self._pending = done
            out = infos["final_obs"]
            info = np.zeros((len(INFO_KEYS), self.num_envs), np.float32)
            for i, m in enumerate(infos["final_metrics"]):
                if m is not None:
                    info[:, i] = [m[key] for key in INFO_KEYS]
        else:
            self._pending = None
            out = obs
        return self._tensordict(flat_observation(out), rewards, done, info)

    def _tensordict(self, obs, rewards, done, info):
        e, n, g, dev = self.num_envs, self.n_agents, self.group, self.device
        if info is None:
            infos = {key: torch.zeros(e, n, 1) for key in INFO_KEYS}
        else:
            infos = {key: torch.from_numpy(info[i]).view(e, 1, 1).expand(e, n, 1).clone()
                     for i, key in enumerate(INFO_KEYS)}
        d_env = torch.from_numpy(done).view(e, 1)
        d_agent = d_env.view(e, 1, 1).expand(e, n, 1).clone()
        agents = {
            "observation": torch.from_numpy(obs),
            "info": _td(infos, self._agent_shape),
            "done": d_agent,
            "terminated": torch.zeros(e, n, 1, dtype=torch.bool),
            "truncated": d_agent.clone(),
        }
        if rewards is not None:
            agents["reward"] = torch.from_numpy(rewards).view(e, n, 1)
        td = _td(
            {
                g: _td(agents, self._agent_shape),
                "done": d_env,
                "terminated": torch.zeros(e, 1, dtype=torch.bool),
                "truncated": d_env.clone(),
            },
            self.batch_size,
        )
        return td if dev is None or dev == torch.device("cpu") else td.to(dev)

    # ---- extras -------------------------------------------------------------------------

    def greedy_actions(self) -> torch.Tensor:
        """The scripted greedy baseline's actions (``tending sim --policy greedy``) for the
        simulator's current state, int64 ``(E, N)``: a reference policy to run through the
        same env (one-hot encode it for ``categorical_actions=False``)."""
        if self._current is None:
            raise RuntimeError("greedy_actions: call reset() first")
        a = torch.from_numpy(self._venv.greedy_actions(self._current).astype(np.int64))
        return a.to(self.device)

    def episode_seed(self, env: int, episode: int) -> int:
        """The seed env ``env``'s episode ``episode`` is laid out from."""
        return _native.episode_seed(self._seed, env, episode)

    def __repr__(self) -> str:
        return (f"{self.__class__.__name__}(setup={self.setup!r}, num_envs={self.num_envs}, "
                f"n_agents={self.n_agents}, obs_dim={self.obs_dim}, device={self.device})")


def make_env(setup: str = "6.4_2", num_envs: int = 32, seed: int | None = 0, **kwargs) -> TendingEnv:
    """A :class:`TendingEnv`; keyword arguments as its constructor's."""
    return TendingEnv(setup=setup, num_envs=num_envs, seed=seed, **kwargs)
