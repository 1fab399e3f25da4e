"""The tending scenario written for VMAS: a twin of our Rust simulator for side-by-side runs.

A VMAS ``BaseScenario`` (vmas 1.5.2) with N robots (discs), M machines and K storage
areas (static boxes) in the paper's 2.3 m walled room, batched over VMAS's ``batch_dim``
envs in torch, plus a BenchMARL task for it (``vmas_tending/<setup>``, see :func:`task`)::

    from vmas import make_env
    from vmas_tending import TendingScenario
    env = make_env(TendingScenario(), num_envs=32, continuous_actions=False,
                   max_steps=200, setup="6.4_2")

Scenario kwargs: ``setup`` ("N.M_K", default "6.4_2"), ``obs_layout`` ("full" or
"tending", below), and any constant of ``configs/default.toml`` by its field name
(``k_speed``, ``reach``, ``prep_steps``, ``pick``, ``place``, ``collision``, ``progress``,
``utilization``, ``time``, ...); the defaults are that file's values.

Actions: ``Discrete(5)``, the paper's moves as our simulator numbers them (plan::action):
0 stay, 1 left (-x), 2 right (+x), 3 down (-y), 4 up (+y), each a holonomic velocity
command of ``k_speed`` (0.5 m/s). VMAS's own discretisation of a 1-D action with 5 values
gives u in {0, -1, -0.5, 0.5, 1} for actions 0..4; :class:`VelocityTracker` (a VMAS
``Dynamics``) decodes that back to the action index and turns its velocity command into a
force the way our simulator does (the force that reaches the command after this step's
drag, norm capped at ``max_force``). The BenchMARL task refuses continuous actions.

Observation per robot, a flat float vector (``obs_layout``):

- ``"full"`` (default): own position x, y, velocity vx, vy, has_part (5); per machine
  relative position dx, dy, part_ready, remaining preparation time / prep_steps (4M); per
  storage relative position (2K); per other robot, in robot order, relative position and
  has_part (3(N-1)). 6.4_2: 40 values.
- ``"tending"``: exactly the flat vector of ``tending.torchrl.TendingEnv``: own x, y,
  has_part (3); per machine dx, dy, part_ready (3M); per storage dx, dy (2K); per other robot
  dx, dy, has_part (3(N-1)). 6.4_2: 34 values. ``bench/python/side_by_side.py`` uses this
  one, so both simulators feed MAPPO the same features.

Info per robot (``("agents", "info", k)``, as TendingEnv has them): ``parts_delivered``,
``collisions``, ``mu``: the episode's totals on its last step, 0 on other steps.

What is the same as our simulator (sim/src/env/step.rs, layout.rs, config.rs):

- the constants: room 2.3 m, dt 0.1 s, one substep, drag 0.25, contact force 100, contact
  margin 1e-3, mass 1, max_force 3, k_speed 0.5, reach 0.08, collision distance 0.005,
  prep_steps 20, 200-step episodes; the size rule (every length scaled by
  sqrt(occupancy * room area / footprint) when the bodies would cover more than
  ``occupancy`` of the floor; 6.4_2 is unscaled: robot radius 0.08, machines 0.24 x 0.24,
  storages 0.30 x 0.16);
- the layout rule: storages, then machines, then robots, uniform with rejection, boxes
  ``box_gap_diameters`` robot diameters from each other and the walls, robots 0.25 radii
  clear of everything (the same rule, not the same random draws: layouts differ per seed);
- machines start with a part ready; a picked machine is ready again 20 steps later (timer
  counted down before picks in a step, so a part becomes pickable on the step it is made);
- pick: a robot without a part whose centre is within radius + reach of a ready machine's
  surface takes the nearest such machine's part, robots in index order (first come);
  place: a robot with a part within reach of any storage delivers it;
- the reward terms and weights: pick +3, place +5, collision -0.3 per body touched per step
  (robots, machines, storages, walls at surface distance <= 0.005 m), progress 2 per metre
  towards the nearest ready machine (or storage with a part) measured from the previous and
  the new position against one target set, utilization -0.02 x ready-and-uncollected / M
  after the step's picks, time -0.01 when a robot neither picked nor placed and the
  utilization term is 0; metrics: parts delivered, collisions (a robot-robot contact counts
  2), MU = parts collected / (M x ceil(steps / prep_steps)).

What is approximate (VMAS's own machinery):

- contact physics: VMAS's collision forces between spheres, sphere-box (VMAS ``Box``
  landmarks) and sphere-line (the four walls are VMAS ``Line`` landmarks of the room's
  length); our simulator uses the same soft-plus penetration force but its own box
  distance (parry2d) and half-plane walls, so contacts near box corners and walls push
  slightly differently. VMAS starts a box or line contact LINE_MIN_DIST (6.7 mm) beyond
  the surface; the twin's physical boxes are that much smaller and its walls that much
  farther out so that contact starts at the same surfaces as ours (otherwise VMAS would
  hold robots 6.7 mm off every box and wall, beyond the 5 mm collision distance, and count
  far fewer collisions);
- episode end: TorchRL's ``VmasEnv`` reports the 200-step horizon as ``terminated`` (no
  value bootstrap in GAE); our TendingEnv reports it as ``truncated``;
- random streams: layouts come from torch's global generator (seeded by VMAS), not from
  our per-episode ChaCha8 seeds.
"""

