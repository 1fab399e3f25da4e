//! robot_node's stages for the start-up/stall watchdog of the shared runtime
//! ([`ros::watchdog`]): the node records where it is, the watchdog names it when it
//! exits the process with [`EXIT_WATCHDOG`] so that `tending fleet` restarts it.

pub use ros::watchdog::{Limits, Stuck, EXIT_WATCHDOG};

/// The watchdog over robot_node's stages.
pub type Watchdog = ros::watchdog::Watchdog<Stage>;

/// Where the main path is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Stage {
    /// Loading the controller(s).
    Controller = 0,
    /// Creating the DDS context.
    Context = 1,
    /// Creating the ROS 2 node and its spinner.
    Node = 2,
    /// Creating the cmd_vel writer(s).
    Writers = 3,
    /// Creating the start-up subscriptions (own topics, /clock).
    Subscriptions = 4,
    /// Event loop running (heartbeat every iteration).
    Running = 5,
    /// Event loop running, creating a subscription to a discovered topic.
    DiscoveredSubscription = 6,
    /// Event loop left (shutting down): not watched.
    Done = 7,
}

impl ros::watchdog::Stage for Stage {
    const FIRST: Self = Stage::Controller;

    fn to_u8(self) -> u8 {
        self as u8
    }

    fn from_u8(x: u8) -> Stage {
        match x {
            0 => Stage::Controller,
            1 => Stage::Context,
            2 => Stage::Node,
            3 => Stage::Writers,
            4 => Stage::Subscriptions,
            5 => Stage::Running,
            6 => Stage::DiscoveredSubscription,
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
            Stage::Controller => "loading the controller",
            Stage::Context => "creating the DDS context",
            Stage::Node => "creating the ROS 2 node",
            Stage::Writers => "creating the cmd_vel writer(s)",
            Stage::Subscriptions => "creating the start-up subscriptions",
            Stage::Running => "in the control loop",
            Stage::DiscoveredSubscription => "creating a subscription to a discovered topic",
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
        for x in 0..8u8 {
            let s = Stage::from_u8(x);
            assert_eq!(s.to_u8(), x);
            assert_eq!(s.is_startup(), x < 5, "{s:?}");
        }
        assert_eq!(Stage::from_u8(200), Stage::Done);
        assert!(Stage::Done.is_done() && !Stage::Running.is_done());
    }

    #[test]
    fn the_message_names_the_stage() {
        let v = ros::watchdog::verdict(
            Stage::Node,
            std::time::Duration::from_secs(12),
            std::time::Duration::from_secs(1),
            &Limits::from_secs(10.0, 10.0),
        )
        .unwrap();
        assert!(v.to_string().contains("creating the ROS 2 node"), "{v}");
    }
}
