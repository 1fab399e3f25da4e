//! `rosgraph_msgs` message types.
//!
//! Only `Clock`: the message that simulators and `ros2 bag play --clock`
//! publish on `/clock`, and that nodes with `use_sim_time` read.

use serde::{Deserialize, Serialize};

use crate::{builtin_interfaces::Time, message::Message};

/// `rosgraph_msgs/msg/Clock`: the current simulated time.
///
/// Its CDR encoding is that of its only field, `builtin_interfaces/Time`, but
/// the DDS type name differs (`rosgraph_msgs::msg::dds_::Clock_`), and DDS
/// implementations refuse to match a reader and a writer whose type names
/// differ on one topic.
#[derive(Clone, Copy, Debug, Eq, PartialEq, Serialize, Deserialize)]
pub struct Clock {
  pub clock: Time,
}

impl Message for Clock {}