from __future__ import annotations

import copy
import math
from typing import Callable, Dict, List, Optional

import torch
from vmas.simulator.core import Agent, Box, Landmark, Line, Sphere, World
from vmas.simulator.dynamics.common import Dynamics
from vmas.simulator.scenario import BaseScenario
from vmas.simulator.utils import LINE_MIN_DIST, Color

# configs/default.toml (sim/src/config.rs), by field name.
DEFAULTS = dict(
    room_size=2.3, dt=0.1, substeps=1, episode_steps=200,
    drag=0.25, collision_force=100.0, contact_margin=1e-3, mass=1.0, max_force=3.0,
    prep_steps=20, k_speed=0.5, reach=0.08, collision_distance=0.005,
    robot_radius=0.08, machine_size=(0.24, 0.24), storage_size=(0.3, 0.16),
    occupancy=0.35, box_gap_diameters=1.25,
    pick=3.0, place=5.0, collision=-0.3, progress=2.0, utilization=-0.02, time=-0.01,
)
ROBOT_CLEARANCE_RADII = 0.25  # sim/src/layout.rs
N_ACTIONS = 5

# VMAS maps discrete action a of a 5-value axis to u: 0 -> 0, 1 -> -1, 2 -> -0.5, 3 -> 0.5,
# 4 -> 1; round(2 (u + 1)) is then 2, 0, 1, 3, 4. Row g of this table is the paper's move of
# the action that gives g: left, right, stay, down, up (unit vectors, times k_speed).
_MOVE_OF_U_INDEX = ((-1.0, 0.0), (1.0, 0.0), (0.0, 0.0), (0.0, -1.0), (0.0, 1.0))


def parse_setup(setup: str):
    """"6.4_2" (or "6_4_2") -> (6, 4, 2)."""
    s = setup.split("/", 1)[-1].replace(".", "_").split("_")
    if len(s) != 3 or not all(x.isdigit() and int(x) > 0 for x in s):
        raise ValueError(f"setup: expected N.M_K with positive counts, got {setup!r}")
    return tuple(int(x) for x in s)


