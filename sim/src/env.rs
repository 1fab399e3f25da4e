//! One tending environment: bodies, the step, pick/place, rewards and metrics.

use crate::entities::{MachineId, RobotId, Sizes, StaticBox, StorageId};
use crate::grid::Grid;
use crate::layout::{self, generate, sizes_for};
use crate::metrics::Metrics;
use crate::{action_to_velocity, ScenarioConfig, Setup, SimError};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// What happened to one robot in the last step.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RobotEvents {
    pub picked: Option<MachineId>,
    pub placed: Option<StorageId>,
    /// Bodies this robot touched at the end of the step.
    pub collisions: u32,
}

/// Read-only view of a robot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotView {
    pub id: RobotId,
    pub pos: [f32; 2],
    pub vel: [f32; 2],
    pub has_part: bool,
}

/// Read-only view of a machine.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MachineView {
    pub id: MachineId,
    pub centre: [f32; 2],
    pub half: [f32; 2],
    pub part_ready: bool,
    /// Steps until the next part is ready (0 when ready).
    pub timer: u32,
}

/// Read-only view of a storage area.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StorageView {
    pub id: StorageId,
    pub centre: [f32; 2],
    pub half: [f32; 2],
}

#[derive(Debug, Clone)]
pub struct Env {
    cfg: ScenarioConfig,
    setup: Setup,
    sizes: Sizes,
    rng: ChaCha8Rng,
    steps: u32,
    next_id: [u32; 3],

    r_id: Vec<RobotId>,
    r_pos: Vec<[f32; 2]>,
    r_vel: Vec<[f32; 2]>,
    r_prev: Vec<[f32; 2]>,
    r_force: Vec<[f32; 2]>,
    r_part: Vec<bool>,
    r_reward: Vec<f32>,
    r_events: Vec<RobotEvents>,

    m_id: Vec<MachineId>,
    m_box: Vec<StaticBox>,
    m_ready: Vec<bool>,
    m_timer: Vec<u32>,
    m_alive: Vec<u32>,

    s_id: Vec<StorageId>,
    s_box: Vec<StaticBox>,

    grid: Grid,
    ready_scratch: Vec<[f32; 2]>,
    metrics: Metrics,
    /// P_max contribution of machines removed during the episode.
    p_max_removed: u32,
}

#[inline]
fn softplus_pen(x: f32, k: f32) -> f32 {
    // k * ln(1 + exp(x / k)), stable for large x (VMAS's contact penetration).
    let z = x / k;
    if z > 20.0 {
        x
    } else {
        k * z.exp().ln_1p()
    }
}

/// Distance from `p` to the nearest point of `set`, None for an empty set.
#[inline]
fn nearest(set: &[[f32; 2]], p: [f32; 2]) -> Option<f32> {
    let mut best = f32::INFINITY;
    for &c in set {
        best = best.min(dist2(c, p));
    }
    best.is_finite().then(|| best.sqrt())
}

#[inline]
fn dist2(a: [f32; 2], b: [f32; 2]) -> f32 {
    let dx = a[0] - b[0];
    let dy = a[1] - b[1];
    dx * dx + dy * dy
}

impl Env {
    /// A new environment of `setup`, laid out from `seed`.
    pub fn new(cfg: ScenarioConfig, setup: Setup, seed: u64) -> Result<Self, SimError> {
        cfg.validate()?;
        if setup.machines == 0 || setup.storages == 0 || setup.robots == 0 {
            return Err(SimError::BadSetup {
                setup: setup.to_string(),
                reason: "a setup needs at least one robot, one machine and one storage".into(),
            });
        }
        let sizes = sizes_for(setup, &cfg);
        let interaction = 2.0 * sizes.robot_radius + cfg.task.collision_distance.max(0.0);
        let grid = Grid::new(cfg.world.room_size, interaction);
        let mut env = Env {
            cfg,
            setup,
            sizes,
            rng: ChaCha8Rng::seed_from_u64(seed),
            steps: 0,
            next_id: [0; 3],
            r_id: Vec::new(),
            r_pos: Vec::new(),
            r_vel: Vec::new(),
            r_prev: Vec::new(),
            r_force: Vec::new(),
            r_part: Vec::new(),
            r_reward: Vec::new(),
            r_events: Vec::new(),
            m_id: Vec::new(),
            m_box: Vec::new(),
            m_ready: Vec::new(),
            m_timer: Vec::new(),
            m_alive: Vec::new(),
            s_id: Vec::new(),
            s_box: Vec::new(),
            grid,
            ready_scratch: Vec::new(),
            metrics: Metrics::default(),
            p_max_removed: 0,
        };
        env.reset(seed)?;
        Ok(env)
    }

