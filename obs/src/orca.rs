//! Greedy task allocation + ORCA reciprocal collision avoidance (van den Berg et al. 2011,
//! via the `dodgy_2d` port of RVO2): the scripted baseline a factory would deploy.
//!
//! Decentralized and computed from the robot's own observation only (plus the fleet's
//! body sizes, speed, period and room size, which a robot knows as parameters). ORCA needs
//! velocities, which the observation lacks: [`GreedyOrca`] estimates its own and its peers'
//! velocities from successive observations (positions one period apart), so it is stateful
//! like a recurrent policy and must be reset when its inputs jump.
//!
//! The output is a continuous velocity command, not one of the 5 discrete actions: the
//! simulator's native input (`Env::step_velocities`) and robot_node's `cmd_vel` are
//! continuous, and rounding ORCA's velocity to an axis move would void the half-plane
//! guarantee that makes it avoid anything.

use crate::geom::{nearest_on_box, norm};
use crate::greedy::{greedy_target, GreedyParams, Target};
use crate::machine_clock::MachineClock;
use crate::storage_queue::StorageMemory;
use crate::targets;
use dodgy_2d::{Agent, AvoidanceOptions, Obstacle, Vec2};
use std::borrow::Cow;

/// Clearance (m) of ORCA used as a safety filter on a learned policy's command (eval
/// `--orca-filter`, robot_node's default filter, training `orca_filter`). Larger than
/// greedy-ORCA's own 25 mm: a learned policy asks for full speed at every step, so the
/// one-period lag of the velocity estimate and of the base's velocity tracking leaves it
/// touching peers at 25 mm. Tuned on seed 7 (not the evaluation seeds 0-2): at 40 mm the
/// bundled policy keeps its parts up to 42 robots (6.4_2 32.7 either way, 42.28_14 202.5
/// vs 202.4) with 0-0.2 contacts per episode instead of 0.3-6.6; at 100.16_2 it trades
/// parts for contacts (44.4 vs 58.4 parts, 20 vs 118 contacts). docs/RESULTS.md section 7.
pub const FILTER_CLEARANCE: f32 = 0.04;

/// Peer clearance (m) of the ORCA filter for a robot at rest ([`OrcaParams::rest_clearance`]):
/// the filter's clearance shrinks to this as the robot slows, since the velocity lag that
/// [`FILTER_CLEARANCE`] covers grows with speed, and queues at a storage move slowly.
/// Tuned on seeds 7-12 (not the evaluation seeds 0-2), 50 episodes each, the bundled
/// policy: at 30 mm 30.6_1 has 2.6 contact steps per episode to greedy-ORCA's 3.5 and
/// 60.12_3 1.7 to 3.7, the two setups where the margin binds; at 25 mm 100.16_2 has more
/// than the script. Each millimetre buys parts where the storages are the bottleneck
/// (80.40_4: 204.9 at 35 mm, 213.0 at 30). ADR 0017 chose 35 mm on seeds 7-8 alone, where
/// 30.6_1 had 3.2 to the script's 2.5. docs/adr/0019-rest-clearance-30-mm.md.
pub const FILTER_REST_CLEARANCE: f32 = 0.03;

/// A robot with no observed peer nearer than this many radii keeps only greedy-ORCA's
/// clearance to boxes and walls (`GreedyOrca::box_clearance_among`). Tuned on seeds 7-8,
/// 20 episodes each: 6 gains on the robot-poor setups, 10 gains less.
pub const ALONE_RADII: f32 = 6.0;

/// Clearance (m) of greedy-ORCA itself (see [`OrcaParams::new`]).
pub const GREEDY_ORCA_CLEARANCE: f32 = 0.025;

/// Horizon (s) over which greedy-ORCA avoids boxes and walls ([`OrcaParams::obstacle_time_horizon`]).
/// ORCA slows a robot heading for a box once the box's margin is within this many seconds
/// at its speed, so every arrival at a machine or a storage starts braking about
/// `K_speed x horizon` out. Kept for the script as first set: on the tuning screen (seed 7
/// x 20 episodes, 28 setups) 0.15 s gives it 1.039x the parts but up to twice the contact
/// steps where the storages are crowded (80.40_4 16.2 -> 32.1, 90.20_3 9.5 -> 21.4), and
/// the script is the baseline whose contacts the policy must not exceed;
/// `tending eval --script-obstacle-horizon` runs the other point (docs/RESULTS.md 7.18).
pub const OBSTACLE_HORIZON: f32 = 0.3;

/// [`OBSTACLE_HORIZON`] of the ORCA filter behind a learned policy (offline, in training
/// and in robot_node: [`OrcaParams::for_policy_filter`]). The planner sends the robot to a
/// stand-off inside reach of its box, and the pick or place happens as it crosses the
/// reach, so braking 0.15 m out only delays every arrival. Tuned on seed 7 x 20 episodes
/// (not the evaluation seeds 0-2), the bundled policy, 28 setups: 0.1 s 1.012x the parts
/// of 0.3 s, 0.15 s 1.018x, 0.2 s 1.016x (0.12 s and 0.18 s 0.999x and 0.996x of 0.15 s);
/// at 0.1 s contact steps rose to 10-50 per
/// episode on the crowded setups (100.50_10 1.9 -> 50.1), at 0.15 s to at most 6.8
/// (90.20_3, 2.4 before), below greedy-ORCA's on all but 8.6_3 and 16.4_1 (0.2 and 0.1
/// to 0.0). docs/adr/0030-filter-obstacle-horizon.md.
pub const FILTER_OBSTACLE_HORIZON: f32 = 0.15;

/// How far (in robot radii) from a storage box an idle robot backs out ([`OrcaParams::make_room`]).
/// Tuned on seed 7 (not the evaluation seeds 0-2), greedy-ORCA, 20 episodes per setup, 0 to
/// 14 radii: 6-8 are best from 2 to 75 robots (6.4_2 30.7 -> 34.2 parts, 42.28_14 228 ->
/// 243.5), larger values keep helping only at 100.16_2 (40 -> 90 at 8, 111 at 14) and cost
/// parts below it. docs/RESULTS.md section 7.4, docs/adr/0014-make-room.md.
pub const MAKE_ROOM_RADII: f32 = 8.0;

/// [`MAKE_ROOM_RADII`] for the planner of a target-action policy (`crate::targets`), which
/// asks to stay far less often than greedy finds no task, so a wider berth costs it nothing
/// below 100 robots. Tuned on seed 7 (20 episodes per setup, 8-20 radii, the bundled
/// policy): 2-75 robots within the noise from 8 to 20; 100.16_2 67.5 parts at 8, 82.7 at
/// 12, 89.5 at 14; from 14 up one 12.8_4 episode pinned a robot against a box (7.5 contact
/// steps per episode). docs/adr/0016-policy-make-room.md.
pub const POLICY_MAKE_ROOM_RADII: f32 = 12.0;

