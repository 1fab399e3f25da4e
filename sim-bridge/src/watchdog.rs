//! sim_bridge's stages for the start-up/stall watchdog of the shared runtime
//! ([`ros::watchdog`]): a bridge whose start-up or step loop hangs exits with
//! [`EXIT_WATCHDOG`] naming the stage, and `tending fleet` restarts it (the robots re-pin
//! to the new bridge's writers once the old ones are stale, ADR 0004).

pub use ros::watchdog::{Limits, Stuck, EXIT_WATCHDOG};

/// The watchdog over sim_bridge's stages.
pub type Watchdog = ros::watchdog::Watchdog<Stage>;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Stage {
    /// Building the simulator.
    Core = 0,
    /// Creating the DDS context.
    Context = 1,
    /// Creating the ROS 2 node and its spinner.
    Node = 2,
    /// Creating the fixed publishers and subscriptions (/clock, markers, commands, cmd_vel).
    Endpoints = 3,
    /// Step loop running (heartbeat every iteration).
    Running = 4,
    /// Step loop running, creating writers or readers for entities that appeared.
    EntityEndpoints = 5,
    /// Step loop left (shutting down): not watched.
    Done = 6,
}

impl ros::watchdog::Stage for Stage {
    const FIRST: Self = Stage::Core;

    fn to_u8(self) -> u8 {
        self as u8
    }

    fn from_u8(x: u8) -> Stage {
        match x {
            0 => Stage::Core,
            1 => Stage::Context,
            2 => Stage::Node,
            3 => Stage::Endpoints,
            4 => Stage::Running,
            5 => Stage::EntityEndpoints,
            _ => Stage::Done,
        }
    }

    fn is_startup(self) -> bool {
        (self as u8) < (Stage::Running as u8)
    }

    fn is_done(self) -> bool {
        self == Stage::Done
    }

    fn describe(self) -> &'static str {
        match self {
            Stage::Core => "building the simulator",
            Stage::Context => "creating the DDS context",
            Stage::Node => "creating the ROS 2 node",
            Stage::Endpoints => "creating the bridge's publishers and subscriptions",
            Stage::Running => "in the step loop",
            Stage::EntityEndpoints => "creating writers or readers for new entities",
            Stage::Done => "in shutdown",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ros::watchdog::Stage as _;

    #[test]
    fn every_stage_round_trips_and_only_the_loop_stages_are_past_startup() {
        for x in 0..7u8 {
            let s = Stage::from_u8(x);
            assert_eq!(s.to_u8(), x);
            assert_eq!(s.is_startup(), x < 4, "{s:?}");
        }
        assert_eq!(Stage::from_u8(99), Stage::Done);
    }
}
