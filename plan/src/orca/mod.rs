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

//!
//! Three parts, one per file: [`params`] (the tuned constants and [`OrcaParams`]),
//! [`planner`] (the preferred velocity: where the robot wants to go, greedy's box or a
//! target action's, with make-room, keep-off and detours) and [`filter`] (ORCA proper:
//! the velocity nearest the preferred one that avoids peers, boxes and walls, with the
//! velocity estimates it needs).

pub mod filter;
pub mod params;
pub mod planner;

pub use params::{
    OrcaParams, ALONE_RADII, FILTER_CLEARANCE, FILTER_OBSTACLE_HORIZON, FILTER_REST_CLEARANCE,
    GREEDY_ORCA_CLEARANCE, MAKE_ROOM_RADII, OBSTACLE_HORIZON, POLICY_MAKE_ROOM_RADII,
};

use crate::greedy::GreedyParams;
use crate::machine_clock::MachineClock;
use crate::storage_queue::StorageMemory;

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

    /// `n` control steps passed without a call (a real-time robot that missed states):
    /// the machine clock counts them ([`MachineClock::skip`]).
    pub fn skip_steps(&mut self, n: u32) {
        self.clock.skip(n);
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
}