    /// An environment with bodies at given positions (tests, replays, hand-made floors).
    /// Sizes follow `setup` as usual; positions must be finite.
    pub fn with_layout(
        cfg: ScenarioConfig,
        setup: Setup,
        layout: layout::Layout,
        seed: u64,
    ) -> Result<Self, SimError> {
        let mut env = Self::new(cfg, setup, seed)?;
        let all = layout
            .robots
            .iter()
            .chain(&layout.machines)
            .chain(&layout.storages);
        if let Some(p) = all
            .clone()
            .find(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            return Err(SimError::BadPosition {
                kind: "layout body",
                x: p[0],
                y: p[1],
            });
        }
        env.clear_bodies();
        for c in layout.storages {
            env.push_storage(c);
        }
        for c in layout.machines {
            env.push_machine(c);
        }
        for p in layout.robots {
            env.push_robot(p);
        }
        env.grid.rebuild(&env.r_pos);
        env.update_p_max();
        Ok(env)
    }

    fn clear_bodies(&mut self) {
        self.steps = 0;
        self.next_id = [0; 3];
        self.metrics = Metrics::default();
        self.p_max_removed = 0;
        for v in [
            &mut self.r_pos,
            &mut self.r_vel,
            &mut self.r_prev,
            &mut self.r_force,
        ] {
            v.clear();
        }
        self.r_id.clear();
        self.r_part.clear();
        self.r_reward.clear();
        self.r_events.clear();
        self.m_id.clear();
        self.m_box.clear();
        self.m_ready.clear();
        self.m_timer.clear();
        self.m_alive.clear();
        self.s_id.clear();
        self.s_box.clear();
    }

    /// Start a new episode with the initial setup, laid out from `seed`.
    pub fn reset(&mut self, seed: u64) -> Result<(), SimError> {
        self.rng = ChaCha8Rng::seed_from_u64(seed);
        let l = generate(self.setup, &self.cfg, &self.sizes, &mut self.rng)?;
        self.clear_bodies();
        for c in l.storages {
            self.push_storage(c);
        }
        for c in l.machines {
            self.push_machine(c);
        }
        for p in l.robots {
            self.push_robot(p);
        }
        self.grid.rebuild(&self.r_pos);
        self.update_p_max();
        Ok(())
    }

    fn push_robot(&mut self, p: [f32; 2]) -> RobotId {
        let id = RobotId(self.next_id[0]);
        self.next_id[0] += 1;
        self.r_id.push(id);
        self.r_pos.push(p);
        self.r_vel.push([0.0; 2]);
        self.r_prev.push(p);
        self.r_force.push([0.0; 2]);
        self.r_part.push(false);
        self.r_reward.push(0.0);
        self.r_events.push(RobotEvents::default());
        id
    }

    fn push_machine(&mut self, c: [f32; 2]) -> MachineId {
        let id = MachineId(self.next_id[1]);
        self.next_id[1] += 1;
        self.m_id.push(id);
        self.m_box.push(StaticBox {
            centre: c,
            half: self.sizes.machine_half,
        });
        // A machine starts with a part ready (it has been producing before the shift).
        self.m_ready.push(true);
        self.m_timer.push(0);
        self.m_alive.push(0);
        id
    }

    fn push_storage(&mut self, c: [f32; 2]) -> StorageId {
        let id = StorageId(self.next_id[2]);
        self.next_id[2] += 1;
        self.s_id.push(id);
        self.s_box.push(StaticBox {
            centre: c,
            half: self.sizes.storage_half,
        });
        id
    }

    fn all_boxes(&self) -> Vec<StaticBox> {
        self.m_box
            .iter()
            .chain(self.s_box.iter())
            .copied()
            .collect()
    }

    // ---- live add / remove -------------------------------------------------------------

