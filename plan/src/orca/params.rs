//! What greedy-ORCA and the ORCA filter plan with: the tuned margins and horizons (each
//! with the measurement that set it) and [`OrcaParams`].

use crate::greedy::GreedyParams;

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
/// `tending eval --margins configs/margins/greedy-orca-0.15.toml` runs the other point.
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

/// Everything [`super::GreedyOrca`] plans with.
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
    /// Once stuck ([`super::STUCK_STEPS`]), head for the corner of the box in the way instead of
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
    /// --margins`, [`crate::margins`]); chain [`Self::with_obstacle_horizon`]
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

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> OrcaParams {
        OrcaParams::new(GreedyParams::default(), 2.3, 0.08)
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
}
