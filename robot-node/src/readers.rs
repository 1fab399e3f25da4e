//! The node's readers (docs/adr/0008-shared-readers.md): one per input topic, whatever
//! the number of hosted robots, each sample taken once and fanned out to every hosted
//! robot ([`crate::fanout`]). In cell mode (docs/adr/0038-cell-topics.md) the readers are
//! the hosted robots' own topics and the cells around them.

use std::collections::HashSet;
use std::sync::Arc;

use ros2_client::dds::Subscription;
use ros2_client::message_info::MessageInfo;
use serde::de::DeserializeOwned;
use tracing::{debug, warn};

use msgs::cells::{self, Cell};
use msgs::{Bool, EntityTopic, Path, PoseStamped, RoomBounds};
use ros::stamp_key_info;

use crate::cells::CellContent;
use crate::fanout::{self, Delivered, Incoming};
use crate::hosted::Hosted;
use crate::world::{DropReason, WriterId};

pub(crate) enum SubKind {
    Pose(Subscription<PoseStamped>, EntityTopic),
    Flag(Subscription<Bool>, EntityTopic),
    Cell(Subscription<Path>, Cell),
    /// A cell no hosted robot reads any more: its reader deleted, its slot (mio token)
    /// kept so the others' tokens stay valid.
    Closed,
}

pub(crate) struct Sub {
    /// The topic's ROS name (log lines).
    pub(crate) name: String,
    pub(crate) kind: SubKind,
}

/// The readers of the node: one per input topic, whatever the number of hosted robots,
/// indexed by their mio token.
#[derive(Default)]
pub(crate) struct Readers {
    pub(crate) subs: Vec<Sub>,
    /// Topics subscribed to (or being subscribed to).
    pub(crate) known: HashSet<EntityTopic>,
    /// Cell mode: cells subscribed to.
    pub(crate) cells: HashSet<Cell>,
    /// Topics already warned about (wrong type, failed subscription): warned once.
    pub(crate) wrong_type_warned: HashSet<String>,
    pub(crate) sub_failed_warned: HashSet<EntityTopic>,
    /// Readers to drain: signalled by mio, or left with samples by a bounded drain.
    pub(crate) todo: Vec<usize>,
    pub(crate) leftover: Vec<usize>,
    pub(crate) drops_seen: u64,
}

impl Readers {
    /// Readers open now.
    pub(crate) fn open(&self) -> usize {
        self.subs
            .iter()
            .filter(|s| !matches!(s.kind, SubKind::Closed))
            .count()
    }
}

/// Take every sample waiting on `sub` (at most 1000: a flood on one topic cannot starve
/// the loop) and fan each out to every hosted robot. Returns true if the bound was hit
/// (more may be waiting).
pub(crate) fn drain(
    sub: &Sub,
    hosted: &mut [Hosted],
    room: &RoomBounds,
    now: f64,
    drops_seen: &mut u64,
) -> bool {
    for _ in 0..1000 {
        let d = match &sub.kind {
            SubKind::Pose(s, topic) => take_one(s, topic, hosted, now, |m, info| Incoming::Pose {
                msg: m,
                writer: writer_id(info),
            }),
            SubKind::Flag(s, topic) => take_one(s, topic, hosted, now, |m, info| Incoming::Flag {
                value: m.data,
                stamp: stamp_key_info(info),
                writer: writer_id(info),
            }),
            SubKind::Cell(s, cell) => take_cell(s, *cell, &sub.name, hosted, room, now),
            SubKind::Closed => None,
        };
        let Some(d) = d else {
            return false;
        };
        if d.new_writer > 0 {
            warn!(
                "{}: the pinned writer's data went stale; now pinned to a new writer",
                sub.name
            );
        }
        if let Some(r) = d.reason {
            if *drops_seen < 20 || drops_seen.is_power_of_two() {
                warn!("dropped a sample on {}: {r:?}", sub.name);
            }
            *drops_seen += 1;
        }
    }
    true
}

/// One sample of `s`, if any, fanned out to every hosted robot as `incoming` makes it (or
/// as undecodable).
fn take_one<M: 'static + DeserializeOwned + serde::Serialize>(
    s: &Subscription<M>,
    topic: &EntityTopic,
    hosted: &mut [Hosted],
    now: f64,
    incoming: impl for<'m> Fn(&'m M, &MessageInfo) -> Incoming<'m>,
) -> Option<Delivered> {
    let brains = hosted.iter_mut().map(|h| &mut h.brain);
    match s.take() {
        Ok(Some((m, info))) => Some(fanout::deliver_sized(
            brains,
            topic,
            &incoming(&m, &info),
            payload_bytes(&m),
            now,
        )),
        Ok(None) => None,
        Err(e) => {
            debug!("undecodable sample on {}: {e:?}", topic.ros_name());
            Some(fanout::deliver(brains, topic, &Incoming::Undecodable, now))
        }
    }
}

/// One cell message of `s`, if any: decoded and validated once, then handed to every
/// hosted robot that reads or keeps that cell.
fn take_cell(
    s: &Subscription<Path>,
    cell: Cell,
    name: &str,
    hosted: &mut [Hosted],
    room: &RoomBounds,
    now: f64,
) -> Option<Delivered> {
    let brains = hosted.iter_mut().map(|h| &mut h.brain);
    let (content, writer) = match s.take() {
        Ok(Some((m, info))) => {
            let content = match cells::decode(&m, room) {
                Ok(entries) => Ok(Arc::new(CellContent {
                    stamp: msgs::stamp::stamp_key_time(&m.header.stamp),
                    entries,
                    bytes: payload_bytes(&m),
                })),
                Err(e) => {
                    debug!("refused a sample on {name}: {e}");
                    Err(match e {
                        cells::BadCell::Pose { source, .. } => match source {
                            msgs::InvalidMsg::NonFinite { .. } => DropReason::NonFinite,
                            msgs::InvalidMsg::OutOfRoom { .. } => DropReason::OutOfRoom,
                        },
                        _ => DropReason::Unexpected,
                    })
                }
            };
            (content, writer_id(&info))
        }
        Ok(None) => return None,
        Err(e) => {
            debug!("undecodable sample on {name}: {e:?}");
            (Err(DropReason::Decode), [0; 16])
        }
    };
    Some(fanout::deliver_cell(brains, cell, &content, writer, now))
}

/// The CDR payload size of a received message (as serialized again: the same bytes the
/// writer sent, encapsulation header included).
fn payload_bytes<M: serde::Serialize>(m: &M) -> usize {
    msgs::cdr::encode(m).map(|v| v.len()).unwrap_or(0)
}

/// The DDS writer a received sample came from (its GUID).
fn writer_id(info: &MessageInfo) -> WriterId {
    info.publisher_gid().to_bytes16()
}