    /// Add a robot at `pos`, or at a free spot drawn from the environment's rng.
    pub fn add_robot(&mut self, pos: Option<[f32; 2]>) -> Result<RobotId, SimError> {
        let boxes = self.all_boxes();
        let (room, r) = (self.cfg.world.room_size, self.sizes.robot_radius);
        let p = match pos {
            Some(p) => {
                let ok = p[0].is_finite()
                    && p[1].is_finite()
                    && layout::robot_fits(room, r, p, &boxes, &self.r_pos);
                if !ok {
                    return Err(SimError::BadPosition {
                        kind: "robot",
                        x: p[0],
                        y: p[1],
                    });
                }
                p
            }
            None => layout::sample_robot(&mut self.rng, room, r, &boxes, &self.r_pos).ok_or(
                SimError::NoFreeSpot {
                    kind: "robot",
                    tries: 4000,
                },
            )?,
        };
        let id = self.push_robot(p);
        self.grid.rebuild(&self.r_pos);
        Ok(id)
    }

    pub fn remove_robot(&mut self, id: RobotId) -> Result<(), SimError> {
        let i = self.robot_index(id).ok_or(SimError::UnknownId {
            kind: "robot",
            id: id.0,
        })?;
        // Ordered removal keeps the remaining robots' order (and so determinism).
        self.r_id.remove(i);
        self.r_pos.remove(i);
        self.r_vel.remove(i);
        self.r_prev.remove(i);
        self.r_force.remove(i);
        self.r_part.remove(i);
        self.r_reward.remove(i);
        self.r_events.remove(i);
        self.grid.rebuild(&self.r_pos);
        Ok(())
    }

    fn add_box(&mut self, machine: bool, pos: Option<[f32; 2]>) -> Result<u32, SimError> {
        let kind = if machine { "machine" } else { "storage" };
        let half = if machine {
            self.sizes.machine_half
        } else {
            self.sizes.storage_half
        };
        let boxes = self.all_boxes();
        let room = self.cfg.world.room_size;
        let gap = self.cfg.sizes.box_gap_diameters * 2.0 * self.sizes.robot_radius;
        let r = self.sizes.robot_radius;
        let b = match pos {
            Some(c) => {
                let b = StaticBox { centre: c, half };
                let clear = self
                    .r_pos
                    .iter()
                    .all(|&p| b.signed_distance(p).0 > r * 1.25);
                let ok = c[0].is_finite()
                    && c[1].is_finite()
                    && clear
                    && layout::box_fits(room, gap, &b, &boxes);
                if !ok {
                    return Err(SimError::BadPosition {
                        kind,
                        x: c[0],
                        y: c[1],
                    });
                }
                b
            }
            None => layout::sample_box(&mut self.rng, room, gap, half, &boxes, &self.r_pos, r)
                .ok_or(SimError::NoFreeSpot { kind, tries: 4000 })?,
        };
        Ok(if machine {
            self.push_machine(b.centre).0
        } else {
            self.push_storage(b.centre).0
        })
    }

    pub fn add_machine(&mut self, pos: Option<[f32; 2]>) -> Result<MachineId, SimError> {
        let id = self.add_box(true, pos).map(MachineId)?;
        self.update_p_max();
        Ok(id)
    }

    pub fn add_storage(&mut self, pos: Option<[f32; 2]>) -> Result<StorageId, SimError> {
        self.add_box(false, pos).map(StorageId)
    }

    pub fn remove_machine(&mut self, id: MachineId) -> Result<(), SimError> {
        let j = self
            .m_id
            .iter()
            .position(|&m| m == id)
            .ok_or(SimError::UnknownId {
                kind: "machine",
                id: id.0,
            })?;
        self.p_max_removed += self.machine_p_max(self.m_alive[j]);
        self.m_id.remove(j);
        self.m_box.remove(j);
        self.m_ready.remove(j);
        self.m_timer.remove(j);
        self.m_alive.remove(j);
        self.update_p_max();
        Ok(())
    }

    pub fn remove_storage(&mut self, id: StorageId) -> Result<(), SimError> {
        let k = self
            .s_id
            .iter()
            .position(|&s| s == id)
            .ok_or(SimError::UnknownId {
                kind: "storage",
                id: id.0,
            })?;
        self.s_id.remove(k);
        self.s_box.remove(k);
        Ok(())
    }

