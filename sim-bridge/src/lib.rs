//! `sim_bridge`: the tending simulator behind the ROS 2 contract (DESIGN.md).
//!
//! - [`params`]: ROS 2 command-line parameters (`ros::args` conventions);
//! - [`core`]: DDS-free logic: bodies by namespace, cmd_vel validation, spawn on first
//!   command, despawn when stale, lockstep bookkeeping, `/tending/command`, metrics,
//!   markers;
//! - [`delay`]: the fault-injection hold of `test_cmd_delay_ms` / `test_state_delay_ms`;
//! - [`node`]: the ros2-client node (cmd_vel discovery, step loop);
//! - `outputs`: what the node publishes (state frames, per-entity writers, the recorder);
//! - [`watchdog`]: the stages the start-up/stall watchdog names (exit code 75).
//!
//! Run-time commands on `/tending/command` (std_msgs/String): `add_machine [x y]`,
//! `remove_machine <id>`, `add_storage [x y]`, `remove_storage <id>`,
//! `add_robot <name> [x y]`, `remove_robot <name>`.
//!
//! stdout carries one JSON metrics line per `metrics_period_s` (and a last one on exit);
//! logs go to stderr.

pub mod core;
pub mod delay;
pub mod node;
mod outputs;
pub mod params;
pub mod watchdog;