/// Everything [`GreedyOrca`] plans with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrcaParams {
    pub greedy: GreedyParams,
    /// Half the side of the square room (walls at +-room_half), m.
    pub room_half: f32,
    /// Pick/place reach beyond the robot's radius, m (the simulator's scaled `reach`).
    pub reach: f32,
    /// Clearance kept to peers beyond touching, m (the simulator counts a contact within
    /// its collision distance, 5 mm by default, so this must exceed that). Boxes and walls
    /// get the smaller of this and 0.4 x reach, so that targets stay reachable.
    pub clearance: f32,
    /// Clearance kept to peers by a robot at rest, m, at most [`Self::clearance`]. A robot's
    /// clearance grows linearly with its estimated speed from this to `clearance` at
    /// K_speed, and a pair keeps the mean of its two; equal to `clearance` (greedy-ORCA's
    /// default), the clearance is fixed.
    pub rest_clearance: f32,
    /// Horizon over which collisions with peers are avoided, s.
    pub time_horizon: f32,
    /// Horizon over which collisions with boxes and walls are avoided, s.
    pub obstacle_time_horizon: f32,
    /// At most this many nearest peers constrain the velocity (RVO2's maxNeighbors).
    pub max_neighbours: usize,
    /// A robot with nowhere to go (greedy finds no task, or a target policy asks to stay)
    /// that is closer than this to a storage box backs straight out to this distance, m;
    /// 0 turns it off. Without it, robots that have just delivered and have no task stay
    /// where they placed, the robots bringing the next parts queue around them, and at
    /// 100 robots and 2 storage areas half the fleet ends up carrying parts it cannot place
    /// (docs/adr/0014-make-room.md).
    pub make_room: f32,
    /// Once stuck ([`STUCK_STEPS`]), head for the corner of the box in the way instead of
    /// into it ([`crate::detour`]). On by default; off only to measure what it does.
    pub detour: bool,
}

impl OrcaParams {
    /// Defaults, tuned by hand on 6.4_2, 24.16_8, 42.28_14 and 100.16_2 (20 episodes of
    /// seed 0 each; clearance 0.015-0.03 m, horizon 0.25-1 s tried): a larger clearance
    /// or horizon costs parts at 100 robots, a smaller one lets robots touch there.
    pub fn new(greedy: GreedyParams, room_size: f32, reach: f32) -> Self {
        Self {
            greedy,
            room_half: room_size / 2.0,
            reach,
            clearance: GREEDY_ORCA_CLEARANCE,
            rest_clearance: GREEDY_ORCA_CLEARANCE,
            time_horizon: 0.5,
            obstacle_time_horizon: OBSTACLE_HORIZON,
            max_neighbours: 10,
            make_room: MAKE_ROOM_RADII * greedy.robot_radius,
            detour: true,
        }
    }

    /// The same parameters with the given fixed peer clearance (e.g. [`FILTER_CLEARANCE`]).
    pub fn with_clearance(mut self, clearance: f32) -> Self {
        self.clearance = clearance;
        self.rest_clearance = clearance;
        self
    }

    /// The same parameters with [`Self::rest_clearance`] set (call after
    /// [`Self::with_clearance`], which resets it).
    pub fn with_rest_clearance(mut self, rest_clearance: f32) -> Self {
        self.rest_clearance = rest_clearance;
        self
    }

    /// The same parameters with [`Self::obstacle_time_horizon`] set, s.
    pub fn with_obstacle_horizon(mut self, horizon: f32) -> Self {
        self.obstacle_time_horizon = horizon;
        self
    }

    /// The same parameters with [`Self::make_room`] set to `radii` robot radii.
    pub fn with_make_room_radii(mut self, radii: f32) -> Self {
        self.make_room = radii * self.greedy.robot_radius;
        self
    }

    /// What a learned policy runs behind (offline, in training rollouts and in robot_node
    /// alike; one definition so they cannot drift apart): for its target planner
    /// [`POLICY_MAKE_ROOM_RADII`]; behind the ORCA filter (`filter_clearance` Some) the
    /// filter's peer clearance at full speed and [`FILTER_REST_CLEARANCE`] (or less) at
    /// rest, which also set the planner's stand-off at a box; without the filter
    /// greedy-ORCA's fixed clearance.
    pub fn for_policy(self, filter_clearance: Option<f32>) -> Self {
        match filter_clearance {
            Some(c) => self.for_policy_filter(c, FILTER_REST_CLEARANCE),
            None => self
                .with_clearance(GREEDY_ORCA_CLEARANCE)
                .with_make_room_radii(POLICY_MAKE_ROOM_RADII),
        }
    }

    /// [`Self::for_policy`] behind the filter with both clearances given: `clearance` at
    /// full speed, `rest` (or `clearance` if smaller) at rest, and the filter's
    /// [`FILTER_OBSTACLE_HORIZON`]. For sweeps of the safety margin (`tending eval
    /// --filter-clearance --filter-rest-clearance`); chain [`Self::with_obstacle_horizon`]
    /// for another horizon.
    pub fn for_policy_filter(self, clearance: f32, rest: f32) -> Self {
        self.with_clearance(clearance)
            .with_rest_clearance(clearance.min(rest))
            .with_obstacle_horizon(FILTER_OBSTACLE_HORIZON)
            .with_make_room_radii(POLICY_MAKE_ROOM_RADII)
    }

    /// Refuse values ORCA cannot work with, naming the field.
    pub fn validate(&self) -> Result<(), String> {
        let g = &self.greedy;
        let positive = [
            ("robot_radius", g.robot_radius),
            ("k_speed", g.k_speed),
            ("dt", g.dt),
            ("room_half", self.room_half),
            ("reach", self.reach),
            ("time_horizon", self.time_horizon),
            ("obstacle_time_horizon", self.obstacle_time_horizon),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("ORCA parameter `{name}` must be positive, got {v}"));
            }
        }
        let halves = [g.machine_half, g.storage_half].into_iter().flatten();
        if let Some(v) = halves.into_iter().find(|v| !(v.is_finite() && *v > 0.0)) {
            return Err(format!("ORCA box half size must be positive, got {v}"));
        }
        if !(self.make_room.is_finite() && self.make_room >= 0.0) {
            return Err(format!(
                "ORCA parameter `make_room` must be >= 0, got {}",
                self.make_room
            ));
        }
        if !(self.clearance.is_finite() && self.clearance >= 0.0) {
            return Err(format!(
                "ORCA parameter `clearance` must be >= 0, got {}",
                self.clearance
            ));
        }
        if !(self.rest_clearance.is_finite()
            && (0.0..=self.clearance).contains(&self.rest_clearance))
        {
            return Err(format!(
                "ORCA parameter `rest_clearance` must be between 0 and `clearance` ({}), got {}",
                self.clearance, self.rest_clearance
            ));
        }
        Ok(())
    }

    /// Peer clearance of a robot moving at `speed` m/s ([`Self::rest_clearance`]).
    pub fn clearance_at(&self, speed: f32) -> f32 {
        let f = (speed / self.greedy.k_speed).clamp(0.0, 1.0);
        self.rest_clearance + (self.clearance - self.rest_clearance) * f
    }
}

