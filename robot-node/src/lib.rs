//! `robot_node`: one decentralized tending controller per robot.
//!
//! - [`args`]: ROS 2 command-line conventions (`--ros-args`, `-r`, `-p`, `--params-file`),
//!   `ROS_DOMAIN_ID`;
//! - [`world`]: latest validated inputs with staleness, and the observation built from them;
//! - [`sample`]: one received value, the writer-pin rule and drop reasons, shared by both;
//! - [`cells`]: cell mode's part of the world: the cells around the robot (ADR 0038);
//! - [`controller`]: the [`controller::Controller`] trait (seam for the learned policy),
//!   the policy through `plan`'s pilot, and the scripted controllers (greedy, greedy-ORCA,
//!   matching-ORCA);
//! - [`tick`]: one control step, DDS-free;
//! - [`fanout`]: one received sample to every robot a process hosts, DDS-free;
//! - [`node`]: the ros2-client node: controllers, context, node and spinner, start-up;
//! - `event_loop`: discovery, timing, the phases of the loop (one method each);
//! - `hosted`: a hosted robot, its cmd_vel writer and one control step of it;
//! - `readers`: one reader per input topic, drained into every hosted robot;
//! - [`watchdog`]: exit code 75 when start-up or the control loop hangs (the stages it names),
//!   and the start-up retry loop.

pub mod args;
pub mod cells;
pub mod controller;
mod event_loop;
pub mod fanout;
mod hosted;
pub mod node;
mod readers;
pub mod sample;
pub mod tick;
pub mod watchdog;
pub mod world;
