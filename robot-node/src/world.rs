//! What the robot knows about the world: the latest validated sample of every input,
//! with its arrival time, and the staleness rules that turn it into an observation.
//!
//! Times are seconds on a monotonic clock chosen by the caller (the node uses wall time
//! since start), so this module is deterministic and testable without DDS.
//!
//! Writer pinning (docs/adr/0004-writer-pinning.md): every input topic (pose and flag of
//! each entity) is pinned to the DDS writer whose valid sample it holds; a valid sample
//! from another writer is refused ([`DropReason::ForeignWriter`]) unless the pinned
//! writer's data is older than the entity's staleness timeout ([`World::pin_release_s`]),
//! in which case the new writer takes the pin ([`Accepted::NewWriter`]).

use std::collections::BTreeMap;
use std::sync::Arc;

use msgs::cells::{Cell, CellGrid};
use msgs::{Entity, EntityTopic, Leaf, PoseStamped, RoomBounds};

use crate::cells::{CellContent, CellView, Gathered};
use crate::sample::PeerKey;
pub use crate::sample::{admit, Accepted, DropReason, Sample, WriterId, DEFAULT_WRITER};

#[derive(Debug, Clone, Default)]
struct EntityState {
    pose: Option<Sample<[f64; 2]>>,
    flag: Option<Sample<bool>>,
}

/// Counters of everything received, dropped and done; logged periodically and on exit.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Counters {
    pub accepted: u64,
    /// CDR payload bytes of the samples accepted (traffic per robot, docs/bench/cells.md).
    pub accepted_bytes: u64,
    pub dropped_decode: u64,
    pub dropped_non_finite: u64,
    pub dropped_out_of_room: u64,
    pub dropped_unexpected: u64,
    /// Valid samples refused because another writer holds the topic's pin.
    pub dropped_foreign_writer: u64,
    /// Pins handed to a new writer after the pinned writer's data went stale.
    pub writer_changes: u64,
    pub ticks: u64,
    pub commands: u64,
    /// Realtime: ticks that found no new state and sent the last command again (counted
    /// in `ticks` and `commands` too).
    pub repeated_commands: u64,
    /// Realtime: peer poses in the observations acted on, and how many of them were of
    /// another state (stamp) than the robot's own pose.
    pub peer_poses_used: u64,
    pub peer_poses_off_stamp: u64,
    pub zero_own_stale: u64,
    /// Zero commands sent at start-up while topic discovery was still adding inputs
    /// (the node's world settles first, docs/adr/0024-act-on-state.md).
    pub zero_discovering: u64,
    pub zero_obs_invalid: u64,
    pub zero_controller_error: u64,
    pub zero_bad_output: u64,
    pub publish_errors: u64,
    pub subscriptions: u64,
    /// Lockstep: states acted on before every expected entity of that stamp was in.
    pub lockstep_wait_timeouts: u64,
    /// Lockstep: answers sent again because the bridge had not moved on after
    /// `lockstep_resend_s` (docs/adr/0029-lockstep-resends.md).
    pub lockstep_resends: u64,
    /// Real time (`act_on_state`): states acted on after `state_wait_s` with some expected
    /// entity of that stamp still missing (its older sample was used).
    pub state_wait_timeouts: u64,
    /// Control periods missed: wall clock, a tick that ran more than one period after its
    /// scheduled time (each whole period of lateness is one missed, skipped tick); sim time,
    /// tick indices skipped between two `/clock` updates. Not counted in lockstep.
    pub ticks_missed: u64,
    /// Wall clock: largest lateness of a tick behind its scheduled time, microseconds.
    pub tick_late_max_us: u64,
}

impl Counters {
    pub fn drop(&mut self, r: DropReason) {
        match r {
            DropReason::Decode => self.dropped_decode += 1,
            DropReason::NonFinite => self.dropped_non_finite += 1,
            DropReason::OutOfRoom => self.dropped_out_of_room += 1,
            DropReason::Unexpected => self.dropped_unexpected += 1,
            DropReason::ForeignWriter => self.dropped_foreign_writer += 1,
        }
    }
    pub fn dropped(&self) -> u64 {
        self.dropped_decode
            + self.dropped_non_finite
            + self.dropped_out_of_room
            + self.dropped_unexpected
            + self.dropped_foreign_writer
    }
}