    // ---- accessors ----------------------------------------------------------------------

    pub fn config(&self) -> &ScenarioConfig {
        &self.cfg
    }
    pub fn setup(&self) -> Setup {
        self.setup
    }
    /// The current counts (they differ from `setup()` after live changes).
    pub fn counts(&self) -> Setup {
        Setup::new(self.r_id.len(), self.m_id.len(), self.s_id.len())
    }
    pub fn sizes(&self) -> &Sizes {
        &self.sizes
    }
    pub fn steps(&self) -> u32 {
        self.steps
    }
    pub fn is_done(&self) -> bool {
        self.steps >= self.cfg.world.episode_steps
    }
    pub fn metrics(&self) -> &Metrics {
        &self.metrics
    }
    pub fn n_robots(&self) -> usize {
        self.r_id.len()
    }
    pub fn robot_ids(&self) -> &[RobotId] {
        &self.r_id
    }
    pub fn robot_index(&self, id: RobotId) -> Option<usize> {
        self.r_id.iter().position(|&r| r == id)
    }
    /// Per-robot rewards of the last step, in robot order.
    pub fn rewards(&self) -> &[f32] {
        &self.r_reward
    }
    /// Per-robot events of the last step, in robot order.
    pub fn events(&self) -> &[RobotEvents] {
        &self.r_events
    }
    pub fn robots(&self) -> impl ExactSizeIterator<Item = RobotView> + '_ {
        (0..self.r_id.len()).map(|i| RobotView {
            id: self.r_id[i],
            pos: self.r_pos[i],
            vel: self.r_vel[i],
            has_part: self.r_part[i],
        })
    }
    pub fn machines(&self) -> impl ExactSizeIterator<Item = MachineView> + '_ {
        (0..self.m_id.len()).map(|j| MachineView {
            id: self.m_id[j],
            centre: self.m_box[j].centre,
            half: self.m_box[j].half,
            part_ready: self.m_ready[j],
            timer: self.m_timer[j],
        })
    }
    pub fn storages(&self) -> impl ExactSizeIterator<Item = StorageView> + '_ {
        (0..self.s_id.len()).map(|k| StorageView {
            id: self.s_id[k],
            centre: self.s_box[k].centre,
            half: self.s_box[k].half,
        })
    }

    /// Test and tooling hook: put robot `id` at `pos` with velocity `vel`.
    pub fn set_robot_state(
        &mut self,
        id: RobotId,
        pos: [f32; 2],
        vel: [f32; 2],
    ) -> Result<(), SimError> {
        let i = self.robot_index(id).ok_or(SimError::UnknownId {
            kind: "robot",
            id: id.0,
        })?;
        self.r_pos[i] = pos;
        self.r_vel[i] = vel;
        self.r_prev[i] = pos;
        self.grid.rebuild(&self.r_pos);
        Ok(())
    }

    // ---- the step -----------------------------------------------------------------------

    /// Step with the discrete actions of every robot (in robot order).
    pub fn step_actions(&mut self, actions: &[u8]) -> Result<(), SimError> {
        if actions.len() != self.r_id.len() {
            return Err(SimError::WrongCommandCount {
                expected: self.r_id.len(),
                got: actions.len(),
            });
        }
        let k = self.cfg.task.k_speed;
        // Reuse r_force as the command buffer: it is overwritten by the step anyway.
        for (i, &a) in actions.iter().enumerate() {
            self.r_force[i] = action_to_velocity(a, k).ok_or(SimError::BadAction {
                index: i,
                action: a,
            })?;
        }
        self.step_inner();
        Ok(())
    }

    /// Step with a velocity command (vx, vy) in m/s per robot (in robot order): the path
    /// both the discrete actions and the ROS bridge's Twist messages take.
    pub fn step_velocities(&mut self, cmds: &[[f32; 2]]) -> Result<(), SimError> {
        if cmds.len() != self.r_id.len() {
            return Err(SimError::WrongCommandCount {
                expected: self.r_id.len(),
                got: cmds.len(),
            });
        }
        if let Some(i) = cmds
            .iter()
            .position(|c| !(c[0].is_finite() && c[1].is_finite()))
        {
            return Err(SimError::NonFiniteCommand {
                robot: self.r_id[i].0,
                vx: cmds[i][0],
                vy: cmds[i][1],
            });
        }
        self.r_force.copy_from_slice(cmds);
        self.step_inner();
        Ok(())
    }

    /// One control step; `r_force` holds the velocity commands on entry.
    fn step_inner(&mut self) {
        let n = self.r_id.len();
        let cfg = &self.cfg;
        let (dt, drag, mass) = (cfg.world.dt, cfg.physics.drag, cfg.physics.mass);
        let (kf, km) = (cfg.physics.collision_force, cfg.physics.contact_margin);
        let k_speed = cfg.task.k_speed;
        let max_force = cfg.physics.max_force;
        let substeps = cfg.world.substeps;
        let sub_dt = dt / substeps as f32;
        let half_room = cfg.world.room_size / 2.0;
        let r = self.sizes.robot_radius;

        // Velocity tracker: the force that reaches the (speed-clamped) command after this
        // step's drag, capped at max_force. Held for all substeps, like a VMAS action.
        let mut track = std::mem::take(&mut self.r_force);
        for i in 0..n {
            let mut c = track[i];
            let s = (c[0] * c[0] + c[1] * c[1]).sqrt();
            if s > k_speed {
                c = [c[0] * k_speed / s, c[1] * k_speed / s];
            }
            let v = self.r_vel[i];
            let mut f = [
                mass * (c[0] - (1.0 - drag) * v[0]) / dt,
                mass * (c[1] - (1.0 - drag) * v[1]) / dt,
            ];
            let fs = (f[0] * f[0] + f[1] * f[1]).sqrt();
            if fs > max_force {
                f = [f[0] * max_force / fs, f[1] * max_force / fs];
            }
            track[i] = f;
            self.r_prev[i] = self.r_pos[i];
        }

        let mut force = std::mem::take(&mut self.ready_scratch); // reused as force buffer
        for sub in 0..substeps {
            force.clear();
            force.extend_from_slice(&track);
            if sub > 0 {
                self.grid.rebuild(&self.r_pos);
            }
            // Robot-robot contacts from the broad phase.
            let pos = &self.r_pos;
            self.grid.for_each_pair(|i, j| {
                let dx = pos[i][0] - pos[j][0];
                let dy = pos[i][1] - pos[j][1];
                let d2 = dx * dx + dy * dy;
                let dmin = 2.0 * r;
                if d2 < dmin * dmin {
                    let d = d2.sqrt().max(1e-6);
                    let f = kf * softplus_pen(dmin - d, km) / d;
                    force[i][0] += f * dx;
                    force[i][1] += f * dy;
                    force[j][0] -= f * dx;
                    force[j][1] -= f * dy;
                }
            });
            for i in 0..n {
                let p = self.r_pos[i];
                // Static boxes (machines and storages): only the robot moves.
                for b in self.m_box.iter().chain(self.s_box.iter()) {
                    if b.far(p, r) {
                        continue;
                    }
                    let (d, dir) = b.signed_distance(p);
                    if d < r {
                        let f = kf * softplus_pen(r - d, km);
                        force[i][0] += f * dir[0];
                        force[i][1] += f * dir[1];
                    }
                }
                // Walls as half-planes: no thickness to tunnel through.
                for (axis, sign) in [(0usize, 1.0f32), (0, -1.0), (1, 1.0), (1, -1.0)] {
                    let d = half_room - sign * p[axis];
                    if d < r {
                        force[i][axis] -= sign * kf * softplus_pen(r - d, km);
                    }
                }
            }
            // Semi-implicit Euler, drag once per step (VMAS).
            for i in 0..n {
                let v = &mut self.r_vel[i];
                if sub == 0 {
                    v[0] *= 1.0 - drag;
                    v[1] *= 1.0 - drag;
                }
                v[0] += force[i][0] / mass * sub_dt;
                v[1] += force[i][1] / mass * sub_dt;
                self.r_pos[i][0] += v[0] * sub_dt;
                self.r_pos[i][1] += v[1] * sub_dt;
            }
        }
        self.r_force = track;
        self.grid.rebuild(&self.r_pos);

        self.count_collisions();
        self.advance_machines();
        self.pick_place_and_reward(&mut force);
        self.ready_scratch = force;

        self.steps += 1;
        for a in &mut self.m_alive {
            *a += 1;
        }
        self.update_p_max();
        self.metrics.steps = self.steps;
    }

    fn count_collisions(&mut self) {
        let r = self.sizes.robot_radius;
        let cd = self.cfg.task.collision_distance;
        let half_room = self.cfg.world.room_size / 2.0;
        for e in &mut self.r_events {
            *e = RobotEvents::default();
        }
        let lim = 2.0 * r + cd;
        let (pos, ev) = (&self.r_pos, &mut self.r_events);
        let mut rr = 0;
        self.grid.for_each_pair(|i, j| {
            if dist2(pos[i], pos[j]) <= lim * lim {
                ev[i].collisions += 1;
                ev[j].collisions += 1;
                rr += 2;
            }
        });
        let (mut rm, mut rs, mut rw) = (0, 0, 0);
        for (i, &p) in self.r_pos.iter().enumerate() {
            for b in &self.m_box {
                if !b.far(p, r + cd) && b.signed_distance(p).0 - r <= cd {
                    self.r_events[i].collisions += 1;
                    rm += 1;
                }
            }
            for b in &self.s_box {
                if !b.far(p, r + cd) && b.signed_distance(p).0 - r <= cd {
                    self.r_events[i].collisions += 1;
                    rs += 1;
                }
            }
            for axis in 0..2 {
                if half_room - p[axis].abs() - r <= cd {
                    self.r_events[i].collisions += 1;
                    rw += 1;
                }
            }
        }
        let m = &mut self.metrics;
        m.collisions_robot_robot += rr;
        m.collisions_robot_machine += rm;
        m.collisions_robot_storage += rs;
        m.collisions_robot_wall += rw;
        m.collisions += rr + rm + rs + rw;
    }

    fn advance_machines(&mut self) {
        for j in 0..self.m_id.len() {
            if !self.m_ready[j] {
                self.m_timer[j] = self.m_timer[j].saturating_sub(1);
                if self.m_timer[j] == 0 {
                    self.m_ready[j] = true;
                }
            }
        }
    }

    /// Picks, places and every reward term of the paper's section IV-C.
    /// `scratch` is a reusable buffer (no allocation in the step loop).
    fn pick_place_and_reward(&mut self, scratch: &mut Vec<[f32; 2]>) {
        let rw = &self.cfg.rewards;
        let r = self.sizes.robot_radius;
        let reach = self.sizes.reach;
        // Targets computed once for all robots (the paper's global computation).
        scratch.clear();
        for j in 0..self.m_id.len() {
            if self.m_ready[j] {
                scratch.push(self.m_box[j].centre);
            }
        }
        // Storage centres go after the ready machines in the same scratch buffer.
        let n_ready = scratch.len();
        scratch.extend(self.s_box.iter().map(|b| b.centre));
        let (ready, stores) = scratch.split_at(n_ready);
        for i in 0..self.r_id.len() {
            let (p, prev) = (self.r_pos[i], self.r_prev[i]);
            let had_part = self.r_part[i];
            // Progress toward the closest target, measured against one target set for both
            // positions so that a target vanishing (picked by another robot) gives no jump.
            let targets = if had_part { stores } else { ready };
            let progress = nearest(targets, prev)
                .zip(nearest(targets, p))
                .map_or(0.0, |(a, b)| a - b);
            let mut reward =
                rw.progress * progress + rw.collision * self.r_events[i].collisions as f32;
            if had_part {
                let hit = self
                    .s_box
                    .iter()
                    .position(|b| !b.far(p, r + reach) && b.signed_distance(p).0 - r <= reach);
                if let Some(k) = hit {
                    self.r_part[i] = false;
                    self.r_events[i].placed = Some(self.s_id[k]);
                    self.metrics.parts_delivered += 1;
                    reward += rw.place;
                }
            } else {
                // First come (robot order), nearest machine within reach.
                let mut best: Option<(usize, f32)> = None;
                for j in 0..self.m_id.len() {
                    let b = &self.m_box[j];
                    if !self.m_ready[j] || b.far(p, r + reach) {
                        continue;
                    }
                    let d = b.signed_distance(p).0 - r;
                    if d <= reach && best.is_none_or(|(_, bd)| d < bd) {
                        best = Some((j, d));
                    }
                }
                if let Some((j, _)) = best {
                    self.m_ready[j] = false;
                    self.m_timer[j] = self.cfg.task.prep_steps;
                    self.r_part[i] = true;
                    self.r_events[i].picked = Some(self.m_id[j]);
                    self.metrics.parts_collected += 1;
                    reward += rw.pick;
                }
            }
            self.r_reward[i] = reward;
        }
        // Utilization penalty and time penalty after all picks of the step.
        let uncollected = self.m_ready.iter().filter(|&&x| x).count();
        let r_u = if self.m_id.is_empty() {
            0.0
        } else {
            rw.utilization * uncollected as f32 / self.m_id.len() as f32
        };
        let mut total = 0.0f64;
        for i in 0..self.r_id.len() {
            let ev = self.r_events[i];
            self.r_reward[i] += r_u;
            if ev.picked.is_none() && ev.placed.is_none() && r_u == 0.0 {
                self.r_reward[i] += rw.time;
            }
            total += self.r_reward[i] as f64;
        }
        self.metrics.total_reward += total;
    }

    fn machine_p_max(&self, alive: u32) -> u32 {
        alive.div_ceil(self.cfg.task.prep_steps)
    }

    fn update_p_max(&mut self) {
        let live: u32 = self.m_alive.iter().map(|&a| self.machine_p_max(a)).sum();
        self.metrics.p_max = self.p_max_removed + live;
    }

    // ---- observations -------------------------------------------------------------------

    /// The entity counts every robot's observation has now.
    pub fn obs_counts(&self) -> obs::Counts {
        obs::Counts {
            machines: self.m_id.len(),
            storages: self.s_id.len(),
            peers: self.r_id.len().saturating_sub(1),
        }
    }

    /// Write every robot's observation (rows in robot order) into the given slices, sized
    /// for `obs_counts()`: own n x 3, machines n x M x 3, storages n x K x 2, peers
    /// n x (n-1) x 3.
    pub fn observe_into(
        &self,
        own: &mut [f32],
        machines: &mut [f32],
        storages: &mut [f32],
        peers: &mut [f32],
    ) {
        let n = self.r_id.len();
        let (m, k) = (self.m_id.len(), self.s_id.len());
        let pw = n.saturating_sub(1) * 3;
        for i in 0..n {
            let [x, y] = self.r_pos[i];
            own[i * 3..i * 3 + 3].copy_from_slice(&[x, y, obs::flag(self.r_part[i])]);
            let mo = &mut machines[i * m * 3..(i + 1) * m * 3];
            for j in 0..m {
                let c = self.m_box[j].centre;
                mo[j * 3] = c[0] - x;
                mo[j * 3 + 1] = c[1] - y;
                mo[j * 3 + 2] = obs::flag(self.m_ready[j]);
            }
            let so = &mut storages[i * k * 2..(i + 1) * k * 2];
            for j in 0..k {
                let c = self.s_box[j].centre;
                so[j * 2] = c[0] - x;
                so[j * 2 + 1] = c[1] - y;
            }
            let po = &mut peers[i * pw..(i + 1) * pw];
            // Peers in robot order without robot i: two straight runs, no per-item branch.
            let (before, after) = po.split_at_mut(i * 3);
            for (o, (q, &hp)) in before
                .chunks_exact_mut(3)
                .zip(self.r_pos[..i].iter().zip(&self.r_part[..i]))
            {
                o[0] = q[0] - x;
                o[1] = q[1] - y;
                o[2] = obs::flag(hp);
            }
            for (o, (q, &hp)) in after
                .chunks_exact_mut(3)
                .zip(self.r_pos[i + 1..].iter().zip(&self.r_part[i + 1..]))
            {
                o[0] = q[0] - x;
                o[1] = q[1] - y;
                o[2] = obs::flag(hp);
            }
        }
    }

    /// Every robot's observation as a batch (resized in place; no allocation once sized).
    pub fn observe(&self, out: &mut obs::ObsBatch) {
        out.resize(self.r_id.len(), self.obs_counts());
        let obs::ObsBatch {
            own,
            machines,
            storages,
            peers,
            ..
        } = out;
        self.observe_into(own, machines, storages, peers);
    }
}
