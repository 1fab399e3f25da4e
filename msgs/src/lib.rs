//! ROS 2 wire contract of `tending` (see DESIGN.md): serde mirrors of the standard
//! `common_interfaces` messages, their type names and `ros2msg` schema text, CDR helpers,
//! topic names and QoS profiles, stamp keys, input validation, and the SROS2 keystore
//! layout ([`enclave`]). The node runtime that
//! puts them on DDS is the `ros` crate.
//!
//! Only standard types cross the wire, so stock ROS 2 tools read everything.

pub mod cdr;
pub mod cells;
pub mod enclave;
pub mod qos;
pub mod schema;
pub mod stamp;
pub mod topics;
pub mod types;
pub mod validate;

pub use qos::Profile;
pub use schema::{schema_text, MsgDef, RosMessage};
pub use topics::{parse_topic, Entity, EntityTopic, Leaf};
pub use types::*;
pub use validate::{InvalidMsg, RoomBounds};
