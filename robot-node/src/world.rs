//! What the robot knows about the world: the latest validated sample of every input,
//! with its arrival time, and the staleness rules that turn it into an observation.
//!
//! Times are seconds on a monotonic clock chosen by the caller (the node uses wall time
//! since start), so this module is deterministic and testable without DDS.

use std::collections::BTreeMap;

use msgs::{Entity, EntityTopic, Leaf, PoseStamped, RoomBounds};

/// A value and when it arrived.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample<T> {
    pub value: T,
    pub at: f64,
    /// Simulator step stamp (microseconds, [`msgs::dds::stamp_key_ns`]): a pose's header
    /// stamp, a flag's DDS source timestamp. Used in lockstep only.
    pub stamp: Option<i64>,
}

impl<T: Copy> Sample<T> {
    fn fresh(s: &Option<Sample<T>>, now: f64, timeout: f64) -> Option<T> {
        match s {
            Some(s) if timeout <= 0.0 || now - s.at <= timeout => Some(s.value),
            _ => None,
        }
    }
}

#[derive(Debug, Clone, Default)]
struct EntityState {
    pose: Option<Sample<[f64; 2]>>,
    flag: Option<Sample<bool>>,
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
}

/// Counters of everything received, dropped and done; logged periodically and on exit.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Counters {
    pub accepted: u64,
    pub dropped_decode: u64,
    pub dropped_non_finite: u64,
    pub dropped_out_of_room: u64,
    pub dropped_unexpected: u64,
    pub ticks: u64,
    pub commands: u64,
    pub zero_own_stale: u64,
    pub zero_obs_invalid: u64,
    pub zero_controller_error: u64,
    pub zero_bad_output: u64,
    pub publish_errors: u64,
    pub subscriptions: u64,
    /// Lockstep: states acted on before every expected entity of that stamp was in.
    pub lockstep_wait_timeouts: u64,
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
        }
    }
    pub fn dropped(&self) -> u64 {
        self.dropped_decode
            + self.dropped_non_finite
            + self.dropped_out_of_room
            + self.dropped_unexpected
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
        self.ticks += o.ticks;
        self.commands += o.commands;
        self.zero_own_stale += o.zero_own_stale;
        self.zero_obs_invalid += o.zero_obs_invalid;
        self.zero_controller_error += o.zero_controller_error;
        self.zero_bad_output += o.zero_bad_output;
        self.publish_errors += o.publish_errors;
        self.subscriptions += o.subscriptions;
        self.lockstep_wait_timeouts += o.lockstep_wait_timeouts;
        self.ticks_missed += o.ticks_missed;
        self.tick_late_max_us = self.tick_late_max_us.max(o.tick_late_max_us);
    }

    /// The counters as one JSON object (machine-readable stats line).
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "accepted": self.accepted,
            "dropped": {
                "decode": self.dropped_decode,
                "non_finite": self.dropped_non_finite,
                "out_of_room": self.dropped_out_of_room,
                "unexpected": self.dropped_unexpected,
            },
            "ticks": self.ticks,
            "commands": self.commands,
            "zero": {
                "own_stale": self.zero_own_stale,
                "obs_invalid": self.zero_obs_invalid,
                "controller_error": self.zero_controller_error,
                "bad_output": self.zero_bad_output,
            },
            "publish_errors": self.publish_errors,
            "subscriptions": self.subscriptions,
            "lockstep_wait_timeouts": self.lockstep_wait_timeouts,
            "ticks_missed": self.ticks_missed,
            "tick_late_max_us": self.tick_late_max_us,
        })
    }
}

impl std::fmt::Display for Counters {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "accepted={} dropped(decode={} non_finite={} out_of_room={} unexpected={}) \
             ticks={} commands={} zero(own_stale={} obs_invalid={} controller_error={} bad_output={}) \
             publish_errors={} subscriptions={} lockstep_wait_timeouts={} \
             ticks_missed={} tick_late_max_us={}",
            self.accepted,
            self.dropped_decode,
            self.dropped_non_finite,
            self.dropped_out_of_room,
            self.dropped_unexpected,
            self.ticks,
            self.commands,
            self.zero_own_stale,
            self.zero_obs_invalid,
            self.zero_controller_error,
            self.zero_bad_output,
            self.publish_errors,
            self.subscriptions,
            self.lockstep_wait_timeouts,
            self.ticks_missed,
            self.tick_late_max_us
        )
    }
}

/// Staleness and validation settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldConfig {
    /// Robots (own and peers): no sample for this long -> stale.
    pub stale_timeout_s: f64,
    /// Machines and storages; <= 0 = never stale.
    pub static_stale_timeout_s: f64,
    pub room: RoomBounds,
}