/// Every box a robot observes, machines then storages: (centre relative to the robot,
/// half size).
fn observed_boxes<'a>(
    machines: &'a [f32],
    storages: &'a [f32],
    g: &'a GreedyParams,
) -> impl Iterator<Item = ([f32; 2], [f32; 2])> + 'a {
    machines
        .chunks_exact(3)
        .map(|m| ([m[0], m[1]], g.machine_half))
        .chain(
            storages
                .chunks_exact(2)
                .map(|s| ([s[0], s[1]], g.storage_half)),
        )
}

/// One robot's greedy-ORCA controller (keeps the previous positions it saw).
#[derive(Debug, Clone)]
pub struct GreedyOrca {
    params: OrcaParams,
    prev_own: Option<[f32; 2]>,
    /// Peers' absolute positions in the previous observation.
    prev_peers: Vec<[f32; 2]>,
    peers_now: Vec<[f32; 2]>,
    /// The storage a carrier heads for under the "matched" entry (`crate::storage_queue`).
    storage_memory: StorageMemory,
    /// The robot's position at the planner's previous call, and the steps in a row it has
    /// not moved since although it wanted to (kept by the planner, not the filter: robot_node
    /// runs them as two instances).
    planned_from: Option<[f32; 2]>,
    stuck_steps: u32,
    /// Steps left going around a box ([`crate::detour`]) after being stuck.
    detour_left: u32,
    /// When each machine will have a part, for the "matched" entry (kept by the planner).
    clock: MachineClock,
}

/// Stuck: this many steps in a row below a tenth of K_speed while the preferred velocity
/// is over half of it; then [`DETOUR_STEPS`] steps of going around the box in the way
/// ([`crate::detour`]). Only when stuck: detouring whenever the straight line met a grown
/// box cost 3 % of the parts (matching-ORCA, seed 7 x 20 episodes, 28 setups: corners
/// are longer than the slide along a face ORCA gives), stuck-triggered gained 1.4 %.
/// 3 and 8 steps, and 8 or 30 detour steps, were within 0.3 % of these.
/// docs/RESULTS.md 7.10.
pub const STUCK_STEPS: u32 = 5;
/// Stuck counts only within this many radii beyond the obstacle margin of a box: a robot
/// held up by peers waits for them rather than being sent for a box corner. Offline the
/// parts are the same within 0.1 % either way (matching-ORCA, seed 7 x 20 episodes, 28
/// setups: 1.013x against 1.014x without the condition).
pub const STUCK_BOX_RADII: f32 = 0.5;
pub const DETOUR_STEPS: u32 = 15;

impl GreedyOrca {
    pub fn new(params: OrcaParams) -> Result<Self, String> {
        params.validate()?;
        Ok(Self {
            clock: MachineClock::new(params.greedy.prep_steps),
            params,
            prev_own: None,
            prev_peers: Vec::new(),
            peers_now: Vec::new(),
            storage_memory: StorageMemory::default(),
            planned_from: None,
            stuck_steps: 0,
            detour_left: 0,
        })
    }

    pub fn params(&self) -> &OrcaParams {
        &self.params
    }

    /// Forget the previous observation (velocities read as zero on the next call) and the
    /// storage a carrier was heading for.
    pub fn reset(&mut self) {
        self.prev_own = None;
        self.prev_peers.clear();
        self.storage_memory.clear();
        self.planned_from = None;
        self.stuck_steps = 0;
        self.detour_left = 0;
        self.clock.reset();
    }

    /// Velocity command (vx, vy), m/s, for one observation row (layout of `ObsBatch`):
    /// the greedy preferred velocity through [`Self::filter`].
    pub fn velocity(
        &mut self,
        own: &[f32],
        machines: &[f32],
        storages: &[f32],
        peers: &[f32],
    ) -> [f32; 2] {
        let pref = self.greedy_preferred(own, machines, storages, peers);
        self.note_progress(own, machines, storages, pref);
        self.filter(own, machines, storages, peers, pref)
    }

    /// Boxes get less clearance than peers when the reach is short: the robot must get
    /// within `reach` of its target box, and ORCA keeps it this far away.
    fn box_clearance(&self) -> f32 {
        self.params.clearance.min(0.4 * self.params.reach)
    }

    /// The filter's margin to boxes and walls on this step: [`Self::box_clearance`], but
    /// no more than greedy-ORCA's own clearance while no observed peer is within
    /// [`ALONE_RADII`] radii. A wider berth around boxes is there for when a peer can
    /// squeeze the robot against one; alone, it only slows the robot between machines
    /// (robot-poor setups: 2.8_1 23.5 -> 24.3 parts on the tuning seeds 7-8, 5.10_2 54.2 ->
    /// 55.0, 30.6_1's contacts unchanged; at 25 mm whatever the peers, 30.6_1's contacts
    /// doubled). docs/RESULTS.md 7.7. A no-op for greedy-ORCA, whose clearance is that.
    fn box_clearance_among(&self, peers: &[f32]) -> f32 {
        let near = ALONE_RADII * self.params.greedy.robot_radius;
        let alone = peers
            .chunks_exact(3)
            .all(|q| q[0] * q[0] + q[1] * q[1] >= near * near);
        if alone {
            self.box_clearance().min(GREEDY_ORCA_CLEARANCE)
        } else {
            self.box_clearance()
        }
    }

    /// `n` control steps passed without a call (a real-time robot that missed states):
    /// the machine clock counts them ([`MachineClock::skip`]).
    pub fn skip_steps(&mut self, n: u32) {
        self.clock.skip(n);
    }

    /// Greedy's preferred velocity: [`Self::preferred_towards`] the [`greedy_target`] box.
    pub fn greedy_preferred(
        &self,
        own: &[f32],
        machines: &[f32],
        storages: &[f32],
        peers: &[f32],
    ) -> [f32; 2] {
        let t = greedy_target(own, machines, storages, peers, &self.params.greedy);
        self.preferred_or_make_room(t, own, machines, storages)
    }

