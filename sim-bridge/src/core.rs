//! The DDS-free bridge: simulator, robot bodies by name, commands, staleness, lockstep
//! bookkeeping, run-time commands, metrics. `node` moves messages in and out of it.

use std::collections::{BTreeMap, HashMap};

use msgs::{Time, Twist};
use serde::Serialize;
use sim::{Env, MachineId, RobotId, ScenarioConfig, StorageId};

use crate::params::{BridgeParams, Mode};

/// The RTPS writer GUID of a sample (`MessageInfo::publisher_gid().to_bytes16()`).
pub type WriterId = [u8; 16];

/// The writer [`Core::on_cmd`] attributes its commands to (callers that do not know it).
pub const DEFAULT_WRITER: WriterId = [0; 16];

/// A robot body and the latest command for it.
#[derive(Debug, Clone)]
pub struct RobotSlot {
    pub id: RobotId,
    pub cmd: [f32; 2],
    /// Stamp key (us) of the state the latest command answers (its DDS source timestamp).
    pub cmd_stamp: Option<i64>,
    /// Wall time of the latest valid command.
    pub last_cmd_at: Option<f64>,
    pub created_at: f64,
    /// Spawned from the setup at start-up (gets the start-up grace period).
    pub initial: bool,
    /// Realtime: held at zero velocity since its latest command passed the command
    /// timeout (`cmd_vel_timeout_s`); cleared by the next command.
    pub timed_out: bool,
    /// The writer its cmd_vel is pinned to (the first valid one; see [`Core::on_cmd_from`]).
    pub writer: Option<WriterId>,
}

#[derive(Debug, Clone, Default, Serialize, PartialEq, Eq)]
pub struct BridgeCounters {
    pub cmds_accepted: u64,
    /// NaN / infinite Twists (never reach the simulator).
    pub cmds_dropped_non_finite: u64,
    /// Undecodable (wrong-size) Twists.
    pub cmds_dropped_decode: u64,
    /// Lockstep: commands answering an older state than the current one.
    pub cmds_late: u64,
    /// Lockstep: copies of an answer already received (robot_node resends its answer
    /// while the bridge has not moved on, ADR 0029); not late, never used again.
    pub cmds_repeated: u64,
    /// A first cmd_vel that could not spawn a body (no free spot).
    pub spawn_failures: u64,
    pub spawned: u64,
    pub despawned: u64,
    /// Lockstep: steps taken before every robot answered.
    pub lockstep_timeouts: u64,
    /// Lockstep: a state published again because some robot had not answered it after
    /// `lockstep_resend_s` (docs/adr/0029-lockstep-resends.md).
    pub state_resends: u64,
    /// Realtime: robot-steps a body was commanded zero velocity because its latest
    /// cmd_vel was older than `cmd_vel_timeout_s` (a dead or stalled robot_node; ADR 0031).
    pub cmd_timeout_steps: u64,
    /// Realtime: times a body's commands timed out (it was stopped).
    pub cmd_timeouts: u64,
    /// cmd_vel samples refused because they came from a second writer on a robot's topic
    /// while the robot's pinned writer was still commanding it: another fleet's robot of
    /// the same name, or any other node, on this domain (ADR 0032). `tending fleet`
    /// fails a run in which this is not zero.
    pub cmds_foreign_writer: u64,
    /// A robot's cmd_vel taken over by a new writer after the pinned one fell silent (a
    /// restarted robot_node).
    pub cmd_writer_changes: u64,
    pub commands_ok: u64,
    pub commands_failed: u64,
    /// Realtime: robot-steps by the age of the state the applied command answers, in
    /// steps: 0 = the state being stepped (what lockstep always has), 1 = the one before,
    /// 2, and 3 or more. Commands without a stamp are not counted. How far real time
    /// lags behind the observations its commands were computed from (RESULTS 7.11).
    pub cmd_age_0: u64,
    pub cmd_age_1: u64,
    pub cmd_age_2: u64,
    pub cmd_age_3plus: u64,
}

/// How old (sim seconds) the state a robot's latest command answers may be for the robot
/// to count in [`MetricsLine::robots_on_state`]: 10 steps at the paper's dt.
pub const ON_STATE_WINDOW_S: f64 = 1.0;