impl Counters {
    /// Add another robot's counters (multi-robot mode totals); maxima stay maxima.
    pub fn add(&mut self, o: &Counters) {
        self.accepted += o.accepted;
        self.dropped_decode += o.dropped_decode;
        self.dropped_non_finite += o.dropped_non_finite;
        self.dropped_out_of_room += o.dropped_out_of_room;
        self.dropped_unexpected += o.dropped_unexpected;
        self.dropped_foreign_writer += o.dropped_foreign_writer;
        self.writer_changes += o.writer_changes;
        self.ticks += o.ticks;
        self.commands += o.commands;
        self.repeated_commands += o.repeated_commands;
        self.peer_poses_used += o.peer_poses_used;
        self.peer_poses_off_stamp += o.peer_poses_off_stamp;
        self.zero_own_stale += o.zero_own_stale;
        self.zero_discovering += o.zero_discovering;
        self.zero_obs_invalid += o.zero_obs_invalid;
        self.zero_controller_error += o.zero_controller_error;
        self.zero_bad_output += o.zero_bad_output;
        self.publish_errors += o.publish_errors;
        self.accepted_bytes += o.accepted_bytes;
        self.subscriptions += o.subscriptions;
        self.lockstep_wait_timeouts += o.lockstep_wait_timeouts;
        self.lockstep_resends += o.lockstep_resends;
        self.state_wait_timeouts += o.state_wait_timeouts;
        self.ticks_missed += o.ticks_missed;
        self.tick_late_max_us = self.tick_late_max_us.max(o.tick_late_max_us);
    }

    /// The counters as one JSON object (machine-readable stats line).
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "accepted": self.accepted,
            "accepted_bytes": self.accepted_bytes,
            "dropped": {
                "decode": self.dropped_decode,
                "non_finite": self.dropped_non_finite,
                "out_of_room": self.dropped_out_of_room,
                "unexpected": self.dropped_unexpected,
                "foreign_writer": self.dropped_foreign_writer,
            },
            "writer_changes": self.writer_changes,
            "ticks": self.ticks,
            "commands": self.commands,
            "repeated_commands": self.repeated_commands,
            "peer_poses_used": self.peer_poses_used,
            "peer_poses_off_stamp": self.peer_poses_off_stamp,
            "zero": {
                "own_stale": self.zero_own_stale,
                "discovering": self.zero_discovering,
                "obs_invalid": self.zero_obs_invalid,
                "controller_error": self.zero_controller_error,
                "bad_output": self.zero_bad_output,
            },
            "publish_errors": self.publish_errors,
            "subscriptions": self.subscriptions,
            "lockstep_wait_timeouts": self.lockstep_wait_timeouts,
            "lockstep_resends": self.lockstep_resends,
            "state_wait_timeouts": self.state_wait_timeouts,
            "ticks_missed": self.ticks_missed,
            "tick_late_max_us": self.tick_late_max_us,
        })
    }
}

impl std::fmt::Display for Counters {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "accepted={} bytes={} dropped(decode={} non_finite={} out_of_room={} unexpected={} \
             foreign_writer={}) writer_changes={} ticks={} commands={} repeated_commands={} \
             peer_poses(used={} off_stamp={}) zero(own_stale={} discovering={} obs_invalid={} controller_error={} bad_output={}) \
             publish_errors={} subscriptions={} lockstep_wait_timeouts={} lockstep_resends={} \
             state_wait_timeouts={} ticks_missed={} tick_late_max_us={}",
            self.accepted,
            self.accepted_bytes,
            self.dropped_decode,
            self.dropped_non_finite,
            self.dropped_out_of_room,
            self.dropped_unexpected,
            self.dropped_foreign_writer,
            self.writer_changes,
            self.ticks,
            self.commands,
            self.repeated_commands,
            self.peer_poses_used,
            self.peer_poses_off_stamp,
            self.zero_own_stale,
            self.zero_discovering,
            self.zero_obs_invalid,
            self.zero_controller_error,
            self.zero_bad_output,
            self.publish_errors,
            self.subscriptions,
            self.lockstep_wait_timeouts,
            self.lockstep_resends,
            self.state_wait_timeouts,
            self.ticks_missed,
            self.tick_late_max_us
        )
    }
}

