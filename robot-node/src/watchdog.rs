//! robot_node's stages for the start-up/stall watchdog of the shared runtime
//! ([`ros::watchdog`]): the node records where it is, the watchdog names it when it
//! exits the process with [`EXIT_WATCHDOG`] so that `tending fleet` restarts it.

pub use ros::watchdog::{Limits, Stuck, EXIT_WATCHDOG};

/// The watchdog over robot_node's stages.
pub type Watchdog = ros::watchdog::Watchdog<NodeStage>;

ros::watchdog_stages! {
    /// Where the main path is.
    pub enum NodeStage {
        startup {
        /// Loading the controller(s).
        Controller => "loading the controller",
        /// Creating the DDS context.
        Context => "creating the DDS context",
        /// Creating the ROS 2 node and its spinner.
        Node => "creating the ROS 2 node",
        /// Creating the cmd_vel writer(s).
        Writers => "creating the cmd_vel writer(s)",
        /// Creating the start-up subscriptions (own topics, /clock).
        Subscriptions => "creating the start-up subscriptions",
        }
        running {
        /// Event loop running (heartbeat every iteration).
        Running => "in the control loop",
        /// Event loop running, creating a subscription to a discovered topic.
        DiscoveredSubscription => "creating a subscription to a discovered topic",
        }
        /// Event loop left (shutting down): not watched.
        done Done => "in shutdown",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_message_names_the_stage() {
        let v = ros::watchdog::verdict(
            NodeStage::Node,
            std::time::Duration::from_secs(12),
            std::time::Duration::from_secs(1),
            &Limits::from_secs(10.0, 10.0),
        )
        .unwrap();
        assert!(v.to_string().contains("creating the ROS 2 node"), "{v}");
        assert!(v.startup);
    }
}