/// Latest data about self, machines, storages and peers.
#[derive(Debug, Clone)]
pub struct World {
    pub cfg: WorldConfig,
    /// This robot's id (namespace without the leading slash).
    pub me: String,
    own: EntityState,
    machines: BTreeMap<u32, EntityState>,
    storages: BTreeMap<u32, EntityState>,
    peers: BTreeMap<PeerKey, EntityState>,
}

/// Peers in natural order (`robot_2` before `robot_10`): the simulator's robot order when
/// robots are named `robot_<spawn index>`, so observations match the simulator's exactly.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
struct PeerKey {
    stem: String,
    index: Option<u64>,
    name: String,
}

impl PeerKey {
    fn new(name: &str) -> Self {
        let digits = name.len() - name.trim_end_matches(|c: char| c.is_ascii_digit()).len();
        let (stem, num) = name.split_at(name.len() - digits);
        Self {
            stem: stem.to_string(),
            index: num.parse().ok(),
            name: name.to_string(),
        }
    }
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
    pub fn new(me: &str, cfg: WorldConfig) -> Self {
        Self {
            cfg,
            me: me.trim_matches('/').to_string(),
            own: EntityState::default(),
            machines: BTreeMap::new(),
            storages: BTreeMap::new(),
            peers: BTreeMap::new(),
        }
    }

    fn slot(&mut self, entity: &Entity) -> &mut EntityState {
        match entity {
            Entity::Robot(r) if *r == self.me => &mut self.own,
            Entity::Robot(r) => self.peers.entry(PeerKey::new(r)).or_default(),
            Entity::Machine(j) => self.machines.entry(*j).or_default(),
            Entity::Storage(k) => self.storages.entry(*k).or_default(),
        }
    }

    /// A pose arrived on `topic`: validate and store it.
    pub fn on_pose(
        &mut self,
        topic: &EntityTopic,
        msg: &PoseStamped,
        now: f64,
    ) -> Result<(), DropReason> {
        if topic.leaf != Leaf::Pose {
            return Err(DropReason::Unexpected);
        }
        let xy = msgs::validate::pose_stamped(msg, &self.cfg.room).map_err(|e| match e {
            msgs::InvalidMsg::NonFinite { .. } => DropReason::NonFinite,
            msgs::InvalidMsg::OutOfRoom { .. } => DropReason::OutOfRoom,
        })?;
        let stamp = Some(msgs::dds::stamp_key_time(&msg.header.stamp));
        self.slot(&topic.entity).pose = Some(Sample {
            value: xy,
            at: now,
            stamp,
        });
        Ok(())
    }

    /// A Bool arrived on `topic` (`has_part` of a robot or `part_ready` of a machine).
    pub fn on_flag(
        &mut self,
        topic: &EntityTopic,
        value: bool,
        now: f64,
    ) -> Result<(), DropReason> {
        self.on_flag_stamped(topic, value, None, now)
    }

    /// A Bool arrived, with the step stamp of its DDS source timestamp.
    pub fn on_flag_stamped(
        &mut self,
        topic: &EntityTopic,
        value: bool,
        stamp: Option<i64>,
        now: f64,
    ) -> Result<(), DropReason> {
        match (&topic.entity, topic.leaf) {
            (Entity::Robot(_), Leaf::HasPart) | (Entity::Machine(_), Leaf::PartReady) => {}
            _ => return Err(DropReason::Unexpected),
        }
        self.slot(&topic.entity).flag = Some(Sample {
            value,
            at: now,
            stamp,
        });
        Ok(())
    }

