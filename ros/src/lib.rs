//! The node runtime that `robot_node`, `sim_bridge`, `tending record`/`bag play` and
//! `ros_bench` share, so that each of them is only its own logic:
//!
//! - [`args`]: the ROS 2 command line (`--ros-args`, `-p`, `--params-file`, remaps,
//!   `ROS_DOMAIN_ID`), which ros2-client does not parse;
//! - [`node`]: DDS context on a domain, node, and the thread spinning it;
//! - [`pubsub`]: typed subscriptions and publishers with the contract's QoS profiles, and
//!   [`StampedWriter`] (samples stamped with the simulator step);
//! - [`process`]: the stop flag set by SIGINT/SIGTERM, tracing set-up;
//! - [`watchdog`]: the start-up/stall watchdog;
//! - [`security`]: DDS Security from `ROS_SECURITY_*` and `--enclave` (SROS2 enclaves).
//!
//! The wire contract itself (message types, topic names, QoS profiles, schemas) is `msgs`.

pub mod args;
pub mod node;
pub mod process;
pub mod pubsub;
pub mod security;
pub mod watchdog;

pub use node::{context, context_with, dds_err, NodeSpec, RosNode};
pub use process::{init_tracing, stop_flag};
pub use pubsub::{
    publisher, publisher_qos, stamp_key_info, subscription, subscription_qos, StampedWriter,
};
pub use security::Security;
