//! A robot hosted by the node: its brain (world model, controller, counters), its
//! `cmd_vel` writer and its timing state, and what one control step of it does (wall
//! clock or sim time: [`tick_now`]; lockstep: [`lockstep_step`]).

use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use ros2_client::dds::{Context, Node, NodeLoggingHandle};
use ros2_client::log::LogLevel;
use ros2_client::rosout;
use tracing::{debug, info};

use msgs::topics::{self, Leaf};
use msgs::{Profile, Twist};
use ros::StampedWriter;

use crate::args::Params;
use crate::controller::Controller;
use crate::tick::{Brain, Outcome, TickResult};
use crate::watchdog::{retry, Watchdog};
use crate::world::{Counters, World, WorldModelConfig};

/// A hosted robot (name, controller, its k_speed).
pub(crate) type RobotSpec = (String, Box<dyn Controller>, f64);

/// One hosted robot: its brain (world model, controller, counters), its `cmd_vel` writer
/// and its timing state.
pub(crate) struct Hosted {
    pub(crate) me: String,
    /// Prefix of its log lines: empty with one robot per process, `robot_3: ` otherwise.
    pub(crate) tag: String,
    pub(crate) brain: Brain,
    pub(crate) cmd: StampedWriter<Twist>,
    /// Wall clock: when its next tick is due.
    pub(crate) next_tick: Instant,
    pub(crate) last_outcome: Option<Outcome>,
    /// Lockstep: the last state acted on, and the state waited for (since when).
    pub(crate) last_acted: Option<i64>,
    pub(crate) pending: Option<(i64, Instant)>,
    /// Lockstep: the command answering `last_acted`, and when it last went out.
    pub(crate) last_answer: Option<([f64; 2], Instant)>,
}

impl Hosted {
    pub(crate) fn publish(&mut self, v: [f64; 2], stamp: Option<i64>) {
        if self
            .cmd
            .write(Twist::planar(v[0], v[1]), stamp.map(|us| us * 1000))
            .is_err()
        {
            self.brain.counters.publish_errors += 1;
        }
    }
}

/// The hosted robots: each with its brain and its cmd_vel writer. cmd_vel carries the
/// stamp of the state it answers as its DDS source timestamp (lockstep); otherwise the
/// wall clock, like any ROS 2 publisher.
pub(crate) fn host(
    p: &Params,
    stop: &AtomicBool,
    ctx: &Context,
    node: &Node,
    robots: Vec<RobotSpec>,
    multi: bool,
    wd: &Watchdog,
) -> anyhow::Result<Vec<Hosted>> {
    let wcfg = WorldModelConfig {
        stale_timeout_s: p.perception.stale_timeout_s,
        static_stale_timeout_s: p.perception.static_stale_timeout_s,
        room: msgs::RoomBounds {
            half_extent: p.geometry.room_size / 2.0,
            margin: p.geometry.room_margin,
        },
        bound: p.perception.bound,
        cells: p.cell_grid()?.map(|g| (g, p.perception.cell_reach)),
    };
    let mut hosted: Vec<Hosted> = Vec::with_capacity(robots.len());
    let placeholder = Instant::now(); // set when the loop starts
    for (me, controller, k_speed) in robots {
        let cmd_name = topics::robot(&me, Leaf::CmdVel).ros_name();
        let cmd: StampedWriter<Twist> = retry("cmd_vel writer", stop, wd, || {
            StampedWriter::new(ctx, node, &cmd_name, Profile::RobotStream).context("cmd_vel writer")
        })?;
        hosted.push(Hosted {
            tag: if multi {
                format!("{me}: ")
            } else {
                String::new()
            },
            brain: Brain::new(World::new(&me, wcfg), controller, k_speed),
            me,
            cmd,
            next_tick: placeholder,
            last_outcome: None,
            last_acted: None,
            pending: None,
            last_answer: None,
        });
    }
    Ok(hosted)
}

/// Log a change of what a robot's ticks decide (not every tick).
fn log_outcome(h: &mut Hosted, log: &NodeLoggingHandle, r: &TickResult, what: &str) {
    if h.last_outcome
        .as_ref()
        .is_none_or(|l| !l.same_kind(&r.outcome))
    {
        match &r.outcome {
            Outcome::Command => rosout!(
                *log,
                LogLevel::Info,
                "{}{what}: observation counts {:?}",
                h.tag,
                r.counts
            ),
            other => rosout!(
                *log,
                LogLevel::Warn,
                "{}commanding zero velocity: {other:?}",
                h.tag
            ),
        }
    }
    h.last_outcome = Some(r.outcome.clone());
}

/// Wall clock or sim time: one control step of `h` now, and its command.
pub(crate) fn tick_now(h: &mut Hosted, log: &NodeLoggingHandle, now: f64) {
    // A command computed from state carries the stamp of the robot's own pose it used (as
    // in lockstep), so the bridge can tell robots that receive its state from robots that
    // only send zeros (`robots_on_state`, the fleet's health check); none otherwise.
    let (r, stamp) = h.brain.tick_once_per_state(now);
    h.publish(r.velocity, stamp);
    log_outcome(h, log, &r, "controlling");
}

/// Since when `h` has been waiting for state `s` to be whole (now, if `s` is new).
fn pending_since(h: &mut Hosted, s: i64) -> Instant {
    match h.pending {
        Some((ps, since)) if ps == s => since,
        _ => {
            let now = Instant::now();
            h.pending = Some((s, now));
            now
        }
    }
}