def sizes_for(n: int, m: int, k: int, c: dict) -> dict:
    """Body sizes by sim/src/layout.rs sizes_for: scale every length when the bodies (boxes
    with their gap halo) would cover more than ``occupancy`` of the floor."""
    room_area = c["room_size"] ** 2
    r = c["robot_radius"]
    g = c["box_gap_diameters"] * 2 * r
    (mw, mh), (sw, sh) = c["machine_size"], c["storage_size"]
    footprint = n * math.pi * r * r + m * (mw + g) * (mh + g) + k * (sw + g) * (sh + g)
    s = math.sqrt(c["occupancy"] * room_area / footprint) if footprint > c["occupancy"] * room_area else 1.0
    return dict(scale=s, robot_radius=r * s, machine_half=(mw * s / 2, mh * s / 2),
                storage_half=(sw * s / 2, sh * s / 2), reach=c["reach"] * s)


def box_signed_distance(p: torch.Tensor, centre: torch.Tensor, half) -> torch.Tensor:
    """Signed distance from points ``p`` (..., 2) to axis-aligned boxes (negative inside)."""
    q = (p - centre).abs() - torch.as_tensor(half, dtype=p.dtype, device=p.device)
    outside = q.clamp(min=0).norm(dim=-1)
    inside = q.max(dim=-1).values.clamp(max=0)
    return outside + inside


class VelocityTracker(Dynamics):
    """The 5 discrete moves as velocity commands, tracked as our simulator does: force =
    mass (command - (1 - drag) v) / dt, norm capped at max_force (held for the step, like a
    VMAS action force; contact forces act on top)."""

    def __init__(self, k_speed, dt, drag, mass, max_force):
        super().__init__()
        self.k_speed, self.dt, self.drag, self.mass, self.max_force = k_speed, dt, drag, mass, max_force
        self._table = None

    @property
    def needed_action_size(self) -> int:
        return 1

    def process_action(self):
        u = self.agent.action.u[:, 0]
        if self._table is None or self._table.device != u.device:
            self._table = torch.tensor(_MOVE_OF_U_INDEX, device=u.device) * self.k_speed
        g = torch.round(2 * (u + 1)).long().clamp(0, 4)
        cmd = self._table[g]
        f = self.mass * (cmd - (1 - self.drag) * self.agent.state.vel) / self.dt
        norm = f.norm(dim=-1, keepdim=True)
        f = torch.where(norm > self.max_force, f * self.max_force / norm.clamp(min=1e-12), f)
        self.agent.state.force = f