/// The world model's staleness and validation settings (not the simulator's
/// `sim::WorldConfig`, which is the simulated room and its clock).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldModelConfig {
    /// Robots (own and peers): no sample for this long -> stale.
    pub stale_timeout_s: f64,
    /// Machines and storages; <= 0 = never stale.
    pub static_stale_timeout_s: f64,
    pub room: RoomBounds,
    /// What the robot observes of what it receives: everything, or the k nearest of each
    /// group by the simulator's rule (`obs::nearest`, docs/adr/0037).
    pub bound: obs::Bound,
    /// Read the floor from cell topics (docs/adr/0038-cell-topics.md): the grid and how
    /// many cells around its own the robot reads. None: every entity's topics.
    pub cells: Option<(CellGrid, u32)>,
}

/// Latest data about self, machines, storages and peers.
#[derive(Debug, Clone)]
pub struct World {
    pub cfg: WorldModelConfig,
    /// This robot's id (namespace without the leading slash).
    pub me: String,
    own: EntityState,
    machines: BTreeMap<u32, EntityState>,
    storages: BTreeMap<u32, EntityState>,
    peers: BTreeMap<PeerKey, EntityState>,
    /// Cell mode: the cells around the robot (machines, storages and peers come from
    /// there, not from the maps above).
    cells: Option<CellView>,
}

/// Own state is not usable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OwnStale {
    NoPose,
    PoseStale,
    NoHasPart,
    HasPartStale,
}

impl std::fmt::Display for OwnStale {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            OwnStale::NoPose => "no own pose received yet",
            OwnStale::PoseStale => "own pose is stale",
            OwnStale::NoHasPart => "no own has_part received yet",
            OwnStale::HasPartStale => "own has_part is stale",
        })
    }
}

impl World {
    pub fn new(me: &str, cfg: WorldModelConfig) -> Self {
        Self {
            cfg,
            me: me.trim_matches('/').to_string(),
            own: EntityState::default(),
            machines: BTreeMap::new(),
            storages: BTreeMap::new(),
            peers: BTreeMap::new(),
            cells: cfg.cells.map(|(g, reach)| CellView::new(g, reach)),
        }
    }

    /// Does this robot read `entity`'s own topics? Always, but in cell mode only its own
    /// (another hosted robot's pose reaches it through the cells, like any peer's).
    pub fn reads_topics_of(&self, entity: &Entity) -> bool {
        self.cells.is_none() || matches!(entity, Entity::Robot(r) if *r == self.me)
    }

    /// Cell mode: the cell the robot is in (by its latest own pose) and how many rings of
    /// cells around it it reads now.
    pub fn own_cell(&self) -> Option<(Cell, u32)> {
        match (&self.cells, self.own.pose) {
            (Some(v), Some(p)) => Some((v.grid.cell_of(p.value), v.rings())),
            _ => None,
        }
    }

    /// Cell mode: the cells the robot reads now (none before its own pose arrived).
    pub fn cells_needed(&self) -> Vec<Cell> {
        match (&self.cells, self.own.pose) {
            (Some(v), Some(p)) => v.needed(p.value).collect(),
            _ => Vec::new(),
        }
    }

    /// Cell mode: a cell's state arrived (validated already). `Ok(None)`: a cell too far
    /// from this robot to keep; not counted.
    pub fn on_cell(
        &mut self,
        cell: Cell,
        content: &Arc<CellContent>,
        writer: WriterId,
        now: f64,
    ) -> Result<Option<Accepted>, DropReason> {
        let own = self.own.pose.map(|p| p.value);
        let release = self.cfg.stale_timeout_s;
        match self.cells.as_mut() {
            Some(v) => v.on_cell(cell, content, writer, own, now, release),
            None => Err(DropReason::Unexpected),
        }
    }

    /// Cell mode: the observation from the cells around `own_pos`, each taken if `usable`.
    fn observe_cells(
        &self,
        v: &CellView,
        own_pos: [f64; 2],
        has_part: bool,
        usable: impl Fn(&Sample<Arc<CellContent>>) -> bool,
    ) -> obs::ObsBuilder {
        let Gathered {
            machines,
            storages,
            peers,
        } = v.gather(&self.me, own_pos, usable);
        obs::ObsBuilder {
            own_pos: [own_pos[0] as f32, own_pos[1] as f32],
            has_part,
            machines,
            storages,
            peers,
        }
        .bounded(&self.cfg.bound)
    }

    fn slot(&mut self, entity: &Entity) -> &mut EntityState {
        match entity {
            Entity::Robot(r) if *r == self.me => &mut self.own,
            Entity::Robot(r) => self.peers.entry(PeerKey::new(r)).or_default(),
            Entity::Machine(j) => self.machines.entry(*j).or_default(),
            Entity::Storage(k) => self.storages.entry(*k).or_default(),
        }
    }

