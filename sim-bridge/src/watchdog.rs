//! sim_bridge's stages for the start-up/stall watchdog of the shared runtime
//! ([`ros::watchdog`]): a bridge whose start-up or step loop hangs exits with
//! [`EXIT_WATCHDOG`] naming the stage, and `tending fleet` restarts it (the robots re-pin
//! to the new bridge's writers once the old ones are stale, ADR 0004).

pub use ros::watchdog::{Limits, Stuck, EXIT_WATCHDOG};

/// The watchdog over sim_bridge's stages.
pub type Watchdog = ros::watchdog::Watchdog<NodeStage>;

ros::watchdog_stages! {
    /// Where the bridge is.
    pub enum NodeStage {
        startup {
        Core => "building the simulator",
        Context => "creating the DDS context",
        Node => "creating the ROS 2 node",
        /// The fixed publishers and subscriptions (/clock, markers, commands, cmd_vel).
        Endpoints => "creating the bridge's publishers and subscriptions",
        }
        running {
        /// Step loop running (heartbeat every iteration).
        Running => "in the step loop",
        /// Step loop running, creating writers or readers for entities that appeared.
        EntityEndpoints => "creating writers or readers for new entities",
        }
        /// Step loop left (shutting down): not watched.
        done Done => "in shutdown",
    }
}
