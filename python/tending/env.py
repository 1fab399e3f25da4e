"""The PettingZoo ParallelEnv over the Rust simulator (``tending._native.Sim``)."""

from __future__ import annotations

import gymnasium
import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from . import _native
from ._args import check_seed, check_setup, config_args

GROUPS = ("self", "machines", "storages", "peers")
# Features per entity of each group (the obs crate's SELF/MACHINE/STORAGE/PEER_DIM); the
# last feature of self, machines and peers is a 0/1 flag.
DIMS = {"self": 3, "machines": 3, "storages": 2, "peers": 3}
FLAGGED = {"self": True, "machines": True, "storages": False, "peers": True}


def _bounds(room: float, count: int, group: str):
    """Box bounds of one group: positions (absolute for self, relative otherwise) within
    +-room (a relative position spans at most the room), flags in [0, 1]."""
    d = DIMS[group]
    low = np.full((count, d), -room, dtype=np.float32)
    high = np.full((count, d), room, dtype=np.float32)
    if FLAGGED[group]:
        low[:, -1], high[:, -1] = 0.0, 1.0
    return low, high


class TendingParallelEnv(ParallelEnv):
    """The machine-tending scenario of the SMAPPO paper (sections III, IV-C..E).

    Agents are ``robot_<id>`` (ids are stable while robots come and go, and restart at 0
    on reset). Actions: ``Discrete(5)``, 0 stay, 1 left, 2 right, 3 down, 4 up (the
    paper's); ``diagonal_actions=True`` gives ``Discrete(9)``, adding 5 left-down,
    6 right-down, 7 left-up, 8 right-up at the same speed; ``action_type="velocity"``
    gives ``Box(-k_speed, k_speed, (2,))``: a holonomic velocity command (vx, vy) in m/s,
    the simulator's native input (its norm is clamped to k_speed), as ROS Twist drives it.

    Observations (``obs_layout="dict"``): a ``Dict`` of per-group arrays, relative
    positions in metres, the room's centre at the origin:

    - ``self`` (3,): x, y, has_part
    - ``machines`` (M, 3): dx, dy, part_ready
    - ``storages`` (K, 2): dx, dy
    - ``peers`` (N-1, 3): dx, dy, has_part of every other robot, in robot order

    Group sizes change when bodies are added or removed (the spaces follow the live
    counts); ``obs_layout="flat"`` gives instead the MAPPO baseline's zero-padded vector
    of fixed size ``3 + 3*max_machines + 2*max_storages + 3*max_peers`` (``flat_max``,
    by default the setup's counts).

    Rewards are the Rust simulator's per-robot rewards. Episodes end by time limit
    (``episode_steps`` of the config, 200 by default): every agent is truncated, none is
    terminated. Infos per agent: ``picked`` (machine id or -1), ``placed`` (storage id or
    -1), ``collisions`` (bodies touched this step), and ``metrics``: the episode's parts
    delivered and collected, collisions by kind, P_max and MU (machine utilization), the
    same numbers as ``tending sim``.

    Episode ``k`` after ``reset(seed=s)`` is laid out from ``episode_seed(s, 0, k)``, as
    episode ``k`` of ``tending sim --seed s``; ``reset()`` without a seed continues the
    sequence from the constructor's ``seed``.
    """

    metadata = {
        "name": "tending_v0",
        "render_modes": ["rgb_array"],
        "render_fps": 10,
        "is_parallelizable": True,
    }

    def __init__(
        self,
        setup: str = "14.10_4",
        seed: int = 0,
        config=None,
        render_mode: str | None = None,
        obs_layout: str = "dict",
        flat_max: tuple[int, int, int] | None = None,
        render_size: int = 460,
        diagonal_actions: bool = False,
        action_type: str = "discrete",
    ):
        setup = check_setup(setup)
        self._base_seed = check_seed(seed)
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(
                f"render_mode: {render_mode!r} is not supported; use None or 'rgb_array'"
            )
        if obs_layout not in ("dict", "flat"):
            raise ValueError(f"obs_layout: {obs_layout!r} is not 'dict' or 'flat'")
        if isinstance(render_size, bool) or not isinstance(render_size, int) or not (
            16 <= render_size <= 4096
        ):
            raise ValueError(f"render_size: expected an int in 16..4096, got {render_size!r}")
        if not isinstance(diagonal_actions, bool):
            raise TypeError(f"diagonal_actions: expected a bool, got {diagonal_actions!r}")
        if action_type not in ("discrete", "velocity"):
            raise ValueError(f"action_type: {action_type!r} is not 'discrete' or 'velocity'")
        self.action_type = action_type
        toml, js = config_args(config)
        self._sim = _native.Sim(
            setup, _native.episode_seed(self._base_seed, 0, 0), toml, js, diagonal_actions
        )
        self.n_actions = self._sim.n_actions
        self.k_speed = self._sim.k_speed()
        self.render_mode = render_mode
        self.render_size = render_size
        self.obs_layout = obs_layout
        n, m, k = self._sim.counts()
        if flat_max is None:
            flat_max = (m, k, n - 1)
        if (
            not isinstance(flat_max, (tuple, list))
            or len(flat_max) != 3
            or not all(isinstance(x, int) and not isinstance(x, bool) and x >= 0 for x in flat_max)
        ):
            raise ValueError(
                f"flat_max: expected (max_machines, max_storages, max_peers) of ints >= 0, "
                f"got {flat_max!r}"
            )
        if obs_layout == "flat" and (flat_max[0] < m or flat_max[1] < k or flat_max[2] < n - 1):
            raise ValueError(
                f"flat_max: {tuple(flat_max)} is smaller than the setup's "
                f"(machines, storages, peers) = {(m, k, n - 1)}"
            )
        self.flat_max = tuple(flat_max)
        self.setup = setup
        self.room_size = self._sim.room_size()
        self.episode_steps = self._sim.episode_steps()
        self.possible_agents = [f"robot_{i}" for i in self._sim.robot_ids()]
        self.agents = []
        self._episode = 0
        self._action_spaces: dict[str, spaces.Space] = {}
        self._obs_space_cache: dict[tuple, spaces.Space] = {}
        self._needs_reset = True
        self._departed: dict[str, object] = {}

    # ---- spaces -------------------------------------------------------------------------

    def observation_space(self, agent):
        n, m, k = self._sim.counts()
        key = (n, m, k) if self.obs_layout == "dict" else ("flat",)
        sp = self._obs_space_cache.get(key)
        if sp is None:
            room = self.room_size
            counts = {"machines": m, "storages": k, "peers": max(n - 1, 0)}
            if self.obs_layout == "dict":
                d = {}
                for g in GROUPS:
                    if g == "self":
                        low, high = _bounds(room, 1, g)
                        low, high = low[0], high[0]
                    else:
                        low, high = _bounds(room, counts[g], g)
                    d[g] = spaces.Box(low, high, dtype=np.float32)
                sp = spaces.Dict(d)
            else:
                mm, mk, mp = self.flat_max
                parts = [_bounds(room, 1, "self"), _bounds(room, mm, "machines"),
                         _bounds(room, mk, "storages"), _bounds(room, mp, "peers")]
                low = np.concatenate([p[0].ravel() for p in parts])
                high = np.concatenate([p[1].ravel() for p in parts])
                sp = spaces.Box(low, high, dtype=np.float32)
            self._obs_space_cache[key] = sp
        return sp

    def action_space(self, agent):
        # One object per agent, so seeding it (PettingZoo's seed test) sticks.
        sp = self._action_spaces.get(agent)
        if sp is None:
            if self.action_type == "velocity":
                k = self.k_speed
                sp = spaces.Box(-k, k, shape=(2,), dtype=np.float32)
            else:
                sp = spaces.Discrete(self.n_actions)
            self._action_spaces[agent] = sp
        return sp

    # ---- episode ------------------------------------------------------------------------

    def reset(self, seed=None, options=None):
        if seed is not None:
            self._base_seed = check_seed(seed)
            self._episode = 0
        self._sim.reset(_native.episode_seed(self._base_seed, 0, self._episode))
        self._episode += 1
        self._needs_reset = False
        self._departed = {}
        self.agents = self._agent_names()
        self.possible_agents = list(
            dict.fromkeys(self.possible_agents + self.agents)
        )
        infos = {a: {} for a in self.agents}
        return self._observations(), infos

    def step(self, actions):
        if self._needs_reset:
            raise RuntimeError("step: the episode is over (or never began): call reset() first")
        if not isinstance(actions, dict):
            raise TypeError(f"actions: expected a dict agent -> action, got {type(actions).__name__}")
        agents = self.agents
        extra = set(actions) - set(agents)
        if extra:
            raise ValueError(f"actions: unknown or inactive agents {sorted(map(str, extra))}")
        missing = [a for a in agents if a not in actions]
        if missing:
            raise ValueError(f"actions: no action for {missing[0]}")
        if self.action_type == "velocity":
            self._sim.step_velocities(self._velocities(actions, agents))
        else:
            self._sim.step(self._discrete(actions, agents))
        obs = self._observations()
        rew = self._sim.rewards()
        rewards = {agent: float(rew[i]) for i, agent in enumerate(agents)}
        infos = self._infos()
        done = self._sim.is_done()
        terminations = {agent: False for agent in agents}
        truncations = {agent: done for agent in agents}
        for agent, last in self._departed.items():
            obs[agent] = last
            rewards[agent] = 0.0
            terminations[agent] = True
            truncations[agent] = False
            infos[agent] = {"removed": True}
        self._departed = {}
        if done:
            self.agents = []
            self._needs_reset = True
        return obs, rewards, terminations, truncations, infos

    def _discrete(self, actions, agents):
        a = np.empty(len(agents), dtype=np.int64)
        for i, agent in enumerate(agents):
            act = actions[agent]
            try:
                v = int(act)
            except (TypeError, ValueError):
                raise TypeError(f"actions: action for {agent} is {act!r}, not an integer") from None
            if v != act or not 0 <= v < self.n_actions:
                raise ValueError(
                    f"actions: action {act!r} for {agent} is not one of 0..{self.n_actions} "
                    "(0 stay, 1 left, 2 right, 3 down, 4 up"
                    + ("; 5 left-down, 6 right-down, 7 left-up, 8 right-up)" if self.n_actions > 5 else ")")
                )
            a[i] = v
        return a

    def _velocities(self, actions, agents):
        """(n, 2) velocity commands in m/s; the simulator clamps their norm to k_speed."""
        v = np.empty((len(agents), 2), dtype=np.float32)
        for i, agent in enumerate(agents):
            try:
                v[i] = np.asarray(actions[agent], dtype=np.float32).reshape(2)
            except (TypeError, ValueError):
                raise ValueError(
                    f"actions: velocity for {agent} is {actions[agent]!r}, not (vx, vy) in m/s"
                ) from None
            if not np.isfinite(v[i]).all():
                raise ValueError(f"actions: velocity for {agent} is not finite: {v[i].tolist()}")
        return v

    def render(self):
        if self.render_mode is None:
            gymnasium.logger.warn(
                "render() called without a render_mode; make the env with render_mode='rgb_array'"
            )
            return None
        return self._sim.render(self.render_size)

    def close(self):
        pass

    # ---- live changes (between steps) ---------------------------------------------------

    def add_robot(self, pos: tuple[float, float] | None = None) -> str:
        """Add a robot at ``pos`` (x, y in metres) or at a free spot drawn from the env's
        rng; returns its agent name. It is in ``agents`` at once and needs an action in
        the next step; :meth:`observe` gives its first observation."""
        self._check_live("add_robot")
        rid = self._sim.add_robot(_pos(pos))
        name = f"robot_{rid}"
        self.agents = self._agent_names()
        if name not in self.possible_agents:
            self.possible_agents.append(name)
        return name

    def remove_robot(self, agent: str) -> None:
        """Remove a robot by agent name; the others keep their names and order. The next
        ``step`` reports it once more, terminated (PettingZoo's way for an agent to leave),
        with its observation at removal, reward 0 and ``infos[agent]["removed"]``."""
        self._check_live("remove_robot")
        if agent not in self.agents:
            raise ValueError(f"remove_robot: {agent!r} is not an active agent")
        # Its observation now is its last: the next step reports it terminated with it.
        last = self._observations()[agent]
        self._sim.remove_robot(int(agent.rsplit("_", 1)[1]))
        self._departed[agent] = last
        self.agents = self._agent_names()

    def add_machine(self, pos=None) -> int:
        self._check_live("add_machine")
        return self._sim.add_machine(_pos(pos))

    def remove_machine(self, machine_id: int) -> None:
        self._check_live("remove_machine")
        self._sim.remove_machine(_int("machine_id", machine_id))

    def add_storage(self, pos=None) -> int:
        self._check_live("add_storage")
        return self._sim.add_storage(_pos(pos))

    def remove_storage(self, storage_id: int) -> None:
        self._check_live("remove_storage")
        self._sim.remove_storage(_int("storage_id", storage_id))

    @property
    def machine_ids(self) -> list[int]:
        return self._sim.machine_ids()

    @property
    def storage_ids(self) -> list[int]:
        return self._sim.storage_ids()

    # ---- views --------------------------------------------------------------------------

    def observe(self):
        """Every active agent's current observation (as ``step`` returns them)."""
        return self._observations()

    def observe_arrays(self):
        """The batch arrays behind the observations: (self (n,3), machines (n,M,3),
        storages (n,K,2), peers (n,n-1,3)), rows in ``agents`` order."""
        return self._sim.observe()

    def greedy_actions(self, observations=None):
        """The scripted greedy baseline's actions (``tending sim --policy greedy``) for
        dict observations (default: the current ones), as an action dict."""
        if self.obs_layout != "dict" or self.action_type != "discrete":
            raise ValueError("greedy_actions: needs obs_layout='dict' and discrete actions")
        if observations is None:
            observations = self._observations()
        arrs = [np.stack([observations[a][g] for a in self.agents]) for g in GROUPS]
        acts = self._sim.greedy_actions(*arrs)
        return {a: int(acts[i]) for i, a in enumerate(self.agents)}

    def metrics(self) -> dict:
        """The episode's metrics so far (parts, collisions by kind, P_max, MU)."""
        return self._sim.metrics()

    @property
    def state_space(self):
        """Box of :meth:`state` for the live counts."""
        n, m, _ = self._sim.counts()
        key = ("state", n, m)
        sp = self._obs_space_cache.get(key)
        if sp is None:
            low, high = _bounds(self.room_size, n, "self")
            low = np.concatenate([low.ravel(), np.zeros(m, np.float32)])
            high = np.concatenate([high.ravel(), np.ones(m, np.float32)])
            sp = self._obs_space_cache[key] = spaces.Box(low, high, dtype=np.float32)
        return sp

    def state(self):
        """Global state: every robot's (x, y, has_part), then every machine's part_ready,
        as one float32 vector (for centralized critics)."""
        own, machines, _, _ = self._sim.observe()
        ready = machines[0, :, 2] if machines.shape[0] else np.zeros(0, np.float32)
        return np.concatenate([own.ravel(), ready]).astype(np.float32)

    # ---- helpers ------------------------------------------------------------------------

    def _agent_names(self):
        return [f"robot_{i}" for i in self._sim.robot_ids()]

    def _check_live(self, what):
        if self._needs_reset:
            raise RuntimeError(f"{what}: no episode is running; call reset() first")

    def _observations(self):
        agents = self.agents
        if self.obs_layout == "flat":
            flat = self._sim.observe_flat(*self.flat_max)
            return {a: flat[i] for i, a in enumerate(agents)}
        own, machines, storages, peers = self._sim.observe()
        return {
            a: {"self": own[i], "machines": machines[i], "storages": storages[i], "peers": peers[i]}
            for i, a in enumerate(agents)
        }

    def _infos(self):
        picked, placed, coll = self._sim.events()
        metrics = self._sim.metrics()
        return {
            a: {
                "picked": int(picked[i]),
                "placed": int(placed[i]),
                "collisions": int(coll[i]),
                "metrics": metrics,
            }
            for i, a in enumerate(self.agents)
        }


def _pos(pos):
    if pos is None:
        return None
    try:
        x, y = pos
        return float(x), float(y)
    except (TypeError, ValueError):
        raise TypeError(f"pos: expected (x, y) in metres or None, got {pos!r}") from None


def _int(name, v):
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
        raise TypeError(f"{name}: expected an int, got {type(v).__name__}")
    return int(v)


def parallel_env(
    setup: str = "14.10_4",
    seed: int = 0,
    config=None,
    render_mode: str | None = None,
    **kwargs,
) -> TendingParallelEnv:
    """A PettingZoo ParallelEnv of the tending scenario; see :class:`TendingParallelEnv`
    (extra keyword arguments: ``obs_layout``, ``flat_max``, ``render_size``,
    ``diagonal_actions``, ``action_type``)."""
    return TendingParallelEnv(setup=setup, seed=seed, config=config, render_mode=render_mode, **kwargs)