    /// A pose arrived on `topic`: validate and store it (attributed to [`DEFAULT_WRITER`]).
    pub fn on_pose(
        &mut self,
        topic: &EntityTopic,
        msg: &PoseStamped,
        now: f64,
    ) -> Result<Accepted, DropReason> {
        self.on_pose_from(topic, msg, DEFAULT_WRITER, now)
    }

    /// A pose arrived on `topic` from DDS writer `writer`: validate it, check the topic's
    /// writer pin, store it. Invalid samples are refused before the pin is looked at, so
    /// they neither take nor refresh a pin.
    pub fn on_pose_from(
        &mut self,
        topic: &EntityTopic,
        msg: &PoseStamped,
        writer: WriterId,
        now: f64,
    ) -> Result<Accepted, DropReason> {
        if topic.leaf != Leaf::Pose {
            return Err(DropReason::Unexpected);
        }
        let xy = msgs::validate::pose_stamped(msg, &self.cfg.room).map_err(|e| match e {
            msgs::InvalidMsg::NonFinite { .. } => DropReason::NonFinite,
            msgs::InvalidMsg::OutOfRoom { .. } => DropReason::OutOfRoom,
        })?;
        let stamp = Some(msgs::stamp::stamp_key_time(&msg.header.stamp));
        let release = self.pin_release_s(&topic.entity);
        let slot = &mut self.slot(&topic.entity).pose;
        let accepted = admit(slot, writer, now, release)?;
        *slot = Some(Sample {
            value: xy,
            at: now,
            stamp,
            writer,
        });
        Ok(accepted)
    }

    /// A Bool arrived on `topic` (`has_part` of a robot or `part_ready` of a machine).
    pub fn on_flag(
        &mut self,
        topic: &EntityTopic,
        value: bool,
        now: f64,
    ) -> Result<Accepted, DropReason> {
        self.on_flag_stamped(topic, value, None, DEFAULT_WRITER, now)
    }

    /// A Bool arrived from DDS writer `writer`, with the step stamp of its DDS source
    /// timestamp; pinned like poses.
    pub fn on_flag_stamped(
        &mut self,
        topic: &EntityTopic,
        value: bool,
        stamp: Option<i64>,
        writer: WriterId,
        now: f64,
    ) -> Result<Accepted, DropReason> {
        match (&topic.entity, topic.leaf) {
            (Entity::Robot(_), Leaf::HasPart) | (Entity::Machine(_), Leaf::PartReady) => {}
            _ => return Err(DropReason::Unexpected),
        }
        let release = self.pin_release_s(&topic.entity);
        let slot = &mut self.slot(&topic.entity).flag;
        let accepted = admit(slot, writer, now, release)?;
        *slot = Some(Sample {
            value,
            at: now,
            stamp,
            writer,
        });
        Ok(accepted)
    }

    /// How long the pinned writer of `entity`'s topics must have been silent (no valid
    /// sample) before another writer may take the pin: the entity's staleness timeout,
    /// i.e. exactly when its data drops out of the observation. Machines and storages
    /// whose staleness is disabled (`static_stale_timeout_s <= 0`) use the robots'
    /// timeout, so a restarted bridge's latched topics are still taken over.
    pub fn pin_release_s(&self, entity: &Entity) -> f64 {
        match entity {
            Entity::Robot(_) => self.cfg.stale_timeout_s,
            Entity::Machine(_) | Entity::Storage(_) if self.cfg.static_stale_timeout_s > 0.0 => {
                self.cfg.static_stale_timeout_s
            }
            _ => self.cfg.stale_timeout_s,
        }
    }

    /// Build the observation input from fresh data only, or say why own data is unusable.
    ///
    /// A machine needs a fresh pose and part_ready, a storage a fresh pose, a peer a
    /// fresh pose and has_part; anything else is left out. Entities are ordered by id.
    /// The robot's own position and has_part at `now`, or why they cannot be used.
    pub fn own_inputs(&self, now: f64) -> Result<([f64; 2], bool), OwnStale> {
        let rt = self.cfg.stale_timeout_s;
        let pos = match (&self.own.pose, Sample::fresh(&self.own.pose, now, rt)) {
            (None, _) => return Err(OwnStale::NoPose),
            (Some(_), None) => return Err(OwnStale::PoseStale),
            (_, Some(p)) => p,
        };
        let has_part = match (&self.own.flag, Sample::fresh(&self.own.flag, now, rt)) {
            (None, _) => return Err(OwnStale::NoHasPart),
            (Some(_), None) => return Err(OwnStale::HasPartStale),
            (_, Some(h)) => h,
        };
        Ok((pos, has_part))
    }