/// One metrics line (JSON on stdout, and `/tending/metrics`).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct MetricsLine {
    pub step: u32,
    pub sim_time: f64,
    pub robots: usize,
    pub machines: usize,
    pub storages: usize,
    pub parts_delivered: u32,
    pub parts_collected: u32,
    pub collisions: u32,
    /// `collisions` by kind (robot-steps in contact with a robot, machine, storage, wall).
    pub collisions_robot_robot: u32,
    pub collisions_robot_machine: u32,
    pub collisions_robot_storage: u32,
    pub collisions_robot_wall: u32,
    /// Collision events: a robot starting to touch something (`sim::Metrics`), the paper's
    /// count beside the contact steps above.
    pub collision_events: u32,
    pub p_max: u32,
    pub mu: f64,
    /// Robots whose latest command answers a state at most [`ON_STATE_WINDOW_S`] old: they
    /// receive this bridge's state and act on it (`tending fleet` checks it).
    pub robots_on_state: usize,
    #[serde(flatten)]
    pub counters: BridgeCounters,
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub done: bool,
}

/// What became of a cmd_vel.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CmdOutcome {
    Accepted,
    /// Accepted and a body was spawned for this namespace.
    Spawned(RobotId),
    DroppedNonFinite,
    DroppedLate,
    /// Lockstep: a copy of the answer to an older state the robot already gave.
    DroppedRepeated,
    /// From a writer other than the one the robot's commands are pinned to.
    DroppedForeignWriter,
    SpawnFailed(String),
}

pub struct Core {
    pub env: Env,
    pub p: BridgeParams,
    robots: BTreeMap<String, RobotSlot>,
    names: HashMap<RobotId, String>,
    pub counters: BridgeCounters,
    /// Lockstep: stamp key of the last published state, when, and the robots expected to
    /// answer it.
    published: Option<(i64, f64, Vec<String>)>,
}

/// Stamp key (us) of a time, the same rounding the robot nodes apply.
pub fn key_of(t: &Time) -> i64 {
    msgs::stamp::stamp_key_time(t)
}

impl Core {
    pub fn new(p: BridgeParams, now: f64) -> anyhow::Result<Self> {
        p.check()?;
        let cfg = match &p.config {
            Some(path) => ScenarioConfig::load(path)
                .map_err(|e| anyhow::anyhow!("scenario config {}: {e}", path.display()))?,
            None => ScenarioConfig::default(),
        };
        let mut env = Env::new(cfg, p.setup, p.seed)?;
        let mut robots = BTreeMap::new();
        let mut names = HashMap::new();
        let ids: Vec<RobotId> = env.robot_ids().to_vec();
        if p.spawn_initial {
            for (i, id) in ids.iter().enumerate() {
                let name = format!("robot_{i}");
                names.insert(*id, name.clone());
                robots.insert(
                    name,
                    RobotSlot {
                        id: *id,
                        cmd: [0.0; 2],
                        cmd_stamp: None,
                        last_cmd_at: None,
                        created_at: now,
                        initial: true,
                        timed_out: false,
                        writer: None,
                    },
                );
            }
        } else {
            for id in ids {
                env.remove_robot(id)?;
            }
        }
        Ok(Self {
            env,
            p,
            robots,
            names,
            counters: BridgeCounters::default(),
            published: None,
        })
    }

    pub fn sim_time(&self) -> f64 {
        self.env.steps() as f64 * self.env.config().world.dt as f64
    }
    pub fn stamp(&self) -> Time {
        Time::from_secs_f64(self.sim_time())
    }
    pub fn stamp_key(&self) -> i64 {
        key_of(&self.stamp())
    }
    pub fn robot_names(&self) -> impl Iterator<Item = &String> {
        self.robots.keys()
    }
    pub fn has_robot(&self, name: &str) -> bool {
        self.robots.contains_key(name)
    }
    pub fn done(&self) -> bool {
        self.p.max_steps > 0 && self.env.steps() as u64 >= self.p.max_steps
    }

    /// A cmd_vel from namespace `name` (without slash), stamped `stamp` (source timestamp
    /// key), received at wall time `now`, from [`DEFAULT_WRITER`].
    pub fn on_cmd(&mut self, name: &str, t: &Twist, stamp: Option<i64>, now: f64) -> CmdOutcome {
        self.on_cmd_from(name, t, stamp, DEFAULT_WRITER, now)
    }

    /// How long a robot's pinned writer must have been silent before another writer may
    /// take over its cmd_vel: realtime, the command timeout (the body has stopped by then);
    /// lockstep, which keeps a body without commands until the stale timeout, that.
    fn pin_release_s(&self) -> f64 {
        match self.p.mode {
            Mode::Realtime => self.p.cmd_vel_timeout_s,
            Mode::Lockstep => self.p.stale_timeout_s,
        }
    }