    /// A target action's preferred velocity (`crate::targets`): [`Self::preferred_towards`]
    /// the box it names on this row; zero for "stay" or a box that does not exist.
    pub fn target_preferred(
        &mut self,
        action: u8,
        own: &[f32],
        machines: &[f32],
        storages: &[f32],
        peers: &[f32],
    ) -> [f32; 2] {
        self.clock.update(own, machines, crate::MACHINE_DIM);
        let t = targets::target_kept(
            action,
            own,
            machines,
            storages,
            peers,
            &self.params.greedy,
            targets::PlannerMemory {
                storage: &mut self.storage_memory,
                ready_in: self.clock.ready_in(),
            },
        );
        let pref = self.preferred_or_make_room(t, own, machines, storages);
        self.note_progress(own, machines, storages, pref);
        pref
    }

    /// Once per step, after planning `pref`: count the steps the robot has not moved
    /// although it wanted to, at a box, and start a detour ([`crate::detour`]) after
    /// [`STUCK_STEPS`] of them.
    fn note_progress(&mut self, own: &[f32], machines: &[f32], storages: &[f32], pref: [f32; 2]) {
        let g = &self.params.greedy;
        let (r, k) = (g.robot_radius, g.k_speed);
        let pos = [own[0], own[1]];
        // a jump of more than two full steps is a reset or a teleport, not progress
        let moved = self
            .planned_from
            .map(|q| norm([pos[0] - q[0], pos[1] - q[1]]))
            .filter(|&d| d <= 2.0 * k * g.dt);
        self.planned_from = Some(pos);
        // stuck *at a box*: a robot held up by peers waits for them instead
        let at_box = || {
            let reach = r + self.box_clearance() + STUCK_BOX_RADII * r;
            observed_boxes(machines, storages, g)
                .any(|(c, h)| crate::geom::box_distance(c, h, [0.0, 0.0]) < reach)
        };
        let wanted = pref[0].is_finite() && pref[1].is_finite() && norm(pref) > 0.5 * k;
        if moved.is_some_and(|d| d < 0.1 * k * g.dt) && wanted && at_box() {
            self.stuck_steps += 1;
        } else {
            self.stuck_steps = 0;
        }
        if self.stuck_steps >= STUCK_STEPS {
            self.stuck_steps = 0;
            self.detour_left = DETOUR_STEPS;
        } else {
            self.detour_left = self.detour_left.saturating_sub(1);
        }
    }

    /// [`Self::preferred_towards`] `target`. With no target: out of an obstacle's margin
    /// first ([`Self::keep_off`]), else [`Self::make_room`]. The order matters in real
    /// time: backing out from a storage next to a wall, ORCA stops a robot at the wall's
    /// margin, a late command carries it on into contact, and make-room alone kept it
    /// pressed there for a whole main-job run.
    fn preferred_or_make_room(
        &self,
        target: Option<Target>,
        own: &[f32],
        machines: &[f32],
        storages: &[f32],
    ) -> [f32; 2] {
        match target {
            None => self
                .keep_off(own, machines, storages)
                .or_else(|| self.make_room(storages))
                .unwrap_or([0.0, 0.0]),
            t => self.preferred_towards(t, own, machines, storages),
        }
    }

    /// Velocity straight away from the nearest wall or box while the robot's centre is
    /// closer to it than ORCA's obstacle margin (robot radius + box clearance), stopping
    /// at the margin; None when nothing is that close. For a robot with nowhere to go:
    /// ORCA only forbids moving *into* an obstacle, so a robot at rest inside the margin
    /// stays where it is; in a real-time fleet one that a late command had carried to
    /// touching a wall stayed touching it for the rest of the run (135 contact steps in
    /// about one main-job run of ten; never offline, where ORCA's stop is exact).
    pub fn keep_off(&self, own: &[f32], machines: &[f32], storages: &[f32]) -> Option<[f32; 2]> {
        let p = &self.params;
        let g = &p.greedy;
        let margin = g.robot_radius + self.box_clearance();
        // (centre-to-surface distance, unit direction away from the surface)
        let mut nearest: Option<(f32, [f32; 2])> = None;
        let mut consider = |d: f32, away: [f32; 2]| {
            if d < margin && nearest.is_none_or(|(b, _)| d < b) {
                nearest = Some((d, away));
            }
        };
        let (x, y) = (own[0], own[1]);
        consider(p.room_half - x, [-1.0, 0.0]);
        consider(p.room_half + x, [1.0, 0.0]);
        consider(p.room_half - y, [0.0, -1.0]);
        consider(p.room_half + y, [0.0, 1.0]);
        for (c, h) in observed_boxes(machines, storages, g) {
            let q = nearest_on_box(c, h, [0.0, 0.0]);
            let n = norm(q);
            // n ~ 0: the centre is on the box; the contact physics pushes it out first.
            if n > 1e-6 {
                consider(n, [-q[0] / n, -q[1] / n]);
            }
        }
        let (d, away) = nearest?;
        let speed = ((margin - d) / g.dt).min(g.k_speed);
        Some([away[0] * speed, away[1] * speed])
    }

    /// Velocity straight away from the nearest storage box while closer to it than
    /// `make_room` (at most K_speed, stopping at that distance); None when no storage box
    /// is that close (or the robot's centre is on one: no direction to back out along).
    pub fn make_room(&self, storages: &[f32]) -> Option<[f32; 2]> {
        let p = &self.params;
        let g = &p.greedy;
        if p.make_room <= 0.0 {
            return None;
        }
        let mut nearest: Option<([f32; 2], f32)> = None;
        for s in storages.chunks_exact(2) {
            let c = [s[0], s[1]];
            let d = crate::geom::box_distance(c, g.storage_half, [0.0, 0.0]);
            if d < p.make_room && nearest.is_none_or(|(_, b)| d < b) {
                nearest = Some((nearest_on_box(c, g.storage_half, [0.0, 0.0]), d));
            }
        }
        let (q, d) = nearest?;
        let n = norm(q);
        if n < 1e-6 {
            return None;
        }
        let speed = ((p.make_room - d) / g.dt).min(g.k_speed);
        Some([-q[0] / n * speed, -q[1] / n * speed])
    }

