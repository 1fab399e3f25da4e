//! One received value and the rules every input topic applies to it, whole-topic or cell
//! (docs/adr/0004-writer-pinning.md): the sample with its arrival time, step stamp and
//! writer, the writer-pin rule, why a sample is refused, and the peers' natural order.
//! Shared by [`crate::world`] and [`crate::cells`].

/// Identity of the DDS writer a sample came from: its 16-byte RTPS GUID (ros2-client's
/// `MessageInfo::publisher_gid().to_bytes16()`).
pub type WriterId = [u8; 16];

/// The writer id the DDS-free convenience methods ([`crate::world::World::on_pose`], [`crate::world::World::on_flag`])
/// attribute their samples to.
pub const DEFAULT_WRITER: WriterId = [0; 16];

/// A value and when it arrived.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample<T> {
    pub value: T,
    pub at: f64,
    /// Simulator step stamp (microseconds, [`msgs::stamp::stamp_key_ns`]): a pose's header
    /// stamp, a flag's DDS source timestamp. Used in lockstep only.
    pub stamp: Option<i64>,
    /// The writer that published it: the topic's pinned writer.
    pub writer: WriterId,
}

/// A sample was taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Accepted {
    /// From the pinned writer, or the topic's first valid sample (which pins its writer).
    Stored,
    /// From a new writer, which replaced a pinned writer whose data had gone stale (e.g.
    /// a restarted sim_bridge).
    NewWriter,
}

impl<T: Copy> Sample<T> {
    pub(crate) fn fresh(s: &Option<Sample<T>>, now: f64, timeout: f64) -> Option<T> {
        match s {
            Some(s) if timeout <= 0.0 || now - s.at <= timeout => Some(s.value),
            _ => None,
        }
    }
}

/// Why an input was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DropReason {
    /// Could not be decoded (wrong size, bad encapsulation, ...).
    Decode,
    /// A NaN or infinite number.
    NonFinite,
    /// A position outside the room bounds.
    OutOfRoom,
    /// A topic/type combination outside the contract.
    Unexpected,
    /// A valid sample from a writer other than the topic's pinned writer, while the
    /// pinned writer's data is fresh (an impostor claiming the entity's name).
    ForeignWriter,
}

/// The writer-pin rule for one topic whose current sample is `held`: the first valid
/// sample pins its writer; the pinned writer is always accepted; another writer is
/// refused while the held sample is at most `release_s` old and takes the pin after.
pub fn admit<T>(
    held: &Option<Sample<T>>,
    writer: WriterId,
    now: f64,
    release_s: f64,
) -> Result<Accepted, DropReason> {
    match held {
        None => Ok(Accepted::Stored),
        Some(s) if s.writer == writer => Ok(Accepted::Stored),
        Some(s) if now - s.at > release_s => Ok(Accepted::NewWriter),
        Some(_) => Err(DropReason::ForeignWriter),
    }
}

/// Peers in natural order (`robot_2` before `robot_10`): the simulator's robot order when
/// robots are named `robot_<spawn index>`, so observations match the simulator's exactly.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) struct PeerKey {
    stem: String,
    index: Option<u64>,
    name: String,
}

impl PeerKey {
    pub(crate) fn new(name: &str) -> Self {
        let digits = name.len() - name.trim_end_matches(|c: char| c.is_ascii_digit()).len();
        let (stem, num) = name.split_at(name.len() - digits);
        Self {
            stem: stem.to_string(),
            index: num.parse().ok(),
            name: name.to_string(),
        }
    }
}