/// Real time with `act_on_state`: act once `h`'s own data and every expected entity of
/// a new state are in (or after `wait`, on the newest data then); true when it acted.
/// The same completeness rule as lockstep, but the bridge does not wait for the command.
/// A state stamped less than `min_gap_us` after the last one acted on is skipped: the
/// controller runs at most at the control rate however fast poses come (a localization
/// stream at 20-100 Hz), since its velocity estimates assume one period between states.
pub(crate) fn state_step(
    h: &mut Hosted,
    log: &NodeLoggingHandle,
    wait: Duration,
    min_gap_us: i64,
    now: f64,
) -> bool {
    let Some(s) = h.brain.world.own_pose_stamp() else {
        return false;
    };
    let last = h.brain.last_stamp();
    if last.is_some_and(|l| s < l) {
        info!("{}state stamps went back: resetting controller", h.tag);
        h.brain.reset();
        h.pending = None;
    }
    let last = h.brain.last_stamp();
    if last.is_some_and(|l| s - l < min_gap_us.max(1)) {
        return false;
    }
    let since = pending_since(h, s);
    // the previous state acted on tells which entities to expect (None: all fresh ones)
    let missing = h.brain.world.lockstep_missing(s, last, now);
    if missing != Some(0) && since.elapsed() < wait {
        return false;
    }
    if missing != Some(0) {
        h.brain.counters.state_wait_timeouts += 1;
    }
    let (r, stamp) = h.brain.act_now(now);
    h.publish(r.velocity, stamp);
    h.pending = None;
    log_outcome(h, log, &r, "controlling");
    true
}

/// Start-up, before the world settled: a zero command without a state stamp (the bridge's
/// start-up gate keeps waiting for this robot).
pub(crate) fn hold(h: &mut Hosted) {
    h.brain.counters.ticks += 1;
    h.brain.counters.zero_discovering += 1;
    h.publish([0.0, 0.0], None);
}

/// Real time with `act_on_state`, at the control timer: a heartbeat. Repeats the last
/// command while a new state is awaited or none came; acts on the newest data only when
/// there is no command to repeat (before the first state, or after own inputs were lost).
pub(crate) fn heartbeat(h: &mut Hosted, log: &NodeLoggingHandle, now: f64) {
    let (r, stamp) = match h.brain.repeat_last(now) {
        Some(r) => r,
        None => h.brain.act_now(now),
    };
    h.publish(r.velocity, stamp);
    log_outcome(h, log, &r, "controlling");
}

/// Lockstep timing: how long a state is waited for to be complete, and how often the
/// answer to it goes out again while no newer state comes (0: never).
#[derive(Debug, Clone, Copy)]
pub(crate) struct LockstepTiming {
    pub(crate) wait: Duration,
    pub(crate) resend: Duration,
}

/// Lockstep: act once `h`'s own data and every expected entity of the newest state are in
/// (or after `t.wait`). While no newer state comes, the answer goes out again every
/// `t.resend`: the bridge may not have received it (ADR 0029).
pub(crate) fn lockstep_step(h: &mut Hosted, log: &NodeLoggingHandle, t: LockstepTiming, now: f64) {
    let Some(s) = h.brain.world.own_pose_stamp() else {
        return;
    };
    if h.last_acted.is_some_and(|l| s < l) {
        info!("{}sim time went back: resetting controller", h.tag);
        h.brain.reset();
        h.last_acted = None;
        h.last_answer = None;
        h.pending = None;
    }
    if h.last_acted.is_some_and(|l| s <= l) {
        if h.last_acted == Some(s) && !t.resend.is_zero() {
            resend_answer(h, s, t.resend);
        }
        return;
    }
    let since = pending_since(h, s);
    let missing = h.brain.world.lockstep_missing(s, h.last_acted, now);
    let timed_out = since.elapsed() >= t.wait;
    if missing == Some(0) || timed_out {
        if missing != Some(0) {
            h.brain.counters.lockstep_wait_timeouts += 1;
            debug!(
                "{}lockstep: acting on {s} us with {missing:?} entities missing",
                h.tag
            );
        }
        let r = h.brain.tick_lockstep(s);
        h.publish(r.velocity, Some(s));
        h.last_acted = Some(s);
        h.last_answer = Some((r.velocity, Instant::now()));
        h.pending = None;
        log_outcome(h, log, &r, "controlling (lockstep)");
    }
}

/// Lockstep: the answer to state `s` again, if it went out `resend` ago or more.
fn resend_answer(h: &mut Hosted, s: i64, resend: Duration) {
    let Some((v, at)) = h.last_answer else {
        return;
    };
    if at.elapsed() >= resend {
        h.publish(v, Some(s));
        h.last_answer = Some((v, Instant::now()));
        h.brain.counters.lockstep_resends += 1;
    }
}

/// One machine-readable stats line on stdout (`-p stats_json:=true`).
pub(crate) fn print_stats_json(me: &str, c: &Counters, t0: Instant, last: bool) {
    use std::io::Write;
    let mut v = c.to_json();
    v["robot"] = me.into();
    v["uptime_s"] = t0.elapsed().as_secs_f64().into();
    v["final"] = last.into();
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{v}");
    let _ = out.flush();
}