    /// Straight for a point just inside reach of `target`, at most K_speed, around any box
    /// in the way ([`crate::detour`]); zero with no target or once there.
    pub fn preferred_towards(
        &self,
        target: Option<Target>,
        own: &[f32],
        machines: &[f32],
        storages: &[f32],
    ) -> [f32; 2] {
        let p = &self.params;
        let g = &p.greedy;
        let (r, k, dt) = (g.robot_radius, g.k_speed, g.dt);
        let Some(t) = target else {
            return [0.0, 0.0];
        };
        let q = nearest_on_box(t.rel, t.half, [0.0, 0.0]);
        let d = norm(q);
        // Stop between the box clearance ORCA keeps and the reach: close enough to pick
        // or place, not so close that ORCA holds the robot off.
        let stand_off = r + 0.5 * (self.box_clearance() + p.reach);
        // Closer than the clearance ORCA keeps (a peer pushed it in, or a late command in
        // real time carried it past its stop): back out to the stand-off instead of
        // resting against the box, where every waiting step would count as a contact.
        // Between the clearance and the stand-off: stay.
        let inner = r + self.box_clearance();
        if (inner..=stand_off).contains(&d) || d < 1e-6 {
            // d ~ 0: the centre is on or in the box, no direction to back out along;
            // the contact physics pushes it out first.
            return [0.0, 0.0];
        }
        if p.detour && self.detour_left > 0 && d > stand_off {
            // the stand-off point is outside the target's grown box, so only other boxes
            // can be in the way
            let goal = crate::detour::Goal {
                point: [q[0] * (d - stand_off) / d, q[1] * (d - stand_off) / d],
                target: (t.rel, t.half),
                stand_off,
            };
            let boxes: Vec<_> = observed_boxes(machines, storages, g).collect();
            let w =
                crate::detour::waypoint(goal, &boxes, inner, r, ([own[0], own[1]], p.room_half));
            if w != goal.point {
                let n = norm(w);
                return [w[0] / n * k, w[1] / n * k];
            }
        }
        // negative inside `inner`: away from the box
        let go = (d - stand_off) / d;
        let v = [q[0] * go / dt, q[1] * go / dt];
        let s = norm(v);
        if s > k {
            [v[0] * k / s, v[1] * k / s]
        } else {
            v
        }
    }

    /// ORCA as a safety filter: the velocity nearest to `pref` (m/s) that avoids the
    /// observed peers, boxes and walls over the horizons. Call once per period (it records
    /// the observation to estimate velocities next time).
    pub fn filter(
        &mut self,
        own: &[f32],
        machines: &[f32],
        storages: &[f32],
        peers: &[f32],
        pref: [f32; 2],
    ) -> [f32; 2] {
        let p = self.params;
        let g = &p.greedy;
        let (r, k, dt) = (g.robot_radius, g.k_speed, g.dt);
        let pos = [own[0], own[1]];
        let box_clearance = self.box_clearance_among(peers);
        // A jump of more than two full steps is a reset or a teleport, not motion.
        let max_jump = 2.0 * k * dt;
        let vel_of = |now: [f32; 2], prev: [f32; 2]| {
            let d = [now[0] - prev[0], now[1] - prev[1]];
            if norm(d) <= max_jump {
                [d[0] / dt, d[1] / dt]
            } else {
                [0.0, 0.0]
            }
        };
        let own_vel = self.prev_own.map_or([0.0, 0.0], |q| vel_of(pos, q));
        self.peers_now.clear();
        self.peers_now.extend(
            peers
                .chunks_exact(3)
                .map(|q| [pos[0] + q[0], pos[1] + q[1]]),
        );
        let pref = if pref[0].is_finite() && pref[1].is_finite() {
            pref
        } else {
            [0.0, 0.0]
        };

        // Each robot's radius carries half its speed-dependent clearance, so a pair keeps
        // the mean of the two (dodgy_2d sums the radii).
        let radius_at = |v: [f32; 2]| r + 0.5 * p.clearance_at(norm(v));
        let me = Agent {
            position: Vec2::ZERO,
            velocity: Vec2::from(own_vel),
            radius: radius_at(own_vel),
            avoidance_responsibility: 1.0,
        };
        // Nearest peers first; each gets the velocity of the previous peer nearest to it.
        let mut near: Vec<(f32, usize)> = peers
            .chunks_exact(3)
            .enumerate()
            .map(|(i, q)| (q[0] * q[0] + q[1] * q[1], i))
            .collect();
        let keep = p.max_neighbours.min(near.len());
        if keep < near.len() {
            near.select_nth_unstable_by(keep, |a, b| a.0.total_cmp(&b.0));
            near.truncate(keep);
        }
        let neighbours: Vec<Cow<Agent>> = near
            .iter()
            .map(|&(_, i)| {
                let now = self.peers_now[i];
                let v = self
                    .matched_prev(i, now, max_jump)
                    .map_or([0.0, 0.0], |q| vel_of(now, q));
                Cow::Owned(Agent {
                    position: Vec2::new(peers[i * 3], peers[i * 3 + 1]),
                    velocity: Vec2::from(v),
                    radius: radius_at(v),
                    avoidance_responsibility: 1.0,
                })
            })
            .collect();

        // Boxes (counter-clockwise: solid inside) within reach of the obstacle horizon,
        // and the room (clockwise: keeps the robot in).
        let horizon = k * p.obstacle_time_horizon + r + box_clearance;
        let mut obstacles: Vec<Cow<Obstacle>> = Vec::new();
        for (c, h) in observed_boxes(machines, storages, g) {
            if crate::geom::box_distance(c, h, [0.0, 0.0]) <= horizon {
                obstacles.push(Cow::Owned(Obstacle::Closed {
                    vertices: vec![
                        Vec2::new(c[0] - h[0], c[1] - h[1]),
                        Vec2::new(c[0] + h[0], c[1] - h[1]),
                        Vec2::new(c[0] + h[0], c[1] + h[1]),
                        Vec2::new(c[0] - h[0], c[1] + h[1]),
                    ],
                }));
            }
        }
        let (lo, hi) = (
            [-p.room_half - pos[0], -p.room_half - pos[1]],
            [p.room_half - pos[0], p.room_half - pos[1]],
        );
        obstacles.push(Cow::Owned(Obstacle::Closed {
            vertices: vec![
                Vec2::new(lo[0], lo[1]),
                Vec2::new(lo[0], hi[1]),
                Vec2::new(hi[0], hi[1]),
                Vec2::new(hi[0], lo[1]),
            ],
        }));

        let v = me.compute_avoiding_velocity(
            &neighbours,
            &obstacles,
            Vec2::from(pref),
            k,
            dt,
            &AvoidanceOptions {
                obstacle_margin: r + box_clearance,
                time_horizon: p.time_horizon,
                obstacle_time_horizon: p.obstacle_time_horizon,
            },
        );

        self.prev_own = Some(pos);
        std::mem::swap(&mut self.prev_peers, &mut self.peers_now);
        if v.is_finite() {
            [v.x, v.y]
        } else {
            [0.0, 0.0]
        }
    }