    /// [`Self::on_cmd`] from `writer` (the sample's RTPS writer GUID). A robot's cmd_vel
    /// is pinned to one writer, as robot_node pins its inputs (ADR 0004): the first valid
    /// command pins its writer; another writer's commands are refused while the pinned one
    /// commanded within [`Self::pin_release_s`] (counted, `cmds_foreign_writer`), and take
    /// over after that (`cmd_writer_changes`). Two writers on one robot's cmd_vel are two
    /// controllers: another fleet's robot of the same name on this domain (ADR 0032).
    pub fn on_cmd_from(
        &mut self,
        name: &str,
        t: &Twist,
        stamp: Option<i64>,
        writer: WriterId,
        now: f64,
    ) -> CmdOutcome {
        if msgs::validate::twist(t).is_err() {
            self.counters.cmds_dropped_non_finite += 1;
            return CmdOutcome::DroppedNonFinite;
        }
        // A command not computed from state carries its publisher's wall clock as source
        // timestamp (robot_node's zeros before it has state, any stock ROS 2 publisher):
        // far beyond sim time, so a stamp later than the current state answers none.
        // Counting those as answers released the start-up gate (ADR 0022) while robots
        // were still sending zeros, and kept such robots in `robots_on_state`.
        let stamp = stamp.filter(|&s| s <= self.stamp_key());
        let v = [t.linear.x as f32, t.linear.y as f32];
        if !(v[0].is_finite() && v[1].is_finite()) {
            self.counters.cmds_dropped_non_finite += 1;
            return CmdOutcome::DroppedNonFinite;
        }
        let mut outcome = CmdOutcome::Accepted;
        if !self.robots.contains_key(name) {
            match self.spawn(name, None, now) {
                Ok(id) => outcome = CmdOutcome::Spawned(id),
                Err(e) => {
                    self.counters.spawn_failures += 1;
                    return CmdOutcome::SpawnFailed(e);
                }
            }
        }
        let release = self.pin_release_s();
        let slot = self.robots.get_mut(name).expect("present or spawned");
        match slot.writer {
            None => slot.writer = Some(writer),
            Some(w) if w == writer => {}
            Some(_) if slot.last_cmd_at.is_none_or(|at| now - at > release) => {
                slot.writer = Some(writer);
                self.counters.cmd_writer_changes += 1;
            }
            Some(_) => {
                self.counters.cmds_foreign_writer += 1;
                return CmdOutcome::DroppedForeignWriter;
            }
        }
        if self.p.mode == Mode::Lockstep {
            if let Some((key, _, _)) = &self.published {
                if stamp.is_some_and(|s| s < *key) {
                    let slot = self.robots.get_mut(name).expect("present or spawned");
                    slot.last_cmd_at = Some(now); // still proof of life
                    if slot.cmd_stamp == stamp {
                        self.counters.cmds_repeated += 1;
                        return CmdOutcome::DroppedRepeated;
                    }
                    self.counters.cmds_late += 1;
                    return CmdOutcome::DroppedLate;
                }
            }
        }
        let slot = self.robots.get_mut(name).expect("present or spawned");
        slot.cmd = v;
        slot.cmd_stamp = stamp;
        slot.last_cmd_at = Some(now);
        slot.timed_out = false;
        self.counters.cmds_accepted += 1;
        outcome
    }

    pub fn on_undecodable_cmd(&mut self) {
        self.counters.cmds_dropped_decode += 1;
    }

    fn spawn(&mut self, name: &str, pos: Option<[f32; 2]>, now: f64) -> Result<RobotId, String> {
        let id = self.env.add_robot(pos).map_err(|e| e.to_string())?;
        self.names.insert(id, name.to_string());
        self.robots.insert(
            name.to_string(),
            RobotSlot {
                id,
                cmd: [0.0; 2],
                cmd_stamp: None,
                last_cmd_at: None,
                created_at: now,
                initial: false,
                timed_out: false,
                writer: None,
            },
        );
        self.counters.spawned += 1;
        Ok(id)
    }

    fn despawn(&mut self, name: &str) -> Result<(), String> {
        let slot = self
            .robots
            .remove(name)
            .ok_or_else(|| format!("no robot `{name}`"))?;
        self.names.remove(&slot.id);
        self.env.remove_robot(slot.id).map_err(|e| e.to_string())?;
        self.counters.despawned += 1;
        Ok(())
    }

    /// Remove bodies whose cmd_vel is stale; returns their names.
    pub fn expire(&mut self, now: f64) -> Vec<String> {
        let stale = self.p.stale_timeout_s;
        let grace = self.p.startup_grace_s.max(stale);
        let gone: Vec<String> = self
            .robots
            .iter()
            .filter(|(_, s)| {
                let deadline = match s.last_cmd_at {
                    Some(t) => t + stale,
                    None if s.initial => s.created_at + grace,
                    None => s.created_at + stale,
                };
                now > deadline
            })
            .map(|(n, _)| n.clone())
            .collect();
        for n in &gone {
            let _ = self.despawn(n);
        }
        gone
    }