class TendingScenario(BaseScenario):
    """The machine-tending scenario (rules: module docstring)."""

    def make_world(self, batch_dim: int, device: torch.device, **kwargs):
        setup = kwargs.pop("setup", "6.4_2")
        self.obs_layout = kwargs.pop("obs_layout", "full")
        if self.obs_layout not in ("full", "tending"):
            raise ValueError(f"obs_layout: 'full' or 'tending', got {self.obs_layout!r}")
        c = dict(DEFAULTS)
        for key in list(kwargs):
            if key not in c:
                raise ValueError(f"unknown tending scenario argument {key!r}")
            c[key] = kwargs.pop(key)
        self.c = c
        self.n, self.m, self.k = parse_setup(setup)
        self.sizes = sizes_for(self.n, self.m, self.k, c)
        r = self.sizes["robot_radius"]
        self.half_room = c["room_size"] / 2

        world = World(batch_dim, device, dt=c["dt"], substeps=c["substeps"], drag=c["drag"],
                      collision_force=c["collision_force"], contact_margin=c["contact_margin"])
        for i in range(self.n):
            world.add_agent(Agent(
                name=f"robot_{i}", shape=Sphere(radius=r), mass=c["mass"], rotatable=False,
                collide=True, color=Color.BLUE, u_range=1.0, action_size=1,
                discrete_action_nvec=[N_ACTIONS],
                dynamics=VelocityTracker(c["k_speed"], c["dt"], c["drag"], c["mass"],
                                         c["max_force"])))
        # VMAS pushes a sphere off a box or line from LINE_MIN_DIST (6.7 mm) beyond its
        # surface; the physical boxes are that much smaller and the walls that much farther
        # out, so contact starts at the rules' surfaces (pick, place and collision counting
        # use the true sizes).
        mh, sh = self.sizes["machine_half"], self.sizes["storage_half"]
        box = lambda h: Box(length=2 * (h[0] - LINE_MIN_DIST), width=2 * (h[1] - LINE_MIN_DIST))
        self.machines = [Landmark(f"machine_{j}", shape=box(mh), collide=True, movable=False,
                                  color=Color.RED) for j in range(self.m)]
        self.storages = [Landmark(f"storage_{j}", shape=box(sh), collide=True, movable=False,
                                  color=Color.GREEN) for j in range(self.k)]
        # Walls: lines on the room's four sides.
        self.walls = [Landmark(f"wall_{j}", shape=Line(length=c["room_size"] + 2 * LINE_MIN_DIST),
                               collide=True, movable=False, color=Color.BLACK) for j in range(4)]
        for lm in self.machines + self.storages + self.walls:
            world.add_landmark(lm)

        z = lambda *s, dt=torch.float32: torch.zeros(batch_dim, *s, device=device, dtype=dt)
        self.has_part = z(self.n, dt=torch.bool)
        self.ready = z(self.m, dt=torch.bool)
        self.timer = z(self.m, dt=torch.long)
        self.t = z(dt=torch.long)
        self.delivered = z()
        self.collected = z()
        self.collisions = z()
        self.rew = z(self.n)
        self.prev = z(self.n, 2)
        self.m_pos = z(self.m, 2)
        self.s_pos = z(self.k, 2)
        self._obs = None
        self.index = {a.name: i for i, a in enumerate(world.agents)}
        return world

    # -- layout ------------------------------------------------------------------------

    def _sample_layout(self, b: int, device):
        """Storages, machines, robots for ``b`` envs by sim/src/layout.rs's rule, batched:
        each body draws candidates for every env at once and takes the first that fits."""
        c, s = self.c, self.sizes
        lim, r = self.half_room, s["robot_radius"]
        gap = c["box_gap_diameters"] * 2 * r
        tries = 64
        boxes: List[tuple] = []  # (centres (b,2), half)

        def draw(bound_x, bound_y, fits):
            out = torch.empty(b, 2, device=device)
            todo = torch.ones(b, dtype=torch.bool, device=device)
            for _ in range(200):
                nb = int(todo.sum())
                cand = (torch.rand(nb, tries, 2, device=device) * 2 - 1) * torch.tensor(
                    [bound_x, bound_y], device=device)
                ok = fits(cand, todo)
                found = ok.any(1)
                first = ok.float().argmax(1)
                pick = cand[torch.arange(nb, device=device), first]
                idx = todo.nonzero().squeeze(1)
                out[idx[found]] = pick[found]
                todo[idx[found]] = False
                if not todo.any():
                    return out
            raise RuntimeError(f"tending layout: no room for a body of {self.n}.{self.m}_{self.k}")

        def box_fits(half):
            def fits(cand, todo):
                ok = torch.ones(cand.shape[:2], dtype=torch.bool, device=device)
                for centres, bh in boxes:
                    d = (cand - centres[todo].unsqueeze(1)).abs()
                    ok &= (d[..., 0] >= bh[0] + half[0] + gap) | (d[..., 1] >= bh[1] + half[1] + gap)
                return ok
            return fits

        storages, machines = [], []
        for half, out in ((s["storage_half"], storages), (s["machine_half"], machines)):
            for _ in range(self.k if out is storages else self.m):
                centre = draw(lim - half[0] - gap, lim - half[1] - gap, box_fits(half))
                boxes.append((centre, half))
                out.append(centre)
        robots: List[torch.Tensor] = []
        clear = r * ROBOT_CLEARANCE_RADII

        def robot_fits(cand, todo):
            ok = torch.ones(cand.shape[:2], dtype=torch.bool, device=device)
            for centres, bh in boxes:
                ok &= box_signed_distance(cand, centres[todo].unsqueeze(1), bh) >= r + clear
            for q in robots:
                ok &= (cand - q[todo].unsqueeze(1)).norm(dim=-1) >= 2 * r + clear
            return ok

        bound = lim - r * (1 + ROBOT_CLEARANCE_RADII)
        for _ in range(self.n):
            robots.append(draw(bound, bound, robot_fits))
        return torch.stack(robots, 1), torch.stack(machines, 1), torch.stack(storages, 1)

    def reset_world_at(self, env_index: Optional[int] = None):
        w = self.world
        b = w.batch_dim if env_index is None else 1
        robots, machines, storages = self._sample_layout(b, w.device)
        sel = slice(None) if env_index is None else env_index
        if env_index is not None:
            robots, machines, storages = robots[0], machines[0], storages[0]
        for i, a in enumerate(w.agents):
            a.set_pos(robots[..., i, :], batch_index=env_index)
        zero = torch.zeros(w.batch_dim if env_index is None else 1, 1, device=w.device)
        if env_index is not None:
            zero = zero[0]
        for j, lm in enumerate(self.machines):
            lm.set_pos(machines[..., j, :], batch_index=env_index)
            lm.set_rot(zero, batch_index=env_index)
        for j, lm in enumerate(self.storages):
            lm.set_pos(storages[..., j, :], batch_index=env_index)
            lm.set_rot(zero, batch_index=env_index)
        h = self.half_room + LINE_MIN_DIST
        for lm, (x, y, rot) in zip(self.walls, ((h, 0, math.pi / 2), (-h, 0, math.pi / 2),
                                                (0, h, 0.0), (0, -h, 0.0))):
            pos = torch.tensor([x, y], dtype=torch.float32, device=w.device)
            rot_t = torch.tensor([rot], dtype=torch.float32, device=w.device)
            if env_index is None:
                pos, rot_t = pos.expand(w.batch_dim, 2), rot_t.expand(w.batch_dim, 1)
            lm.set_pos(pos, batch_index=env_index)
            lm.set_rot(rot_t, batch_index=env_index)
        self.m_pos[sel] = machines
        self.s_pos[sel] = storages
        self.has_part[sel] = False
        self.ready[sel] = True  # a machine starts with a part ready
        self.timer[sel] = 0
        self.t[sel] = 0
        self.delivered[sel] = 0
        self.collected[sel] = 0
        self.collisions[sel] = 0
        self.rew[sel] = 0
        self._obs = None

    # -- step --------------------------------------------------------------------------

    def _robot_pos(self):
        return torch.stack([a.state.pos for a in self.world.agents], 1)

    def pre_step(self):
        self.prev = self._robot_pos().clone()

    def post_step(self):
        """Collisions, machines, picks, places and rewards, in sim/src/env/step.rs order."""
        c, s = self.c, self.sizes
        r, reach, cd = s["robot_radius"], s["reach"], c["collision_distance"]
        p = self._robot_pos()  # (B, N, 2)
        dev = p.device

        # Collisions: bodies each robot touches (surface distance <= cd).
        dd = (p.unsqueeze(2) - p.unsqueeze(1)).norm(dim=-1)
        eye = torch.eye(self.n, dtype=torch.bool, device=dev)
        hits = ((dd <= 2 * r + cd) & ~eye).sum(-1).float()
        sd_m = box_signed_distance(p.unsqueeze(2), self.m_pos.unsqueeze(1), s["machine_half"]) - r
        sd_s = box_signed_distance(p.unsqueeze(2), self.s_pos.unsqueeze(1), s["storage_half"]) - r
        hits += (sd_m <= cd).sum(-1) + (sd_s <= cd).sum(-1)
        hits += (self.half_room - p.abs() - r <= cd).sum(-1)
        self.collisions += hits.sum(-1)

        # Machines make parts: count down, ready at 0.
        waiting = ~self.ready
        self.timer = torch.where(waiting, (self.timer - 1).clamp(min=0), self.timer)
        self.ready |= waiting & (self.timer == 0)

        # Progress towards the nearest target, one target set for both positions.
        inf = torch.tensor(float("inf"), device=dev)
        d_now = (p.unsqueeze(2) - self.m_pos.unsqueeze(1)).norm(dim=-1)
        d_prev = (self.prev.unsqueeze(2) - self.m_pos.unsqueeze(1)).norm(dim=-1)
        ready = self.ready.unsqueeze(1)
        m_now = torch.where(ready, d_now, inf).min(-1).values
        m_prev = torch.where(ready, d_prev, inf).min(-1).values
        s_now = (p.unsqueeze(2) - self.s_pos.unsqueeze(1)).norm(dim=-1).min(-1).values
        s_prev = (self.prev.unsqueeze(2) - self.s_pos.unsqueeze(1)).norm(dim=-1).min(-1).values
        had = self.has_part.clone()
        machine_progress = torch.where(torch.isfinite(m_now), m_prev - m_now, torch.zeros_like(m_now))
        progress = torch.where(had, s_prev - s_now, machine_progress)
        rew = c["progress"] * progress + c["collision"] * hits

        # Places: a robot with a part within reach of any storage.
        placed = had & (sd_s <= reach).any(-1)
        self.has_part &= ~placed
        self.delivered += placed.sum(-1)
        # Picks: robots in index order, each the nearest ready machine within reach.
        picked = torch.zeros_like(had)
        for i in range(self.n):
            d = torch.where(self.ready & (sd_m[:, i] <= reach), sd_m[:, i], inf)
            best, j = d.min(-1)
            take = ~had[:, i] & torch.isfinite(best)
            rows = take.nonzero().squeeze(1)
            self.ready[rows, j[rows]] = False
            self.timer[rows, j[rows]] = c["prep_steps"]
            picked[:, i] = take
        self.has_part |= picked
        self.collected += picked.sum(-1)
        rew += c["place"] * placed + c["pick"] * picked

        # Utilization and time penalties after all picks.
        r_u = c["utilization"] * self.ready.sum(-1, keepdim=True).float() / self.m
        rew += r_u
        idle = ~picked & ~placed & (r_u == 0)
        rew += c["time"] * idle
        self.rew = rew
        self.t += 1
        self._obs = None

    def reward(self, agent: Agent):
        return self.rew[:, self.index[agent.name]]

    # -- observation and info ----------------------------------------------------------

    def _observe_all(self):
        p = self._robot_pos()
        b = p.shape[0]
        part = self.has_part.float().unsqueeze(-1)
        rel_m = self.m_pos.unsqueeze(1) - p.unsqueeze(2)  # (B, N, M, 2)
        ready = self.ready.float().unsqueeze(1).unsqueeze(-1).expand(b, self.n, self.m, 1)
        rel_s = (self.s_pos.unsqueeze(1) - p.unsqueeze(2)).reshape(b, self.n, -1)
        rel_p = p.unsqueeze(1) - p.unsqueeze(2)  # (B, N, N, 2): [i, j] = p_j - p_i
        peers = torch.cat([rel_p, part.unsqueeze(1).expand(b, self.n, self.n, 1)], -1)
        off = ~torch.eye(self.n, dtype=torch.bool, device=p.device)
        peers = peers[:, off].reshape(b, self.n, -1)  # row-major: robot i's others in order
        if self.obs_layout == "tending":
            own = torch.cat([p, part], -1)
            machines = torch.cat([rel_m, ready], -1).reshape(b, self.n, -1)
        else:
            vel = torch.stack([a.state.vel for a in self.world.agents], 1)
            own = torch.cat([p, vel, part], -1)
            left = (self.timer.float() / self.c["prep_steps"]).unsqueeze(1).unsqueeze(-1)
            machines = torch.cat([rel_m, ready, left.expand(b, self.n, self.m, 1)], -1)
            machines = machines.reshape(b, self.n, -1)
        return torch.cat([own, machines, rel_s, peers], -1)

    def observation(self, agent: Agent):
        i = self.index[agent.name]
        if i == 0 or self._obs is None:
            self._obs = self._observe_all()
        return self._obs[:, i]

    def info(self, agent: Agent) -> Dict[str, torch.Tensor]:
        # Episode totals on the last step only, as TendingEnv reports them.
        end = (self.t >= self.c["episode_steps"]).float()
        p_max = self.m * torch.ceil(self.t.float() / self.c["prep_steps"]).clamp(min=1)
        return {"parts_delivered": (self.delivered * end).unsqueeze(-1),
                "collisions": (self.collisions * end).unsqueeze(-1),
                "mu": (self.collected / p_max * end).unsqueeze(-1)}


