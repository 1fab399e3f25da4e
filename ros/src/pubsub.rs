//! Typed publish/subscribe on the contract's topics with the contract's QoS profiles
//! ([`msgs::Profile`]; ros2-client's defaults differ from rclpy's, so QoS is always set),
//! and [`StampedWriter`] for samples that carry the simulator step as source timestamp.

use anyhow::{anyhow, Result};
use ros2_client::dds::rustdds::Topic;
use ros2_client::dds::rustdds::{
    no_key::DataWriterCdr, Publisher as DdsPublisher, QosPolicies, Timestamp,
};
use ros2_client::dds::{Context, Node, Publisher, Subscription};
use ros2_client::message_info::MessageInfo;
use ros2_client::ros_time::ROSTime;
use ros2_client::{Name, QosProfile};

use msgs::{Profile, RosMessage};

use crate::node::dds_err;

fn topic<M: RosMessage>(node: &Node, name: &str, qos: &QosProfile) -> Result<Topic> {
    let parsed = Name::parse(name).map_err(|e| anyhow!("topic name {name}: {e:?}"))?;
    node.create_topic(&parsed, M::type_name(), qos)
        .map_err(|e| anyhow!("create topic {name}: {e:?}"))
}

/// A reader of `M` on `name` (e.g. `/robot_0/pose`) with `profile`'s QoS.
pub fn subscription<M: RosMessage>(
    node: &mut Node,
    name: &str,
    profile: Profile,
) -> Result<Subscription<M>> {
    subscription_qos(node, name, profile.qos())
}

/// [`subscription`] with an explicit QoS (a bag's recorded profile).
pub fn subscription_qos<M: RosMessage>(
    node: &mut Node,
    name: &str,
    qos: QosProfile,
) -> Result<Subscription<M>> {
    let t = topic::<M>(node, name, &qos)?;
    node.create_subscription(&t, Some(qos))
        .map_err(dds_err("create subscription"))
}

/// A ros2-client publisher of `M` on `name` with `profile`'s QoS (stamped with the wall
/// clock; see [`StampedWriter`] for a chosen stamp).
pub fn publisher<M: RosMessage>(
    node: &mut Node,
    name: &str,
    profile: Profile,
) -> Result<Publisher<M>> {
    publisher_qos(node, name, profile.qos())
}

/// [`publisher`] with an explicit QoS (a bag's recorded profile).
pub fn publisher_qos<M: RosMessage>(
    node: &mut Node,
    name: &str,
    qos: QosProfile,
) -> Result<Publisher<M>> {
    let t = topic::<M>(node, name, &qos)?;
    node.create_publisher(&t, Some(qos))
        .map_err(dds_err("create publisher"))
}

/// The stamp key ([`msgs::stamp::stamp_key_ns`]) of a received sample's source
/// timestamp, if it has one.
pub fn stamp_key_info(info: &MessageInfo) -> Option<i64> {
    info.source_timestamp()
        .map(|t| msgs::stamp::stamp_key_ns(t.to_nanos()))
}

/// A plain RustDDS writer on a contract topic whose samples carry an explicit DDS *source
/// timestamp*.
///
/// ros2-client's `Publisher::publish` always stamps samples with the wall clock; the
/// lockstep protocol (docs/adr/0003-lockstep.md) needs the simulator step a sample
/// belongs to on topics whose message has no header (`std_msgs/Bool`,
/// `geometry_msgs/Twist`). The source timestamp is RTPS metadata, so the message types on
/// the wire stay the standard ones and stock ROS 2 tools read them unchanged (rclpy
/// exposes it as the message info's source timestamp).
///
/// Trade-off: these writers are not registered with the node's `ros_discovery_info`, so
/// `ros2 node info` does not list them; `ros2 topic list/info/echo` see them as usual.
pub struct StampedWriter<M: serde::Serialize> {
    writer: DataWriterCdr<M>,
    _publisher: DdsPublisher,
}

impl<M: RosMessage> StampedWriter<M> {
    /// A writer on `ros_name` (e.g. `/robot_0/cmd_vel`) with `profile`'s QoS.
    pub fn new(ctx: &Context, node: &Node, ros_name: &str, profile: Profile) -> Result<Self> {
        let qos = profile.qos();
        let name = Name::parse(ros_name).map_err(|e| anyhow!("topic name {ros_name}: {e:?}"))?;
        let topic = node
            .create_topic(&name, M::type_name(), &qos)
            .map_err(|e| anyhow!("create topic {ros_name}: {e:?}"))?;
        let dds_qos: QosPolicies = (&qos).into();
        let publisher = ctx
            .domain_participant()
            .create_publisher(&dds_qos)
            .map_err(|e| anyhow!("create DDS publisher for {ros_name}: {e:?}"))?;
        let writer = publisher
            .create_datawriter_no_key_cdr::<M>(&topic, Some(dds_qos))
            .map_err(|e| anyhow!("create DDS writer for {ros_name}: {e:?}"))?;
        Ok(Self {
            writer,
            _publisher: publisher,
        })
    }

    /// Write `msg`; its source timestamp is `stamp_ns` (nanoseconds, e.g. sim time) or the
    /// wall clock when `None`.
    pub fn write(&self, msg: M, stamp_ns: Option<i64>) -> Result<()> {
        let ts = match stamp_ns {
            Some(ns) => Timestamp::from(ROSTime::from_nanos(ns)),
            None => Timestamp::now(),
        };
        self.writer.write(msg, Some(ts)).map_err(|e| {
            use ros2_client::dds::rustdds::dds::WriteError as W;
            match e {
                W::WouldBlock { .. } => anyhow!("send window full (would block)"),
                W::Serialization { reason, .. } => anyhow!("serialization: {reason}"),
                W::Poisoned { reason, .. } => anyhow!("poisoned: {reason}"),
                W::Io(inner) => anyhow!("io: {inner}"),
                W::Internal { reason } => anyhow!("internal: {reason}"),
            }
        })
    }
}