    pub fn observation(&self, now: f64) -> Result<obs::ObsBuilder, OwnStale> {
        let rt = self.cfg.stale_timeout_s;
        let st = self.cfg.static_stale_timeout_s;
        let (pos, has_part) = self.own_inputs(now)?;
        if let Some(v) = &self.cells {
            let fresh = |s: &Sample<Arc<CellContent>>| rt <= 0.0 || now - s.at <= rt;
            v.settle_window(&self.me, pos, &self.cfg.bound, fresh);
            return Ok(self.observe_cells(v, pos, has_part, fresh));
        }
        let f = |p: [f64; 2]| [p[0] as f32, p[1] as f32];
        let machines = self
            .machines
            .values()
            .filter_map(|m| {
                Some((
                    f(Sample::fresh(&m.pose, now, st)?),
                    Sample::fresh(&m.flag, now, st)?,
                ))
            })
            .collect();
        let storages = self
            .storages
            .values()
            .filter_map(|s| Some(f(Sample::fresh(&s.pose, now, st)?)))
            .collect();
        let peers = self
            .peers
            .values()
            .filter_map(|r| {
                Some((
                    f(Sample::fresh(&r.pose, now, rt)?),
                    Sample::fresh(&r.flag, now, rt)?,
                ))
            })
            .collect();
        Ok(obs::ObsBuilder {
            own_pos: f(pos),
            has_part,
            machines,
            storages,
            peers,
        }
        .bounded(&self.cfg.bound))
    }

    /// An entity was discovered (subscribed): lockstep expects its data from the first
    /// state on, even before a sample arrived.
    pub fn touch(&mut self, entity: &Entity) {
        self.slot(entity);
    }

    /// Known entities (subscribed to) with no sample yet of a topic they need: a pose, and
    /// for machines and peers a flag. Right after start-up, the world is not complete
    /// until this is 0.
    pub fn entities_without_data(&self) -> usize {
        if let (Some(v), Some(p)) = (&self.cells, self.own.pose) {
            return v.without_data(&self.me, p.value, &self.cfg.bound);
        }
        self.each_entity()
            .filter(|(e, needs_flag)| Self::without_data(e, *needs_flag))
            .count()
    }

    /// Discovered machines and storages without data yet: boxes the robot could not see
    /// in its observation, nor its safety filter steer around.
    pub fn fixtures_without_data(&self) -> usize {
        if self.cells.is_some() {
            // a cell brings its machines and storages with it
            return self.entities_without_data();
        }
        let m = self
            .machines
            .values()
            .filter(|e| Self::without_data(e, true));
        let s = self
            .storages
            .values()
            .filter(|e| Self::without_data(e, false));
        m.count() + s.count()
    }

    fn without_data(e: &EntityState, needs_flag: bool) -> bool {
        e.pose.is_none() || (needs_flag && e.flag.is_none())
    }

    /// Stamp of the latest own pose (lockstep: the simulator state this robot is at).
    pub fn own_pose_stamp(&self) -> Option<i64> {
        self.own.pose.and_then(|p| p.stamp)
    }

    fn each_entity(&self) -> impl Iterator<Item = (&EntityState, bool)> {
        // (state, needs a flag)
        self.machines
            .values()
            .map(|m| (m, true))
            .chain(self.storages.values().map(|s| (s, false)))
            .chain(self.peers.values().map(|r| (r, true)))
    }

    fn complete_at(e: &EntityState, needs_flag: bool, stamp: i64) -> bool {
        e.pose.and_then(|p| p.stamp) == Some(stamp)
            && (!needs_flag || e.flag.and_then(|f| f.stamp) == Some(stamp))
    }

