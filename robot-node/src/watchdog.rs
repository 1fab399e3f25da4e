//! robot_node's stages for the start-up/stall watchdog of the shared runtime
//! ([`ros::watchdog`]): the node records where it is, the watchdog names it when it
//! exits the process with [`EXIT_WATCHDOG`] so that `tending fleet` restarts it; and
//! [`retry`], the start-up retry loop whose every attempt counts as progress.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use tracing::warn;

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

/// Retry a DDS set-up step that can fail transiently (RustDDS reports a full internal
/// channel as a poisoned entity when many entities are created at once): 40 attempts,
/// 250 ms apart, unless stopping.
///
/// Every attempt is start-up progress for the watchdog (a retry loop is not a hang).
pub(crate) fn retry<T>(
    what: &str,
    stop: &AtomicBool,
    wd: &Watchdog,
    mut f: impl FnMut() -> anyhow::Result<T>,
) -> anyhow::Result<T> {
    let mut attempt = 1;
    loop {
        let r = f();
        wd.beat();
        match r {
            Ok(x) => return Ok(x),
            Err(e) if attempt < 40 && !stop.load(Ordering::SeqCst) => {
                if attempt == 1 {
                    warn!("{what}: {e:#} (retrying)");
                }
                attempt += 1;
                std::thread::sleep(Duration::from_millis(250));
            }
            Err(e) => return Err(e),
        }
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