    /// Previous position of peer `i`: same index if it moved at most `max_jump` (the
    /// simulator and robot_node keep peer order while the fleet is unchanged), else the
    /// nearest previous peer within `max_jump`.
    fn matched_prev(&self, i: usize, now: [f32; 2], max_jump: f32) -> Option<[f32; 2]> {
        let d = |q: &[f32; 2]| norm([now[0] - q[0], now[1] - q[1]]);
        if let Some(q) = self.prev_peers.get(i).filter(|q| d(q) <= max_jump) {
            return Some(*q);
        }
        self.prev_peers
            .iter()
            .map(|q| (d(q), *q))
            .filter(|(dist, _)| *dist <= max_jump)
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, q)| q)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> OrcaParams {
        OrcaParams::new(GreedyParams::default(), 2.3, 0.08)
    }

    #[test]
    fn heads_for_the_ready_machine_when_alone() {
        let mut c = GreedyOrca::new(params()).unwrap();
        let v = c.velocity(&[0.0, 0.0, 0.0], &[0.8, 0.0, 1.0], &[-0.8, 0.5], &[]);
        assert!(v[0] > 0.45 && v[1].abs() < 0.05, "{v:?}");
        // With a part: the storage, up and to the left.
        let v = c.velocity(&[0.0, 0.0, 1.0], &[0.8, 0.0, 1.0], &[-0.8, 0.5], &[]);
        assert!(v[0] < -0.3 && v[1] > 0.1, "{v:?}");
    }

    #[test]
    fn yields_to_a_peer_coming_head_on() {
        let mut c = GreedyOrca::new(params()).unwrap();
        // Target straight right; a peer 0.3 m right, last seen 0.05 m further (so coming
        // at 0.5 m/s) and I moved 0.05 m right (0.5 m/s).
        let m = [1.0, 0.0, 1.0];
        let s = [-1.0, 0.9];
        c.velocity(&[-0.05, 0.0, 0.0], &[1.05, 0.0, 1.0], &s, &[0.4, 0.0, 0.0]);
        let v = c.velocity(&[0.0, 0.0, 0.0], &m, &s, &[0.3, 0.0, 1.0]);
        assert!(
            v[1].abs() > 0.1 || v[0] < 0.2,
            "should swerve or slow: {v:?}"
        );
    }

    /// At the stand-off the robot waits; pushed inside the box clearance it backs out
    /// (away from the box, back to the stand-off in one step), so a robot waiting at a
    /// machine does not rest in contact with it.
    #[test]
    fn backs_out_when_closer_than_the_box_clearance() {
        let c = GreedyOrca::new(params()).unwrap();
        let half = [0.12, 0.12];
        let stand_off = 0.08 + 0.5 * (c.box_clearance() + 0.08);
        // machine to the right, its surface `gap` beyond the robot centre
        let at = |gap: f32| {
            c.preferred_towards(
                Some(Target {
                    rel: [gap + half[0], 0.0],
                    half,
                }),
                &[0.0, 0.0, 0.0],
                &[],
                &[],
            )
        };
        assert_eq!(at(stand_off), [0.0, 0.0]);
        assert_eq!(at(0.08 + c.box_clearance() + 0.001), [0.0, 0.0]);
        let v = at(0.085); // 5 mm from touching
        assert!(v[0] < 0.0 && v[1].abs() < 1e-6, "{v:?}");
        assert!((v[0] * 0.1 + (stand_off - 0.085)).abs() < 1e-5, "{v:?}");
        let far = at(1.0);
        assert!(far[0] > 0.49, "{far:?}");
    }

    /// A carrier driving at full speed straight for its storage, 0.12 m from touching it:
    /// greedy-ORCA's 0.3 s obstacle horizon already brakes it there, the policy filter's
    /// 0.15 s lets it keep full speed into the reach, where it places.
    #[test]
    fn the_policy_filter_brakes_later_for_a_box_ahead() {
        let g = GreedyParams::default();
        let gap = 0.12;
        let ahead = g.robot_radius + g.storage_half[0] + gap;
        let speed_towards = |p: OrcaParams| {
            let mut c = GreedyOrca::new(p).unwrap();
            let step = g.k_speed * g.dt;
            // one step earlier, one step farther: the filter estimates full speed
            c.filter(
                &[-0.5, 0.0, 1.0],
                &[],
                &[ahead + step, 0.0],
                &[],
                [g.k_speed, 0.0],
            );
            c.filter(
                &[-0.5 + step, 0.0, 1.0],
                &[],
                &[ahead, 0.0],
                &[],
                [g.k_speed, 0.0],
            )[0]
        };
        let script = speed_towards(params());
        let filter =
            speed_towards(params().for_policy_filter(FILTER_CLEARANCE, FILTER_REST_CLEARANCE));
        assert_eq!(params().obstacle_time_horizon, OBSTACLE_HORIZON);
        assert!(script < 0.8 * g.k_speed, "greedy-ORCA brakes: {script}");
        assert!(
            filter > 0.99 * g.k_speed,
            "the filter does not yet: {filter}"
        );
        // and the filter still brakes once the box is within its horizon
        let mut c =
            GreedyOrca::new(params().for_policy_filter(FILTER_CLEARANCE, FILTER_REST_CLEARANCE))
                .unwrap();
        let near = g.robot_radius + g.storage_half[0] + 0.06;
        let v = c.filter(&[0.0, 0.0, 1.0], &[], &[near, 0.0], &[], [g.k_speed, 0.0]);
        assert!(v[0] < 0.8 * g.k_speed, "{v:?}");
    }

    /// A carrier beside the machine it picked from, its storage straight through that
    /// machine: ORCA holds it at the face. After [`STUCK_STEPS`] steps without moving it
    /// heads round a corner of the box ([`crate::detour`]); with `detour` off it stays.
    #[test]
    fn a_robot_stuck_against_a_box_goes_round_it() {
        let half = GreedyParams::default().machine_half;
        // machine face 0.1 m right of the robot centre (robot radius 0.08), storage beyond
        let machines = [0.1 + half[0], 0.0, 0.0];
        let storages = [0.9, 0.0];
        let own = [-0.3, 0.1, 1.0];
        for detour in [true, false] {
            let mut c = GreedyOrca::new(OrcaParams { detour, ..params() }).unwrap();
            let mut sideways = Vec::new();
            for _ in 0..STUCK_STEPS + 2 {
                // the robot does not move: same observation every step
                c.velocity(&own, &machines, &storages, &[]);
                let pref = c.greedy_preferred(&own, &machines, &storages, &[]);
                sideways.push(pref[1].abs() / norm(pref));
            }
            assert!(sideways[0] < 1e-3, "straight at first: {sideways:?}");
            let last = *sideways.last().unwrap();
            if detour {
                assert!(last > 0.3, "round the box once stuck: {sideways:?}");
            } else {
                assert!(last < 1e-3, "detour off: {sideways:?}");
            }
        }
    }

    #[test]
    fn a_carrier_below_a_gap_too_narrow_gets_to_its_storage() {
        // 2.8_1, seed 0, episode 16 (examples/stuck_carriers.rs): the carrier stood at the
        // mouth of a gap between two machines, narrower than two margins, for 180 steps.
        // Driven by its own commands, it now reaches its stand-off at the storage.
        let mut c = GreedyOrca::new(params()).unwrap();
        let mut p = [0.175f32, -0.263];
        let machines = [[0.390f32, -0.099], [-0.050, -0.136]];
        let storage = [0.464f32, 0.546];
        let dt = c.params.greedy.dt;
        for _ in 0..60 {
            let own = [p[0], p[1], 1.0];
            let m: Vec<f32> = machines
                .iter()
                .flat_map(|q| [q[0] - p[0], q[1] - p[1], 0.0])
                .collect();
            let v = c.velocity(&own, &m, &[storage[0] - p[0], storage[1] - p[1]], &[]);
            p = [p[0] + v[0] * dt, p[1] + v[1] * dt];
        }
        let half = c.params.greedy.storage_half;
        let d = crate::geom::box_distance([storage[0] - p[0], storage[1] - p[1]], half, [0.0, 0.0]);
        assert!(d < 0.14, "{d} m from the storage, at {p:?}");
    }

    #[test]
    fn refuses_bad_parameters() {
        let mut p = params();
        p.greedy.dt = 0.0;
        assert!(GreedyOrca::new(p).unwrap_err().contains("dt"));
        let mut p = params();
        p.greedy.machine_half = [f32::NAN, 0.1];
        assert!(GreedyOrca::new(p).is_err());
        let mut p = params();
        p.make_room = -0.1;
        assert!(GreedyOrca::new(p).unwrap_err().contains("make_room"));
        let p = params().with_clearance(0.03).with_rest_clearance(0.04);
        assert!(GreedyOrca::new(p).unwrap_err().contains("rest_clearance"));
    }

    #[test]
    fn clearance_grows_with_speed_from_rest_to_full() {
        let p = params().for_policy(Some(FILTER_CLEARANCE));
        let k = p.greedy.k_speed;
        assert_eq!(p.clearance_at(0.0), FILTER_REST_CLEARANCE);
        assert_eq!(p.clearance_at(k), FILTER_CLEARANCE);
        assert_eq!(p.clearance_at(2.0 * k), FILTER_CLEARANCE);
        let mid = p.clearance_at(0.5 * k);
        assert!((mid - 0.5 * (FILTER_REST_CLEARANCE + FILTER_CLEARANCE)).abs() < 1e-6);
        // A filter clearance below the rest default is kept fixed.
        let low = params().for_policy(Some(0.02));
        assert_eq!((low.clearance_at(0.0), low.clearance_at(k)), (0.02, 0.02));
        // greedy-ORCA's own clearance is fixed, and so is a target policy's planner
        // without the filter (greedy-ORCA's clearance, the policy's make-room distance).
        assert_eq!(params().clearance_at(0.0), params().clearance_at(k));
        let unfiltered = params().for_policy(None);
        assert_eq!(unfiltered.clearance_at(0.0), GREEDY_ORCA_CLEARANCE);
        assert_eq!(unfiltered.clearance_at(k), GREEDY_ORCA_CLEARANCE);
        let r = unfiltered.greedy.robot_radius;
        assert!((unfiltered.make_room - POLICY_MAKE_ROOM_RADII * r).abs() < 1e-6);
        // Both clearances given (sweeps): the deployed pair is `for_policy`'s; a rest
        // clearance above the full-speed one is cut to it.
        assert_eq!(
            params().for_policy_filter(FILTER_CLEARANCE, FILTER_REST_CLEARANCE),
            params().for_policy(Some(FILTER_CLEARANCE))
        );
        let swept = params().for_policy_filter(0.04, 0.025);
        assert_eq!(
            (swept.clearance_at(0.0), swept.clearance_at(k)),
            (0.025, 0.04)
        );
        let cut = params().for_policy_filter(0.03, 0.035);
        assert_eq!((cut.clearance_at(0.0), cut.clearance_at(k)), (0.03, 0.03));
    }

    /// Alone, the filter keeps greedy-ORCA's clearance to boxes; with a peer near, its own.
    #[test]
    fn wider_box_margin_only_with_a_peer_near() {
        let c = GreedyOrca::new(params().for_policy(Some(FILTER_CLEARANCE))).unwrap();
        let r = c.params.greedy.robot_radius;
        let wide = c.box_clearance();
        assert!(wide > GREEDY_ORCA_CLEARANCE, "{wide}");
        assert_eq!(c.box_clearance_among(&[]), GREEDY_ORCA_CLEARANCE);
        let far = [ALONE_RADII * r + 0.01, 0.0, 0.0];
        assert_eq!(c.box_clearance_among(&far), GREEDY_ORCA_CLEARANCE);
        let near = [ALONE_RADII * r - 0.01, 0.0, 0.0];
        assert_eq!(c.box_clearance_among(&near), wide);
        // greedy-ORCA's own margin does not change.
        let script = GreedyOrca::new(params()).unwrap();
        assert_eq!(
            script.box_clearance_among(&near),
            script.box_clearance_among(&[])
        );
    }

    /// Two robots at rest 35 mm apart (surface to surface): inside a fixed 40 mm clearance
    /// the filter pushes them apart; with 30 mm at rest they may stand there, as in a queue.
    #[test]
    fn robots_at_rest_may_stand_closer_than_moving_ones() {
        let r = params().greedy.robot_radius;
        let peer = [2.0 * r + 0.035, 0.0, 0.0];
        let own = [0.0, 0.0, 0.0];
        let mut fixed = GreedyOrca::new(params().with_clearance(FILTER_CLEARANCE)).unwrap();
        let v = fixed.filter(&own, &[], &[], &peer, [0.0, 0.0]);
        assert!(v[0] < -0.01, "fixed 40 mm backs off: {v:?}");
        let mut adaptive = GreedyOrca::new(params().for_policy(Some(FILTER_CLEARANCE))).unwrap();
        let v = adaptive.filter(&own, &[], &[], &peer, [0.0, 0.0]);
        assert!(norm(v) < 1e-4, "30 mm at rest stays: {v:?}");
    }

    /// An idle robot (no ready machine, no part) next to a storage box backs straight out,
    /// at most K_speed, and stops at `make_room` from the box; with `make_room` 0 it stays.
    #[test]
    fn idle_robot_makes_room_at_a_storage() {
        let c = GreedyOrca::new(params()).unwrap();
        let busy = [0.8, 0.0, 0.0];
        // storage half size [0.15, 0.08]; its centre 0.1 m above the robot, so its
        // surface is 0.02 m away
        let half = params().greedy.storage_half;
        let near = [0.0, 0.1];
        let v = c.greedy_preferred(&[0.0, 0.0, 0.0], &busy, &near, &[]);
        assert!(v[1] < -0.49 && v[0].abs() < 1e-6, "{v:?}");
        // just inside make_room: one step's worth of the remaining gap, no more
        let m = params().make_room;
        let d = m - 0.01;
        let v = c.greedy_preferred(&[0.0, 0.0, 0.0], &busy, &[0.0, half[1] + d], &[]);
        assert!((v[1] + 0.01 / 0.1).abs() < 1e-4, "{v:?}");
        // beyond it: stay
        let far = [0.0, half[1] + m + 0.01];
        assert_eq!(
            c.greedy_preferred(&[0.0, 0.0, 0.0], &busy, &far, &[]),
            [0.0, 0.0]
        );
        // off: no berth, only keep_off's (out of the box's contact margin)
        let mut p = params();
        p.make_room = 0.0;
        let off = GreedyOrca::new(p).unwrap();
        let v = off.greedy_preferred(&[0.0, 0.0, 0.0], &busy, &near, &[]);
        assert!(v[1] < 0.0 && v[0].abs() < 1e-6, "{v:?}");
        let margin = p.greedy.robot_radius + p.clearance.min(0.4 * p.reach);
        let clear = [0.0, half[1] + margin + 0.01];
        assert_eq!(
            off.greedy_preferred(&[0.0, 0.0, 0.0], &busy, &clear, &[]),
            [0.0, 0.0]
        );
    }

    /// Inside a wall's margin, getting out of it comes before making room: next to the top
    /// wall, backing away from a storage below would press up into the wall; the robot
    /// moves down out of the margin instead, and makes room once outside it.
    #[test]
    fn out_of_a_wall_margin_before_making_room() {
        let p = params();
        let c = GreedyOrca::new(p).unwrap();
        let r = p.greedy.robot_radius;
        let margin = r + p.clearance.min(0.4 * p.reach);
        let busy_far = [-0.8, -0.8, 0.0];
        let storage = [0.0, -0.3];
        let open = c.greedy_preferred(&[0.0, 0.0, 0.0], &busy_far, &storage, &[]);
        assert!(open[1] > 0.0, "make room: up, {open:?}");
        let inside = p.room_half - r - 0.003;
        let v = c.greedy_preferred(&[0.0, inside, 0.0], &busy_far, &storage, &[]);
        assert!(v[1] < 0.0, "out of the wall's margin: down, {v:?}");
        let outside = p.room_half - margin - 0.001;
        let v = c.greedy_preferred(&[0.0, outside, 0.0], &busy_far, &storage, &[]);
        assert!(v[1] > 0.0, "outside it, make room again: {v:?}");
    }

    /// A robot with nowhere to go that rests inside ORCA's obstacle margin of a wall or a
    /// box it is not heading for backs straight out to the margin, no farther; ORCA alone
    /// would let it rest there (it only forbids moving in).
    #[test]
    fn a_robot_with_nowhere_to_go_keeps_off_walls_and_boxes() {
        let p = params();
        let mut c = GreedyOrca::new(p).unwrap();
        let r = p.greedy.robot_radius;
        let margin = r + p.clearance.min(0.4 * p.reach);
        let busy_far = [-0.8, 0.0, 0.0];
        // 4 mm from the right wall (room half 1.15): straight left, the gap in one step.
        let x = p.room_half - r - 0.004;
        let v = c.greedy_preferred(&[x, 0.0, 0.0], &busy_far, &[], &[]);
        let want = (margin - (r + 0.004)) / p.greedy.dt;
        assert!((v[0] + want).abs() < 1e-4 && v[1].abs() < 1e-6, "{v:?}");
        // Beyond the margin it stays.
        let x = p.room_half - margin - 0.001;
        assert_eq!(
            c.greedy_preferred(&[x, 0.0, 0.0], &busy_far, &[], &[]),
            [0.0, 0.0]
        );
        // A busy machine 3 mm below (greedy has no task): up, away from it.
        let h = p.greedy.machine_half;
        let below = [0.0, -(h[1] + r + 0.003), 0.0];
        let v = c.greedy_preferred(&[0.0, 0.0, 0.0], &below, &[], &[]);
        assert!(v[1] > 0.0 && v[0].abs() < 1e-6, "{v:?}");
        // The right wall 1 mm away as well: the nearer surface wins.
        let x = p.room_half - r - 0.001;
        let v = c.greedy_preferred(&[x, 0.0, 0.0], &below, &[], &[]);
        assert!(v[0] < 0.0 && v[1].abs() < 1e-6, "{v:?}");
        // A policy asking to stay keeps off the same way.
        let x = p.room_half - r - 0.004;
        let v = c.target_preferred(0, &[x, 0.0, 0.0], &busy_far, &[], &[]);
        assert!(v[0] < 0.0, "{v:?}");
    }

    /// Only a robot with nowhere to go makes room: one with a task heads for it, and a
    /// target policy's "stay" makes room like greedy's idle robot.
    #[test]
    fn make_room_only_without_a_target() {
        let mut c = GreedyOrca::new(params()).unwrap();
        let near = [0.0, 0.1];
        // a ready machine to the right: greedy heads there, storage or not
        let v = c.greedy_preferred(&[0.0, 0.0, 0.0], &[0.8, 0.0, 1.0], &near, &[]);
        assert!(v[0] > 0.49, "{v:?}");
        // with a part: towards the storage, even from inside make_room
        let mid = [0.0, 0.3];
        let v = c.greedy_preferred(&[0.0, 0.0, 1.0], &[0.8, 0.0, 0.0], &mid, &[]);
        assert!(v[1] > 0.49, "{v:?}");
        let v = c.greedy_preferred(&[0.0, 0.0, 0.0], &[0.8, 0.0, 0.0], &mid, &[]);
        assert!(v[1] < -0.49, "{v:?}");
        let stay = c.target_preferred(0, &[0.0, 0.0, 0.0], &[0.8, 0.0, 1.0], &near, &[]);
        assert!(stay[1] < -0.49, "{stay:?}");
    }
}
