//! What a robot knows about its fleet as parameters, and the one place the planner's
//! parameter sets are built from it.
//!
//! The simulator fills [`FleetParams`] from its scenario config (`learn::baselines::fleet_params`),
//! robot_node from its ROS parameters; both then take [`FleetParams::greedy_params`],
//! [`FleetParams::orca_params`] and [`FleetParams::shield_params`] from here, so an offline
//! episode and a fleet of robot nodes plan with the same numbers.

use crate::greedy::GreedyParams;
use crate::orca::OrcaParams;
use crate::shield::ShieldParams;

/// Collision distance of the default scenario, m (sim's `TaskConfig::collision_distance`):
/// the simulator counts a contact when two bodies come this close.
pub const DEFAULT_COLLISION_DISTANCE: f32 = 0.005;

/// The fleet's body sizes, speed, control period, machine timing, room and reach: everything
/// the scripted controllers, the ORCA filter and the shield know besides the observation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FleetParams {
    pub robot_radius: f32,
    /// Half extents of a machine box, m.
    pub machine_half: [f32; 2],
    /// Half extents of a storage box, m.
    pub storage_half: [f32; 2],
    /// Speed of one discrete action (and greedy-ORCA's top speed), m/s.
    pub k_speed: f32,
    /// Control period, s.
    pub dt: f32,
    /// Steps a machine takes to make a part after its last was picked.
    pub prep_steps: u32,
    /// Side of the square room, m (walls at +-room_size/2).
    pub room_size: f32,
    /// Pick/place reach beyond the robot's radius, m.
    pub reach: f32,
    /// Gap at which the simulator counts a contact, m.
    pub collision_distance: f32,
}

impl FleetParams {
    /// A fleet from greedy's parameters in a `room_size` room, reaching as far as a robot's
    /// radius, with the simulator's default contact gap (the defaults tests build on).
    pub fn from_greedy(g: &GreedyParams, room_size: f32) -> Self {
        Self {
            robot_radius: g.robot_radius,
            machine_half: g.machine_half,
            storage_half: g.storage_half,
            k_speed: g.k_speed,
            dt: g.dt,
            prep_steps: g.prep_steps,
            room_size,
            reach: g.robot_radius,
            collision_distance: DEFAULT_COLLISION_DISTANCE,
        }
    }

    /// What the greedy controller plans with.
    pub fn greedy_params(&self) -> GreedyParams {
        GreedyParams {
            robot_radius: self.robot_radius,
            machine_half: self.machine_half,
            storage_half: self.storage_half,
            k_speed: self.k_speed,
            dt: self.dt,
            prep_steps: self.prep_steps,
        }
    }

    /// Greedy-ORCA's parameters (its own defaults: [`OrcaParams::new`]); a learned policy's
    /// planner and filter derive theirs from these ([`OrcaParams::for_policy`]).
    pub fn orca_params(&self) -> OrcaParams {
        OrcaParams::new(self.greedy_params(), self.room_size, self.reach)
    }

    /// The shield's parameters. The margin is the collision distance plus 10 mm for the
    /// velocity tracker's lag behind a command.
    pub fn shield_params(&self) -> ShieldParams {
        let mut p = ShieldParams::new(
            self.robot_radius,
            self.machine_half,
            self.storage_half,
            self.k_speed,
            self.dt,
            self.room_size,
        );
        p.margin = self.collision_distance + 0.01;
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The default scenario at scale 1, as robot_node's defaults describe it.
    fn default_fleet() -> FleetParams {
        let g = GreedyParams::default();
        FleetParams::from_greedy(&g, 2.3)
    }

    #[test]
    fn builders_agree_with_the_parameter_types_own_defaults() {
        let f = default_fleet();
        assert_eq!(f.greedy_params(), GreedyParams::default());
        assert_eq!(
            f.orca_params(),
            OrcaParams::new(GreedyParams::default(), 2.3, 0.08)
        );
        // the default collision distance gives ShieldParams::new's own 15 mm margin, bit
        // for bit (robot_node used that constructor before it took FleetParams)
        let s = f.shield_params();
        assert_eq!(
            s,
            ShieldParams::new(0.08, [0.12, 0.12], [0.15, 0.08], 0.5, 0.1, 2.3)
        );
        assert_eq!(s.margin, 0.015);
    }
}