    /// Lockstep: the current state was published at wall time `now`.
    pub fn mark_published(&mut self, now: f64) {
        let names = self.robots.keys().cloned().collect();
        self.published = Some((self.stamp_key(), now, names));
    }

    /// Lockstep: (every expected robot answered the published state, the wait timed out).
    pub fn lockstep_status(&self, now: f64) -> (bool, bool) {
        let Some((key, at, expected)) = &self.published else {
            return (false, false);
        };
        let all = expected.iter().all(|n| match self.robots.get(n) {
            None => true, // removed meanwhile
            Some(s) => s.cmd_stamp == Some(*key),
        });
        // The first state waits at least until the start-up grace: a robot may still be
        // finishing its DDS Security handshakes and key exchange, which under load take
        // longer than a step's timeout; the state is resent meanwhile (ADR 0029).
        let first = self.env.steps() == 0;
        let timed_out =
            now - at > self.p.lockstep_timeout_s && (!first || now >= self.p.startup_grace_s);
        (all, timed_out)
    }

    /// Lockstep: the published state goes out again (a robot had not answered it).
    pub fn count_state_resend(&mut self) {
        self.counters.state_resends += 1;
    }

    /// One simulator step with the current commands; returns the robots whose commands
    /// timed out at this step (realtime: stopped now, see [`Self::command_of`]).
    pub fn step(&mut self, now: f64, timed_out: bool) -> anyhow::Result<Vec<String>> {
        if timed_out {
            self.counters.lockstep_timeouts += 1;
        }
        let ids: Vec<RobotId> = self.env.robot_ids().to_vec();
        let mut cmds = Vec::with_capacity(ids.len());
        let mut stopped = Vec::new();
        for id in ids {
            let name = self.names[&id].clone();
            let (cmd, stopped_now) = self.command_of(&name, now);
            if stopped_now {
                stopped.push(name);
            }
            cmds.push(cmd);
        }
        self.env.step_velocities(&cmds)?;
        Ok(stopped)
    }

    /// The velocity robot `name` is commanded at this step, and whether its commands
    /// timed out just now. Lockstep: its command only if it answers the published state
    /// (else zero). Realtime: its latest command while at most `cmd_vel_timeout_s` old;
    /// zero after, so that the body brakes to a stop (the simulator's velocity tracker
    /// brakes a zero command within a step or two), as a base controller does on its
    /// command timeout; the body is removed later, at `stale_timeout_s` ([`Self::expire`]).
    fn command_of(&mut self, name: &str, now: f64) -> ([f32; 2], bool) {
        let key = self.published.as_ref().map(|p| p.0);
        let now_key = self.stamp_key();
        let dt_us = (self.env.config().world.dt as f64 * 1e6).max(1.0);
        let (mode, timeout) = (self.p.mode, self.p.cmd_vel_timeout_s);
        let s = self.robots.get_mut(name).expect("every body has a slot");
        let c = &mut self.counters;
        match mode {
            Mode::Lockstep => {
                let ok = key.is_some() && s.cmd_stamp == key;
                (if ok { s.cmd } else { [0.0; 2] }, false)
            }
            Mode::Realtime => match s.last_cmd_at {
                Some(t) if now - t <= timeout => {
                    if let Some(k) = s.cmd_stamp {
                        let age = ((now_key - k) as f64 / dt_us).round().max(0.0) as u64;
                        *match age {
                            0 => &mut c.cmd_age_0,
                            1 => &mut c.cmd_age_1,
                            2 => &mut c.cmd_age_2,
                            _ => &mut c.cmd_age_3plus,
                        } += 1;
                    }
                    (s.cmd, false)
                }
                Some(_) => {
                    c.cmd_timeout_steps += 1;
                    let first = !s.timed_out;
                    if first {
                        s.timed_out = true;
                        c.cmd_timeouts += 1;
                    }
                    ([0.0; 2], first)
                }
                None => ([0.0; 2], false),
            },
        }
    }

    /// A `/tending/command` line; returns a description of what was done.
    pub fn apply_command(&mut self, line: &str, now: f64) -> Result<String, String> {
        let r = self.apply_command_inner(line, now);
        match &r {
            Ok(_) => self.counters.commands_ok += 1,
            Err(_) => self.counters.commands_failed += 1,
        }
        r
    }