# -- BenchMARL -----------------------------------------------------------------------------

ENV_NAME = "vmas_tending"


def _task_class():
    """The BenchMARL task class, built on first use (importing benchmarl takes seconds, and
    the scenario alone needs only vmas and torch), then kept as the module attribute
    ``VmasTendingClass`` so that BenchMARL can pickle the task."""
    if "VmasTendingClass" in globals():
        return globals()["VmasTendingClass"]
    from benchmarl.environments.common import TaskClass as _TaskClass

    class VmasTendingClass(_TaskClass):
        """BenchMARL task: TorchRL's ``VmasEnv`` over a :class:`TendingScenario` instance
        (discrete actions only; one group ``"agents"``, as ``tending/<setup>`` has)."""

        def get_env_fun(self, num_envs: int, continuous_actions: bool, seed: Optional[int],
                        device) -> Callable:
            from torchrl.envs.libs.vmas import VmasEnv
            from torchrl.envs.utils import MarlGroupMapType

            if continuous_actions:
                raise ValueError("vmas_tending has the paper's 5 discrete actions only")
            cfg = copy.deepcopy(self.config)
            steps = cfg.get("episode_steps", DEFAULTS["episode_steps"])
            return lambda: VmasEnv(
                scenario=TendingScenario(), num_envs=num_envs, continuous_actions=False,
                max_steps=steps, seed=seed, device=device, categorical_actions=True,
                group_map=MarlGroupMapType.ALL_IN_ONE_GROUP, **cfg)

        def supports_continuous_actions(self) -> bool:
            return False

        def supports_discrete_actions(self) -> bool:
            return True

        def has_render(self, env) -> bool:
            return False

        def max_steps(self, env) -> int:
            return self.config.get("episode_steps", DEFAULTS["episode_steps"])

        def group_map(self, env):
            return env.group_map

        def observation_spec(self, env):
            spec = env.full_observation_spec_unbatched.clone()
            for group in self.group_map(env):
                if "info" in spec[group]:
                    del spec[(group, "info")]
            return spec

        def info_spec(self, env):
            spec = env.full_observation_spec_unbatched.clone()
            for group in self.group_map(env):
                del spec[(group, "observation")]
            return spec

        def state_spec(self, env):
            return None

        def action_spec(self, env):
            return env.full_action_spec_unbatched

        def action_mask_spec(self, env):
            return None

        @staticmethod
        def env_name() -> str:
            return ENV_NAME

    VmasTendingClass.__qualname__ = "VmasTendingClass"
    globals()["VmasTendingClass"] = VmasTendingClass
    return VmasTendingClass


def task(name: str = "6.4_2", **config):
    """The BenchMARL task ``vmas_tending/<setup>`` (``name`` "6.4_2" or
    "vmas_tending/6.4_2"); ``config``: scenario kwargs (``obs_layout``, constants)."""
    setup = name.split("/", 1)[1] if name.startswith(ENV_NAME + "/") else name
    parse_setup(setup)
    return _task_class()(name=setup, config={"setup": setup, **config})