    /// Build the observation input from fresh data only, or say why own data is unusable.
    ///
    /// A machine needs a fresh pose and part_ready, a storage a fresh pose, a peer a
    /// fresh pose and has_part; anything else is left out. Entities are ordered by id.
    pub fn observation(&self, now: f64) -> Result<obs::ObsBuilder, OwnStale> {
        let rt = self.cfg.stale_timeout_s;
        let st = self.cfg.static_stale_timeout_s;
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
        })
    }

    /// An entity was discovered (subscribed): lockstep expects its data from the first
    /// state on, even before a sample arrived.
    pub fn touch(&mut self, entity: &Entity) {
        self.slot(entity);
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
        })
    }

    /// Known (ever seen) entity counts: machines, storages, peers.
    pub fn known(&self) -> (usize, usize, usize) {
        (self.machines.len(), self.storages.len(), self.peers.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use msgs::topics::{machine, robot, storage};
    use msgs::{PoseStamped, Time};

    fn cfg() -> WorldConfig {
        WorldConfig {
            stale_timeout_s: 1.0,
            static_stale_timeout_s: 2.0,
            room: RoomBounds::default(),
        }
    }
    fn pose(x: f64, y: f64) -> PoseStamped {
        PoseStamped::planar(Time::default(), "map", x, y)
    }

    #[test]
    fn own_must_be_fresh() {
        let mut w = World::new("/robot_0", cfg());
        assert_eq!(w.observation(0.0).unwrap_err(), OwnStale::NoPose);
        w.on_pose(&robot("robot_0", Leaf::Pose), &pose(0.1, 0.2), 0.0)
            .unwrap();
        assert_eq!(w.observation(0.0).unwrap_err(), OwnStale::NoHasPart);
        w.on_flag(&robot("robot_0", Leaf::HasPart), true, 0.5)
            .unwrap();
        let o = w.observation(0.9).unwrap();
        assert_eq!(o.own_pos, [0.1, 0.2]);
        assert!(o.has_part);
        assert_eq!(w.observation(1.01).unwrap_err(), OwnStale::PoseStale);
        w.on_pose(&robot("robot_0", Leaf::Pose), &pose(0.1, 0.2), 1.0)
            .unwrap();
        assert_eq!(w.observation(1.6).unwrap_err(), OwnStale::HasPartStale);
    }

    #[test]
    fn entities_drop_out_when_stale() {
        let mut w = World::new("robot_0", cfg());
        w.on_pose(&robot("robot_0", Leaf::Pose), &pose(0.0, 0.0), 0.0)
            .unwrap();
        w.on_flag(&robot("robot_0", Leaf::HasPart), false, 0.0)
            .unwrap();
        w.on_pose(&machine(1, Leaf::Pose), &pose(0.5, 0.5), 0.0)
            .unwrap();
        // machine without part_ready is not observed yet
        assert!(w.observation(0.0).unwrap().machines.is_empty());
        w.on_flag(&machine(1, Leaf::PartReady), true, 0.0).unwrap();
        w.on_pose(&storage(0, Leaf::Pose), &pose(-1.0, 1.0), 0.0)
            .unwrap();
        w.on_pose(&robot("robot_1", Leaf::Pose), &pose(0.3, 0.0), 0.0)
            .unwrap();
        w.on_flag(&robot("robot_1", Leaf::HasPart), true, 0.0)
            .unwrap();
        let o = w.observation(0.5).unwrap();
        assert_eq!(o.machines, vec![([0.5, 0.5], true)]);
        assert_eq!(o.storages, vec![[-1.0, 1.0]]);
        assert_eq!(o.peers, vec![([0.3, 0.0], true)]);
        // keep own fresh; peer goes stale after 1 s, machine/storage after 2 s
        w.on_pose(&robot("robot_0", Leaf::Pose), &pose(0.0, 0.0), 1.5)
            .unwrap();
        w.on_flag(&robot("robot_0", Leaf::HasPart), false, 1.5)
            .unwrap();
        let o = w.observation(1.5).unwrap();
        assert!(o.peers.is_empty());
        assert_eq!(o.machines.len(), 1);
        let o = w.observation(2.4).unwrap();
        assert!(o.machines.is_empty() && o.storages.is_empty());
        assert_eq!(w.known(), (1, 1, 1));
    }

    #[test]
    fn static_timeout_can_be_disabled() {
        let mut c = cfg();
        c.static_stale_timeout_s = 0.0;
        let mut w = World::new("robot_0", c);
        w.on_pose(&storage(0, Leaf::Pose), &pose(-1.0, 1.0), 0.0)
            .unwrap();
        w.on_pose(&robot("robot_0", Leaf::Pose), &pose(0.0, 0.0), 100.0)
            .unwrap();
        w.on_flag(&robot("robot_0", Leaf::HasPart), false, 100.0)
            .unwrap();
        assert_eq!(w.observation(100.0).unwrap().storages.len(), 1);
    }

    #[test]
    fn bad_inputs_are_refused_and_do_not_overwrite() {
        let mut w = World::new("robot_0", cfg());
        let t = robot("robot_0", Leaf::Pose);
        w.on_pose(&t, &pose(0.2, 0.2), 0.0).unwrap();
        w.on_flag(&robot("robot_0", Leaf::HasPart), false, 0.0)
            .unwrap();
        let mut nan = pose(0.0, 0.0);
        nan.pose.position.x = f64::NAN;
        assert_eq!(w.on_pose(&t, &nan, 0.1), Err(DropReason::NonFinite));
        let mut q = pose(0.0, 0.0);
        q.pose.orientation.z = f64::INFINITY;
        assert_eq!(w.on_pose(&t, &q, 0.1), Err(DropReason::NonFinite));
        assert_eq!(
            w.on_pose(&t, &pose(5.0, 0.0), 0.1),
            Err(DropReason::OutOfRoom)
        );
        assert_eq!(
            w.on_flag(&machine(0, Leaf::Pose), true, 0.1),
            Err(DropReason::Unexpected)
        );
        assert_eq!(w.observation(0.2).unwrap().own_pos, [0.2, 0.2]);
    }
}