    /// Lockstep: is everything of state `stamp` in? Own pose and has_part must carry
    /// `stamp`; so must every entity expected at this state: those that were part of the
    /// previous state `prev` (any sample stamped >= `prev`), or, before the first action,
    /// every entity with fresh data. An entity that left the simulator is therefore waited
    /// for once at most. Returns the number of expected entities still missing, or None
    /// when own data of `stamp` is not complete.
    pub fn lockstep_missing(&self, stamp: i64, prev: Option<i64>, now: f64) -> Option<usize> {
        if !Self::complete_at(&self.own, true, stamp) {
            return None;
        }
        if let (Some(v), Some(p)) = (&self.cells, self.own.pose) {
            return Some(v.missing_at(&self.me, p.value, &self.cfg.bound, stamp));
        }
        let (rt, st) = (self.cfg.stale_timeout_s, self.cfg.static_stale_timeout_s);
        let expected = |e: &EntityState, needs_flag: bool| match prev {
            Some(p) => {
                e.pose.and_then(|s| s.stamp).is_some_and(|s| s >= p)
                    || (needs_flag && e.flag.and_then(|s| s.stamp).is_some_and(|s| s >= p))
            }
            None => {
                // first state: every discovered entity, unless its data is known stale
                let t = if needs_flag { rt } else { st };
                e.pose.is_none() || Sample::fresh(&e.pose, now, t).is_some()
            }
        };
        Some(
            self.each_entity()
                .filter(|(e, f)| expected(e, *f) && !Self::complete_at(e, *f, stamp))
                .count(),
        )
    }

    /// Lockstep observation of state `stamp`: own data and every entity whose data carries
    /// exactly that stamp (what the simulator observation of that step holds).
    pub fn observation_at(&self, stamp: i64) -> Result<obs::ObsBuilder, OwnStale> {
        let own_pose = self.own.pose.ok_or(OwnStale::NoPose)?;
        let own_flag = self.own.flag.ok_or(OwnStale::NoHasPart)?;
        if own_pose.stamp != Some(stamp) {
            return Err(OwnStale::PoseStale);
        }
        if own_flag.stamp != Some(stamp) {
            return Err(OwnStale::HasPartStale);
        }
        if let Some(v) = &self.cells {
            let of_stamp = |s: &Sample<Arc<CellContent>>| s.stamp == Some(stamp);
            return Ok(self.observe_cells(v, own_pose.value, own_flag.value, of_stamp));
        }
        let f = |p: [f64; 2]| [p[0] as f32, p[1] as f32];
        let at = |s: &Option<Sample<[f64; 2]>>| s.filter(|p| p.stamp == Some(stamp));
        let flag_at = |s: &Option<Sample<bool>>| s.filter(|p| p.stamp == Some(stamp));
        Ok(obs::ObsBuilder {
            own_pos: f(own_pose.value),
            has_part: own_flag.value,
            machines: self
                .machines
                .values()
                .filter_map(|m| Some((f(at(&m.pose)?.value), flag_at(&m.flag)?.value)))
                .collect(),
            storages: self
                .storages
                .values()
                .filter_map(|s| Some(f(at(&s.pose)?.value)))
                .collect(),
            peers: self
                .peers
                .values()
                .filter_map(|r| Some((f(at(&r.pose)?.value), flag_at(&r.flag)?.value)))
                .collect(),
        }
        .bounded(&self.cfg.bound))
    }

    /// Fresh peer poses at `now`, and how many carry another stamp than `stamp`.
    pub fn peers_off_stamp(&self, stamp: i64, now: f64) -> (usize, usize) {
        let rt = self.cfg.stale_timeout_s;
        if let (Some(v), Some(p)) = (&self.cells, self.own.pose) {
            let fresh = |s: &Sample<Arc<CellContent>>| rt <= 0.0 || now - s.at <= rt;
            let all = v.gather(&self.me, p.value, fresh).peers.len();
            let on = v.gather(&self.me, p.value, |s| fresh(s) && s.stamp == Some(stamp));
            return (all, all - on.peers.len());
        }
        self.peers
            .values()
            .filter_map(|r| r.pose.filter(|p| rt <= 0.0 || now - p.at <= rt))
            .fold((0, 0), |(n, off), p| {
                (n + 1, off + usize::from(p.stamp != Some(stamp)))
            })
    }

    /// Known (ever seen) entity counts: machines, storages, peers.
    pub fn known(&self) -> (usize, usize, usize) {
        if let (Some(v), Some(p)) = (&self.cells, self.own.pose) {
            let g = v.gather(&self.me, p.value, |_| true);
            return (g.machines.len(), g.storages.len(), g.peers.len());
        }
        (self.machines.len(), self.storages.len(), self.peers.len())
    }
}

#[cfg(test)]
mod tests;
