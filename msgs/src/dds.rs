//! DDS helpers shared by `robot_node` and `sim_bridge`.
//!
//! [`StampedWriter`]: a plain RustDDS writer on a contract topic whose samples carry an
//! explicit DDS *source timestamp*. ros2-client's `Publisher::publish` always stamps
//! samples with the wall clock; the lockstep protocol (docs/adr/0003-lockstep.md) needs
//! the simulator step a sample belongs to on topics whose message has no header
//! (`std_msgs/Bool`, `geometry_msgs/Twist`). The source timestamp is RTPS metadata, so
//! the message types on the wire stay the standard ones and stock ROS 2 tools read them
//! unchanged (rclpy exposes it as the message info's source timestamp).
//!
//! Trade-off: these writers are not registered with the node's `ros_discovery_info`, so
//! `ros2 node info` does not list them; `ros2 topic list/info/echo` see them as usual.

use ros2_client::dds::rustdds::{
    no_key::DataWriterCdr, Publisher as DdsPublisher, QosPolicies, Timestamp,
};
use ros2_client::dds::{Context, Node};
use ros2_client::message_info::MessageInfo;
use ros2_client::ros_time::ROSTime;
use ros2_client::Name;

use crate::{Profile, RosMessage};

/// Stamps are compared in whole microseconds: RTPS timestamps have a 2^-32 s tick, so a
/// nanosecond value does not survive the round trip exactly.
pub fn stamp_key_ns(ns: i64) -> i64 {
    (ns + 500).div_euclid(1000)
}

/// The stamp key of a `builtin_interfaces/Time`.
pub fn stamp_key_time(t: &crate::Time) -> i64 {
    stamp_key_ns(t.sec as i64 * 1_000_000_000 + t.nanosec as i64)
}

/// The stamp key of a received sample's source timestamp, if it has one.
pub fn stamp_key_info(info: &MessageInfo) -> Option<i64> {
    info.source_timestamp().map(|t| stamp_key_ns(t.to_nanos()))
}

/// A writer whose samples carry a chosen source timestamp.
pub struct StampedWriter<M: serde::Serialize> {
    writer: DataWriterCdr<M>,
    _publisher: DdsPublisher,
}

impl<M: RosMessage> StampedWriter<M> {
    /// A reliable writer on `ros_name` (e.g. `/robot_0/cmd_vel`) with `profile`'s QoS.
    pub fn new(
        ctx: &Context,
        node: &Node,
        ros_name: &str,
        profile: Profile,
    ) -> Result<Self, String> {
        let qos = profile.qos();
        let name = Name::parse(ros_name).map_err(|e| format!("topic name {ros_name}: {e:?}"))?;
        let topic = node
            .create_topic(&name, M::type_name(), &qos)
            .map_err(|e| format!("create topic {ros_name}: {e:?}"))?;
        let dds_qos: QosPolicies = (&qos).into();
        let publisher = ctx
            .domain_participant()
            .create_publisher(&dds_qos)
            .map_err(|e| format!("create DDS publisher for {ros_name}: {e:?}"))?;
        let writer = publisher
            .create_datawriter_no_key_cdr::<M>(&topic, Some(dds_qos))
            .map_err(|e| format!("create DDS writer for {ros_name}: {e:?}"))?;
        Ok(Self {
            writer,
            _publisher: publisher,
        })
    }

    /// Write `msg`; its source timestamp is `stamp_ns` (nanoseconds, e.g. sim time) or the
    /// wall clock when `None`.
    pub fn write(&self, msg: M, stamp_ns: Option<i64>) -> Result<(), String> {
        let ts = match stamp_ns {
            Some(ns) => Timestamp::from(ROSTime::from_nanos(ns)),
            None => Timestamp::now(),
        };
        self.writer.write(msg, Some(ts)).map_err(|e| {
            use ros2_client::dds::rustdds::dds::WriteError as W;
            match e {
                W::WouldBlock { .. } => "send window full (would block)".to_string(),
                W::Serialization { reason, .. } => format!("serialization: {reason}"),
                W::Poisoned { reason, .. } => format!("poisoned: {reason}"),
                W::Io(inner) => format!("io: {inner}"),
                W::Internal { reason } => format!("internal: {reason}"),
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stamp_keys_tolerate_tick_rounding() {
        assert_eq!(stamp_key_ns(100_000_000), stamp_key_ns(99_999_999));
        assert_eq!(stamp_key_ns(100_000_000), stamp_key_ns(100_000_001));
        assert_ne!(stamp_key_ns(100_000_000), stamp_key_ns(200_000_000));
        let t = crate::Time::from_secs_f64(0.3);
        assert_eq!(stamp_key_time(&t), 300_000);
    }
}
