//! `ros_discovery_info` while a node creates many endpoints (issue 46, docs/bench/discovery.md).
//!
//! Every participant publishes on `ros_discovery_info` (rmw_dds_common's
//! ParticipantEntitiesInfo) the list of its nodes and, per node, the GIDs of its readers and
//! writers; rclpy and the ros2 CLI use it to map endpoints to node names. The published
//! ros2-client 0.12.1 republished the whole list at every endpoint a node created, so a
//! node creating E endpoints back to back wrote E samples and about 8 E^2 bytes, which every
//! other participant received (about 240 MB through loopback when a 300-robot fleet starts).
//! Our ros2-client coalesces the updates: a change after a quiet period is published at
//! once, later ones within 100 ms (`ROS_DISCOVERY_INFO_MIN_INTERVAL`) in one sample
//! (docs/upstream/ros2-client/0002-*).
//!
//! The test reads the topic from a second participant as a ROS peer does (the message
//! mirrored field by field), counts the producer's writes by the writer's sequence number
//! (exact even where a reader misses samples that were replaced before delivery), and
//! checks that the last sample names every endpoint under the node's name.

use std::collections::BTreeSet;
use std::time::{Duration, Instant};

use msgs::{Profile, Twist};
use ros::node::node;
use ros::{context_with, publisher, subscription, NodeSpec, Security};
use ros2_client::builtin_topics::ros_discovery;
use ros2_client::dds::rustdds::{self, QosPolicyBuilder, RTPSEntity, TopicKind};
use ros2_client::Gid;
use serde::Deserialize;

/// Endpoints the node creates back to back: half readers, half writers.
const ENDPOINTS: usize = 500;

/// rmw_dds_common/msg/NodeEntitiesInfo as on the wire.
#[derive(Debug, Deserialize)]
struct NodeEntitiesInfo {
    node_namespace: String,
    node_name: String,
    reader_gid_seq: Vec<Gid>,
    writer_gid_seq: Vec<Gid>,
}

/// rmw_dds_common/msg/ParticipantEntitiesInfo as on the wire.
#[derive(Debug, Deserialize)]
struct ParticipantEntitiesInfo {
    gid: Gid,
    node_entities_info_seq: Vec<NodeEntitiesInfo>,
}

#[test]
fn a_node_creating_many_endpoints_publishes_few_complete_discovery_infos() {
    let d = test_domains::domain(0);

    // The observer: a reliable, transient-local reader of ros_discovery_info (as rmw's).
    let observer = context_with(d, &Security::Off).expect("observer context");
    let dp = observer.domain_participant();
    let qos = QosPolicyBuilder::new()
        .durability(rustdds::policy::Durability::TransientLocal)
        .reliable(rustdds::Duration::ZERO)
        .history(rustdds::policy::History::KeepLast { depth: 1 })
        .build();
    let topic = dp
        .create_topic(
            ros_discovery::TOPIC_NAME.to_string(),
            ros_discovery::TYPE_NAME.to_string(),
            &qos,
            TopicKind::NoKey,
        )
        .expect("ros_discovery_info topic");
    let mut reader = dp
        .create_subscriber(&qos)
        .expect("subscriber")
        .create_datareader_no_key_cdr::<ParticipantEntitiesInfo>(&topic, Some(qos.clone()))
        .expect("ros_discovery_info reader");

    // The producer: one node creating its endpoints back to back, as a robot process does.
    let ctx = context_with(d, &Security::Off).expect("producer context");
    let producer = Gid::from(ctx.domain_participant().guid());
    let mut n = node(
        &ctx,
        &NodeSpec {
            namespace: "/",
            name: "discovery_info",
            enable_rosout: false,
        },
    )
    .expect("node");
    let t0 = Instant::now();
    let mut readers = Vec::new();
    let mut writers = Vec::new();
    for i in 0..ENDPOINTS / 2 {
        let r = subscription::<Twist>(&mut n, &format!("/robot_{i}/cmd_vel"), Profile::RobotStream)
            .expect("subscription");
        readers.push(r);
        let w = publisher::<Twist>(&mut n, &format!("/robot_{i}/pose"), Profile::RobotStream)
            .expect("publisher");
        writers.push(w);
    }
    let created = t0.elapsed().as_secs_f64();
    let reader_gids: BTreeSet<Gid> = readers.iter().map(|r| r.gid()).collect();
    let writer_gids: BTreeSet<Gid> = writers.iter().map(|w| w.gid()).collect();

    // The producer's samples until one lists every endpoint, then 1 s more for any later
    // one; the highest sequence number is the number of samples it wrote.
    let complete = |p: &ParticipantEntitiesInfo| {
        p.node_entities_info_seq.iter().any(|ni| {
            ni.node_namespace == "/"
                && ni.node_name == "discovery_info"
                && reader_gids.is_subset(&ni.reader_gid_seq.iter().copied().collect())
                && writer_gids.is_subset(&ni.writer_gid_seq.iter().copied().collect())
        })
    };
    let mut writes = 0i64;
    let mut last: Option<ParticipantEntitiesInfo> = None;
    let mut complete_at: Option<Instant> = None;
    let deadline = Instant::now() + Duration::from_secs(30);
    while Instant::now() < deadline
        && complete_at.is_none_or(|t| t.elapsed() < Duration::from_secs(1))
    {
        while let Ok(Some(s)) = reader.take_next_sample() {
            let sn = i64::from(s.sample_info().sample_identity().sequence_number);
            let p = s.into_value();
            if p.gid != producer {
                continue;
            }
            writes = writes.max(sn);
            if complete(&p) && complete_at.is_none() {
                complete_at = Some(Instant::now());
            }
            last = Some(p);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    eprintln!(
        "{ENDPOINTS} endpoints created in {created:.3} s; the producer wrote {writes} \
         ros_discovery_info samples"
    );

    let last = last.expect("no ros_discovery_info sample from the producer");
    assert!(
        complete(&last),
        "the last ros_discovery_info sample does not list every endpoint under \
         /discovery_info: {} nodes, readers {:?}, writers {:?}",
        last.node_entities_info_seq.len(),
        last.node_entities_info_seq
            .iter()
            .map(|ni| ni.reader_gid_seq.len())
            .collect::<Vec<_>>(),
        last.node_entities_info_seq
            .iter()
            .map(|ni| ni.writer_gid_seq.len())
            .collect::<Vec<_>>(),
    );
    // At most one sample per 100 ms of creation, plus the first and the last; and far
    // below one per endpoint (500 + 1 before the fix) however long creation took here.
    let by_time = 2 + (created / 0.1).ceil() as i64;
    assert!(
        writes <= by_time && writes <= (ENDPOINTS / 4) as i64,
        "{writes} ros_discovery_info samples for {ENDPOINTS} endpoints created in \
         {created:.3} s (at most {by_time} expected, one per 100 ms)"
    );
}
