//! The node runtime that `robot_node`, `sim_bridge` and the `tending` CLI share.
//!
//! For now: the start-up/stall [`watchdog`]. The rest of the ROS plumbing (context,
//! `--ros-args`, typed pub/sub, signals, tracing) is planned to move here (DESIGN.md).

pub mod watchdog;
