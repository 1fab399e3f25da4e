//! The step: commands to velocities, contact forces and integration, collisions,
//! machines, pick/place and rewards, and P_max.

use super::{Env, RobotEvents};
use crate::{action_to_velocity, SimError};

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
        // `contact_onset` holds "was in contact last step" until the count below turns it
        // into "started touching this step" (no second per-robot vector to keep in step
        // with robots added and removed live; a robot added live starts untouched).
        for e in &mut self.r_events {
            let was = e.collisions > 0;
            *e = RobotEvents::default();
            e.contact_onset = was;
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
        let mut onsets = 0;
        for e in &mut self.r_events {
            e.contact_onset = e.collisions > 0 && !e.contact_onset;
            onsets += e.contact_onset as u32;
        }
        m.collision_events += onsets;
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

    pub(super) fn machine_p_max(&self, alive: u32) -> u32 {
        alive.div_ceil(self.cfg.task.prep_steps)
    }

    pub(super) fn update_p_max(&mut self) {
        let live: u32 = self.m_alive.iter().map(|&a| self.machine_p_max(a)).sum();
        self.metrics.p_max = self.p_max_removed + live;
    }
}
