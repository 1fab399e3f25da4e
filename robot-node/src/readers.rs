//! The node's readers (docs/adr/0008-shared-readers.md): one per input topic, whatever
//! the number of hosted robots, each sample taken once and fanned out to every hosted
//! robot ([`crate::fanout`]).

use std::collections::HashSet;

use ros2_client::dds::Subscription;
use ros2_client::message_info::MessageInfo;
use serde::de::DeserializeOwned;
use tracing::{debug, warn};

use msgs::{Bool, EntityTopic, PoseStamped};
use ros::stamp_key_info;

use crate::fanout::{self, Delivered, Incoming};
use crate::hosted::Hosted;
use crate::world::WriterId;

pub(crate) enum SubKind {
    Pose(Subscription<PoseStamped>),
    Flag(Subscription<Bool>),
}

pub(crate) struct Sub {
    pub(crate) topic: EntityTopic,
    pub(crate) kind: SubKind,
}

/// The readers of the node: one per input topic, whatever the number of hosted robots,
/// indexed by their mio token.
#[derive(Default)]
pub(crate) struct Readers {
    pub(crate) subs: Vec<Sub>,
    /// Topics subscribed to (or being subscribed to).
    pub(crate) known: HashSet<EntityTopic>,
    /// Topics already warned about (wrong type, failed subscription): warned once.
    pub(crate) wrong_type_warned: HashSet<String>,
    pub(crate) sub_failed_warned: HashSet<EntityTopic>,
    /// Readers to drain: signalled by mio, or left with samples by a bounded drain.
    pub(crate) todo: Vec<usize>,
    pub(crate) leftover: Vec<usize>,
    pub(crate) drops_seen: u64,
}

/// Take every sample waiting on `sub` (at most 1000: a flood on one topic cannot starve
/// the loop) and fan each out to every hosted robot. Returns true if the bound was hit
/// (more may be waiting).
pub(crate) fn drain(sub: &Sub, hosted: &mut [Hosted], now: f64, drops_seen: &mut u64) -> bool {
    for _ in 0..1000 {
        let d = match &sub.kind {
            SubKind::Pose(s) => take_one(s, sub, hosted, now, |m, info| Incoming::Pose {
                msg: m,
                writer: writer_id(info),
            }),
            SubKind::Flag(s) => take_one(s, sub, hosted, now, |m, info| Incoming::Flag {
                value: m.data,
                stamp: stamp_key_info(info),
                writer: writer_id(info),
            }),
        };
        let Some(d) = d else {
            return false;
        };
        if d.new_writer > 0 {
            warn!(
                "{}: the pinned writer's data went stale; now pinned to a new writer",
                sub.topic.ros_name()
            );
        }
        if let Some(r) = d.reason {
            if *drops_seen < 20 || drops_seen.is_power_of_two() {
                warn!("dropped a sample on {}: {r:?}", sub.topic.ros_name());
            }
            *drops_seen += 1;
        }
    }
    true
}

/// One sample of `s`, if any, fanned out to every hosted robot as `incoming` makes it (or
/// as undecodable).
fn take_one<M: 'static + DeserializeOwned>(
    s: &Subscription<M>,
    sub: &Sub,
    hosted: &mut [Hosted],
    now: f64,
    incoming: impl for<'m> Fn(&'m M, &MessageInfo) -> Incoming<'m>,
) -> Option<Delivered> {
    let brains = hosted.iter_mut().map(|h| &mut h.brain);
    match s.take() {
        Ok(Some((m, info))) => Some(fanout::deliver(
            brains,
            &sub.topic,
            &incoming(&m, &info),
            now,
        )),
        Ok(None) => None,
        Err(e) => {
            debug!("undecodable sample on {}: {e:?}", sub.topic.ros_name());
            Some(fanout::deliver(
                brains,
                &sub.topic,
                &Incoming::Undecodable,
                now,
            ))
        }
    }
}

/// The DDS writer a received sample came from (its GUID).
fn writer_id(info: &MessageInfo) -> WriterId {
    info.publisher_gid().to_bytes16()
}