    fn apply_command_inner(&mut self, line: &str, now: f64) -> Result<String, String> {
        let w: Vec<&str> = line.split_whitespace().collect();
        let pos = |a: &[&str]| -> Result<Option<[f32; 2]>, String> {
            match a {
                [] => Ok(None),
                [x, y] => {
                    let x: f32 = x.parse().map_err(|_| format!("bad x `{x}`"))?;
                    let y: f32 = y.parse().map_err(|_| format!("bad y `{y}`"))?;
                    if x.is_finite() && y.is_finite() {
                        Ok(Some([x, y]))
                    } else {
                        Err("position must be finite".into())
                    }
                }
                _ => Err("expected no position or `x y`".into()),
            }
        };
        let id = |a: &[&str]| -> Result<u32, String> {
            match a {
                [i] => i.parse().map_err(|_| format!("bad id `{i}`")),
                _ => Err("expected one id".into()),
            }
        };
        match w.as_slice() {
            ["add_machine", rest @ ..] => {
                let m = self
                    .env
                    .add_machine(pos(rest)?)
                    .map_err(|e| e.to_string())?;
                Ok(format!("added machine_{}", m.0))
            }
            ["remove_machine", rest @ ..] => {
                let j = id(rest)?;
                self.env
                    .remove_machine(MachineId(j))
                    .map_err(|e| e.to_string())?;
                Ok(format!("removed machine_{j}"))
            }
            ["add_storage", rest @ ..] => {
                let s = self
                    .env
                    .add_storage(pos(rest)?)
                    .map_err(|e| e.to_string())?;
                Ok(format!("added storage_{}", s.0))
            }
            ["remove_storage", rest @ ..] => {
                let k = id(rest)?;
                self.env
                    .remove_storage(StorageId(k))
                    .map_err(|e| e.to_string())?;
                Ok(format!("removed storage_{k}"))
            }
            ["add_robot", name, rest @ ..] => {
                if !valid_name(name) || self.robots.contains_key(*name) {
                    return Err(format!("robot name `{name}` is invalid or taken"));
                }
                let id = self.spawn(name, pos(rest)?, now)?;
                Ok(format!("added {name} (body {})", id.0))
            }
            ["remove_robot", name] => {
                self.despawn(name)?;
                Ok(format!("removed {name}"))
            }
            _ => Err(format!("unknown command `{line}`")),
        }
    }

    pub fn metrics(&self) -> MetricsLine {
        let m = self.env.metrics();
        let c = self.env.counts();
        MetricsLine {
            step: self.env.steps(),
            sim_time: self.sim_time(),
            robots: c.robots,
            machines: c.machines,
            storages: c.storages,
            parts_delivered: m.parts_delivered,
            parts_collected: m.parts_collected,
            collisions: m.collisions,
            collisions_robot_robot: m.collisions_robot_robot,
            collisions_robot_machine: m.collisions_robot_machine,
            collisions_robot_storage: m.collisions_robot_storage,
            collisions_robot_wall: m.collisions_robot_wall,
            collision_events: m.collision_events,
            p_max: m.p_max,
            mu: m.utilization(),
            robots_on_state: self.robots_on_state(),
            counters: self.counters.clone(),
            done: self.done(),
        }
    }

    /// Robots whose latest command carries the stamp of a state at most
    /// [`ON_STATE_WINDOW_S`] of sim time older than the current one (robot_node stamps a
    /// command with its own pose's stamp when it computed it from state, none otherwise).
    pub fn robots_on_state(&self) -> usize {
        let oldest = self.stamp_key() - (ON_STATE_WINDOW_S * 1e6) as i64;
        self.robots
            .values()
            .filter(|s| s.cmd_stamp.is_some_and(|k| k >= oldest))
            .count()
    }

    /// Initial robots that have not yet sent a command computed from state (a stamped one):
    /// the realtime start waits for none (`wait_for_robots`).
    pub fn initial_robots_waiting(&self) -> Vec<&str> {
        self.robots
            .iter()
            .filter(|(_, s)| s.initial && s.cmd_stamp.is_none())
            .map(|(n, _)| n.as_str())
            .collect()
    }

    /// Robots by name: position and has_part.
    pub fn robot_states(&self) -> Vec<(String, [f32; 2], bool)> {
        self.env
            .robots()
            .map(|r| (self.names[&r.id].clone(), r.pos, r.has_part))
            .collect()
    }
}

fn valid_name(s: &str) -> bool {
    !s.is_empty()
        && !s.as_bytes()[0].is_ascii_digit()
        && s.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_')
        && !s.starts_with("machine_")
        && !s.starts_with("storage_")
        && s != "tending"
}

#[cfg(test)]
mod tests;
mod view;
