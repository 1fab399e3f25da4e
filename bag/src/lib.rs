//! rosbag2 MCAP bags for `tending` (DESIGN.md "Files", REFERENCE.md "rosbag2 MCAP that other
//! tools read", docs/adr/0002-rosbag-mcap.md).
//!
//! * [`BagWriter`]: a bag directory `<dir>/` holding `<dir-name>_0.mcap` (profile `ros2`, one
//!   `ros2msg` schema per type, one `cdr` channel per topic with `offered_qos_profiles` in
//!   its metadata, messages = CDR with the encapsulation header, uncompressed chunks bounded
//!   in bytes and in time, message and chunk indexes, Statistics) and `metadata.yaml`
//!   (rosbag2 version 9, storage `mcap`), rewritten after every chunk so a killed recorder
//!   leaves a directory that describes what reached the disk.
//! * [`BagReader`]: the messages of a bag file or directory, in file order; lenient on
//!   files cut short (a recorder killed with SIGKILL).
//! * [`metrics`]: an episode's picks, deliveries, robots and reported metrics, bin by bin.
//! * [`recover`]: rewrite a cut bag into a complete one holding every message up to the
//!   last complete chunk.

mod metadata;
mod metrics;
mod reader;
mod writer;

pub use metadata::{BagMetadata, TopicInfo};
pub use metrics::{metrics, BagMetrics, MetricsRow};
pub use reader::{recover, BagMessage, BagReader, RecoverReport, TopicSummary};
pub use writer::{BagWriter, WriterOptions};

/// The type and QoS profile of a contract topic (ROS name `/robot_3/pose`, or DDS name
/// `rt/robot_3/pose`): `/clock`, `/tending/{markers,metrics,command}` and every per-entity
/// topic `msgs::topics::parse_topic` accepts. Returns the ROS name too.
pub fn contract_topic(name: &str) -> Option<(String, &'static msgs::MsgDef, msgs::Profile)> {
    use msgs::{schema, topics, Profile};
    let ros = match name.strip_prefix("rt/") {
        Some(r) => format!("/{r}"),
        None if name.starts_with('/') => name.to_string(),
        None => return None,
    };
    let fixed = match ros.as_str() {
        topics::CLOCK => Some((&schema::CLOCK, Profile::Clock)),
        topics::MARKERS => Some((&schema::MARKER_ARRAY, Profile::Visualization)),
        topics::METRICS => Some((&schema::DIAGNOSTIC_ARRAY, Profile::Visualization)),
        topics::COMMAND => Some((&schema::STRING, Profile::RobotStream)),
        _ => None,
    };
    if let Some((def, p)) = fixed {
        return Some((ros, def, p));
    }
    if msgs::cells::parse_cell_topic(&ros).is_some() {
        return Some((ros, &schema::PATH, Profile::Cell));
    }
    let t = topics::parse_topic(name)?;
    Some((t.ros_name(), t.msg_def()?, t.profile()?))
}

/// The storage file of a bag directory: `<dir-name>_0.mcap`, as rosbag2 names it.
pub fn mcap_file_name(dir: &std::path::Path) -> String {
    let stem = dir
        .file_name()
        .and_then(|s| s.to_str())
        .filter(|s| !s.is_empty())
        .unwrap_or("bag");
    format!("{stem}_0.mcap")
}
