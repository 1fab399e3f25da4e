//! The node's event loop (docs/adr/0007-mio-event-loop.md) over the hosted robots with
//! their `cmd_vel` writers ([`crate::hosted`]) and one reader per input topic shared by
//! all of them ([`crate::readers`], docs/adr/0008-shared-readers.md): one method per
//! phase: wait, drain, discover, lockstep, tick (sim time or wall clock), stats, shutdown.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context as _};
use ros2_client::dds::rustdds::mio1::{Events, Interest, Poll, Token};
use ros2_client::dds::{Context, Node, NodeLoggingHandle, Subscription};
use ros2_client::log::LogLevel;
use ros2_client::rosout;
use tracing::{debug, info, warn};

use msgs::cells::Cell;
use msgs::topics::{self, Leaf};
use msgs::{Bool, Clock, EntityTopic, Path, PoseStamped, Profile, RoomBounds};
use ros::subscription;

use crate::args::Params;
use crate::fanout;
use crate::hosted::{
    heartbeat, hold, host, lockstep_step, print_stats_json, state_step, tick_now, Hosted,
    LockstepTiming, RobotSpec,
};
use crate::readers::{drain, Readers, Sub, SubKind};
use crate::watchdog::{retry, NodeStage, Watchdog};
use crate::world::{Counters, DropReason, World};

const CLOCK_TOKEN: Token = Token(usize::MAX - 1);

/// Readers are drained when their mio event fires, when a drain stopped at its bound, and
/// all of them at this period (a safety net: a missed wake-up costs at most this long).
const SWEEP_PERIOD: Duration = Duration::from_millis(100);

/// Start-up (not lockstep): the world settles once every hosted robot has its own pose,
/// every discovered entity has sent data and, for this long since both the last new
/// topic and the last own pose to arrive, no discovery scan added a topic (scans run
/// every 100 ms until then). Robots of a 20-robot fleet got their own
/// pose 0.05-0.4 s before they had discovered the machines, and acted blind to them
/// (docs/adr/0024-act-on-state.md).
const SETTLE_QUIET: Duration = Duration::from_millis(200);
/// ... or, quiet as above, this long after every own pose arrived with every discovered
/// machine and storage in but some peers still missing (a removed robot's topics can stay
/// discovered without data).
const SETTLE_MAX: Duration = Duration::from_secs(2);
/// ... or, with machines or storages still without data or discovery still adding topics,
/// this long: the robot acts blind to what it lacks only then (a machine removed before
/// it started may leave its topics behind).
/// A 20-robot fleet starting on a loaded 2-core machine settled at `SETTLE_MAX` with 5 of
/// 10 machines and all 4 storages still without data, and drove into those machines
/// (2026-12-03: 40-68 contact steps in 3 of 5 starts). The bridge holds the simulator
/// until every robot acts on state (its `startup_grace_s`, 10 s), so waiting costs no
/// motion.
const SETTLE_MAX_FIXTURES: Duration = Duration::from_secs(10);

/// The start-up rule above: may robots act, with `missing` discovered entities (of which
/// `fixtures` machines and storages) still without data, `waited` after every own pose?
fn settles(quiet: bool, missing: usize, fixtures: usize, waited: Duration) -> bool {
    (quiet && missing == 0)
        || (quiet && waited >= SETTLE_MAX && fixtures == 0)
        || waited >= SETTLE_MAX_FIXTURES
}

pub(crate) fn run(
    p: &Params,
    stop: &AtomicBool,
    ctx: &Context,
    node: &mut Node,
    robots: Vec<RobotSpec>,
    multi: bool,
    wd: &Watchdog,
) -> anyhow::Result<Counters> {
    let mut l = EventLoop::new(p, stop, ctx, node, robots, multi, wd)?;
    wd.stage(NodeStage::Running);
    while !stop.load(Ordering::SeqCst) {
        wd.beat();
        l.wait()?;
        let t = l.now_s();
        l.drain(t);
        l.discover();
        l.follow_cells();
        l.settle();
        if p.lockstep.enabled {
            l.lockstep();
        } else if l.clock_sub.is_some() {
            l.tick_sim_time();
        } else {
            if p.realtime.act_on_state {
                l.act_on_states();
            }
            l.tick_wall_clock();
        }
        l.stats();
    }
    Ok(l.shutdown())
}

/// The event loop's state: the hosted robots, the readers and the deadlines of each phase.
struct EventLoop<'a> {
    p: &'a Params,
    ctx: &'a Context,
    node: &'a mut Node,
    wd: &'a Watchdog,
    multi: bool,
    log: NodeLoggingHandle,
    poll: Poll,
    events: Events,
    hosted: Vec<Hosted>,
    readers: Readers,
    clock_sub: Option<Subscription<Clock>>,
    t0: Instant,
    period: Duration,
    /// How long a state is waited for to be complete: `lockstep_wait_s` in lockstep,
    /// `state_wait_s` in real time with `act_on_state`.
    state_wait: Duration,
    /// Lockstep: `lockstep_resend_s`.
    lockstep_resend: Duration,
    stats_period: Duration,
    next_discovery: Instant,
    next_sweep: Instant,
    next_stats: Instant,
    /// Sim time: last tick index = floor(t * rate), and the last clock value.
    sim_last_index: Option<i64>,
    sim_last_t: f64,
    /// Start-up: the world is complete enough to act on (always in lockstep, which has
    /// its own completeness rule), when every own pose had arrived, and when a discovery
    /// scan last added a topic.
    settled: bool,
    own_seen_at: Option<Instant>,
    last_new_topic_at: Instant,
    /// Cell mode: each hosted robot's cell and rings read when its cells were last
    /// subscribed.
    cell_of: Vec<Option<(Cell, u32)>>,
    room: RoomBounds,
}

impl<'a> EventLoop<'a> {
    /// Start-up: one cmd_vel writer per hosted robot, the readers of their own topics (and
    /// /clock with `use_sim_time`), the start-up line on rosout.
    fn new(
        p: &'a Params,
        stop: &AtomicBool,
        ctx: &'a Context,
        node: &'a mut Node,
        robots: Vec<RobotSpec>,
        multi: bool,
        wd: &'a Watchdog,
    ) -> anyhow::Result<Self> {
        wd.stage(NodeStage::Writers);
        let hosted = host(p, stop, ctx, node, robots, multi, wd)?;
        let log = node.logging_handle();
        let t0 = Instant::now();
        let stats_period = Duration::from_secs_f64(p.stats.period_s);
        let mut l = EventLoop {
            p,
            ctx,
            node,
            wd,
            multi,
            log,
            poll: Poll::new().context("mio poll")?,
            events: Events::with_capacity(1024),
            hosted,
            readers: Readers::default(),
            clock_sub: None,
            t0,
            period: Duration::from_secs_f64(1.0 / p.control.rate_hz),
            state_wait: Duration::from_secs_f64(if p.lockstep.enabled {
                p.lockstep.wait_s
            } else {
                p.realtime.state_wait_s
            }),
            lockstep_resend: Duration::from_secs_f64(p.lockstep.resend_s),
            stats_period,
            next_discovery: t0,
            next_sweep: t0,
            next_stats: t0 + stats_period,
            sim_last_index: None,
            sim_last_t: f64::NEG_INFINITY,
            settled: p.lockstep.enabled,
            own_seen_at: None,
            last_new_topic_at: t0,
            cell_of: Vec::new(),
            room: RoomBounds::default(),
        };
        l.cell_of = vec![None; l.hosted.len()];
        l.room = l.hosted[0].brain.world.cfg.room;
        wd.stage(NodeStage::Subscriptions);
        l.subscribe_own(stop)?;
        l.log_start();
        let n = l.hosted.len();
        for (i, h) in l.hosted.iter_mut().enumerate() {
            h.next_tick = t0 + fanout::tick_offset(i, n, l.period);
        }
        Ok(l)
    }

    fn now_s(&self) -> f64 {
        self.t0.elapsed().as_secs_f64()
    }

    /// Every hosted robot's own topics, read once for all (another hosted robot's own
    /// topics are a peer's for the rest), and /clock with `use_sim_time`.
    fn subscribe_own(&mut self, stop: &AtomicBool) -> anyhow::Result<()> {
        let own: Vec<EntityTopic> = self
            .hosted
            .iter()
            .flat_map(|h| [Leaf::Pose, Leaf::HasPart].map(|leaf| topics::robot(&h.me, leaf)))
            .collect();
        for t in own {
            self.readers.known.insert(t.clone());
            let wd = self.wd;
            retry("own subscription", stop, wd, || self.add_sub(t.clone()))?;
            fanout::touch(self.hosted.iter_mut().map(|h| &mut h.brain), &t);
        }
        if self.p.control.use_sim_time {
            let mut s = subscription::<Clock>(self.node, topics::CLOCK, Profile::Clock)?;
            self.poll
                .registry()
                .register(&mut s, CLOCK_TOKEN, Interest::READABLE)?;
            self.clock_sub = Some(s);
        }
        Ok(())
    }

    /// A reader on `topic` (a pose or a flag), registered with mio under its index.
    fn add_sub(&mut self, topic: EntityTopic) -> anyhow::Result<()> {
        let profile = topic
            .profile()
            .ok_or_else(|| anyhow!("no profile for {topic:?}"))?;
        let name = topic.ros_name();
        let token = Token(self.readers.subs.len());
        let registry = self.poll.registry();
        let kind = match topic.leaf {
            Leaf::Pose => {
                let mut s = subscription::<PoseStamped>(self.node, &name, profile)?;
                registry.register(&mut s, token, Interest::READABLE)?;
                SubKind::Pose(s, topic)
            }
            Leaf::HasPart | Leaf::PartReady => {
                let mut s = subscription::<Bool>(self.node, &name, profile)?;
                registry.register(&mut s, token, Interest::READABLE)?;
                SubKind::Flag(s, topic)
            }
            Leaf::CmdVel => return Err(anyhow!("robot_node does not subscribe to cmd_vel")),
        };
        debug!("subscribed to {name}");
        self.readers.subs.push(Sub { name, kind });
        Ok(())
    }

    /// Cell mode: a reader on `cell`'s topic, registered with mio under its index.
    fn add_cell_sub(&mut self, cell: Cell) -> anyhow::Result<()> {
        let name = cell.ros_name();
        let token = Token(self.readers.subs.len());
        let mut s = subscription::<Path>(self.node, &name, Profile::Cell)?;
        self.poll
            .registry()
            .register(&mut s, token, Interest::READABLE)?;
        debug!("subscribed to {name}");
        self.readers.subs.push(Sub {
            name,
            kind: SubKind::Cell(s, cell),
        });
        Ok(())
    }

    /// Cell mode: when a hosted robot enters another cell or widens its window, subscribe
    /// to the cells around it not read yet (a cell's topic is transient local: its latest
    /// state arrives at once), and close the readers of cells more than one ring outside
    /// every hosted robot's window (one ring of slack: a robot on a cell border does not
    /// churn).
    fn follow_cells(&mut self) {
        let mut moved = false;
        for i in 0..self.hosted.len() {
            let now_in = self.hosted[i].brain.world.own_cell();
            if now_in.is_none() || now_in == self.cell_of[i] {
                continue;
            }
            moved = true;
            self.cell_of[i] = now_in;
            for c in self.hosted[i].brain.world.cells_needed() {
                if self.readers.cells.contains(&c) {
                    continue;
                }
                match self.add_cell_sub(c) {
                    Ok(()) => {
                        self.readers.cells.insert(c);
                        self.readers.leftover.push(self.readers.subs.len() - 1);
                        self.last_new_topic_at = Instant::now();
                        info!("subscribed to cell {}", c.ros_name());
                    }
                    Err(e) => {
                        // retried when the robot next changes cell, or at the next scan
                        warn!("cannot subscribe to {} (will retry): {e:#}", c.ros_name());
                        self.cell_of[i] = None;
                    }
                }
            }
        }
        if moved && self.cell_of.iter().all(Option::is_some) {
            self.close_far_cells();
        }
    }

    fn close_far_cells(&mut self) {
        let windows: Vec<(Cell, u32)> = self.cell_of.iter().flatten().copied().collect();
        for sub in self.readers.subs.iter_mut() {
            let SubKind::Cell(_, c) = &sub.kind else {
                continue;
            };
            let c = *c;
            if windows.iter().any(|(w, r)| c.steps_to(w) <= r + 1) {
                continue;
            }
            if let SubKind::Cell(mut s, _) = std::mem::replace(&mut sub.kind, SubKind::Closed) {
                self.poll.registry().deregister(&mut s).ok();
            }
            self.readers.cells.remove(&c);
            debug!("closed the reader of cell {}", c.ros_name());
        }
    }

    fn log_start(&self) {
        let p = self.p;
        let who = if self.multi {
            format!(
                "{} hosting {} robots ({} .. {})",
                p.node.fully_qualified_name(),
                self.hosted.len(),
                self.hosted[0].me,
                self.hosted[self.hosted.len() - 1].me
            )
        } else {
            p.node.fully_qualified_name()
        };
        rosout!(
            self.log,
            LogLevel::Info,
            "robot_node {} up: domain {}, controller {}, {} Hz ({}), k_speed {} m/s, stale {} s / static {} s",
            who,
            p.node.domain_id,
            self.hosted[0].brain.controller.name(),
            p.control.rate_hz,
            if p.control.use_sim_time { "sim time from /clock" } else { "wall clock" },
            p.control.k_speed,
            p.perception.stale_timeout_s,
            p.perception.static_stale_timeout_s
        );
    }

    /// Wait for data or the next deadline (at most 100 ms, to notice `stop`; not at all
    /// when a reader was left with samples).
    fn wait(&mut self) -> anyhow::Result<()> {
        let now = Instant::now();
        let mut deadline = self
            .next_discovery
            .min(self.next_stats)
            .min(self.next_sweep)
            .min(now + Duration::from_millis(100));
        for h in &self.hosted {
            if self.clock_sub.is_none() {
                deadline = deadline.min(h.next_tick);
            }
            if let Some((_, since)) = h.pending {
                deadline = deadline.min(since + self.state_wait);
            }
        }
        let timeout = if self.readers.leftover.is_empty() {
            deadline.saturating_duration_since(now)
        } else {
            Duration::ZERO
        };
        if let Err(e) = self.poll.poll(&mut self.events, Some(timeout)) {
            if e.kind() != std::io::ErrorKind::Interrupted {
                return Err(e).context("mio poll");
            }
        }
        Ok(())
    }

    /// Drain the readers that have data (each sample once, fanned out to every hosted
    /// robot); every reader at each sweep.
    fn drain(&mut self, t: f64) {
        let r = &mut self.readers;
        r.todo.clear();
        if Instant::now() >= self.next_sweep {
            self.next_sweep = Instant::now() + SWEEP_PERIOD;
            r.todo.extend(0..r.subs.len());
            r.leftover.clear();
        } else {
            r.todo.append(&mut r.leftover);
            let n = r.subs.len();
            r.todo
                .extend(self.events.iter().map(|e| e.token().0).filter(|&i| i < n));
            r.todo.sort_unstable();
            r.todo.dedup();
        }
        for &i in &r.todo {
            if drain(
                &r.subs[i],
                &mut self.hosted,
                &self.room,
                t,
                &mut r.drops_seen,
            ) {
                r.leftover.push(i);
            }
        }
    }

    /// At each discovery period: a reader for every newly discovered contract topic.
    fn discover(&mut self) {
        let now = Instant::now();
        if now < self.next_discovery {
            return;
        }
        let period = Duration::from_secs_f64(self.p.perception.discovery_period_s);
        self.next_discovery = now
            + if self.settled {
                period
            } else {
                period.min(Duration::from_millis(100))
            };
        for d in self.ctx.discovered_topics() {
            let Some(topic) = topics::parse_topic(&d.name) else {
                continue;
            };
            if topic.leaf == Leaf::CmdVel || self.readers.known.contains(&topic) {
                continue;
            }
            if self.p.perception.cell_size > 0.0 {
                // cell mode: peers, machines and storages come from the cells
                continue;
            }
            let expected = topic.msg_def().map(|m| m.dds_name());
            if expected.as_deref() != Some(d.type_name.as_str()) {
                if self.readers.wrong_type_warned.insert(d.name.clone()) {
                    warn!(
                        "ignoring topic {} of type {} (expected {:?})",
                        d.name, d.type_name, expected
                    );
                }
                continue;
            }
            self.readers.known.insert(topic.clone());
            self.wd.stage(NodeStage::DiscoveredSubscription);
            let added = self.add_sub(topic.clone());
            self.wd.stage(NodeStage::Running);
            match added {
                Ok(()) => {
                    fanout::touch(self.hosted.iter_mut().map(|h| &mut h.brain), &topic);
                    // a new reader may hold samples before its first event is seen
                    self.readers.leftover.push(self.readers.subs.len() - 1);
                    self.last_new_topic_at = Instant::now();
                    info!("discovered {}", topic.ros_name());
                }
                Err(e) => {
                    // transient (e.g. RustDDS's entity channel full while many entities
                    // are created at once): retried at the next scan
                    if self.readers.sub_failed_warned.insert(topic.clone()) {
                        warn!(
                            "cannot subscribe to {} (will retry): {e:#}",
                            topic.ros_name()
                        );
                    }
                    self.readers.known.remove(&topic);
                }
            }
        }
        for h in self.hosted.iter_mut() {
            h.brain.counters.subscriptions = self.readers.open() as u64;
        }
    }

    /// Lockstep: act once per simulator state (docs/adr/0003-lockstep.md).
    fn lockstep(&mut self) {
        if let Some(clock) = self.clock_sub.as_ref() {
            while let Ok(Some(_)) = clock.take() {} // /clock is not used in lockstep
        }
        let timing = LockstepTiming {
            wait: self.state_wait,
            resend: self.lockstep_resend,
        };
        for h in self.hosted.iter_mut() {
            let now = self.t0.elapsed().as_secs_f64();
            lockstep_step(h, &self.log, timing, now);
        }
    }

    /// Start-up: settle the world (see [`SETTLE_QUIET`]) before any robot acts on it.
    fn settle(&mut self) {
        if self.settled
            || self
                .hosted
                .iter()
                .any(|h| h.brain.world.own_pose_stamp().is_none())
        {
            return;
        }
        let since = *self.own_seen_at.get_or_insert_with(Instant::now);
        let worlds = || self.hosted.iter().map(|h| &h.brain.world);
        let missing: usize = worlds().map(World::entities_without_data).sum();
        let fixtures: usize = worlds().map(World::fixtures_without_data).sum();
        // quiet since the last new topic and since every own pose was in: scans run every
        // 100 ms until settled, so two of them saw nothing new
        let quiet = self.last_new_topic_at.max(since).elapsed() >= SETTLE_QUIET;
        if settles(quiet, missing, fixtures, since.elapsed()) {
            self.settled = true;
            let (m, s, r) = self.hosted[0].brain.world.known();
            let msg = format!(
                "inputs settled {:.2} s after start: {m} machines, {s} storages, {r} peers \
                 known{}",
                self.t0.elapsed().as_secs_f64(),
                if fixtures > 0 {
                    format!(
                        " ({fixtures} machines/storages still without data after {} s: \
                         acting without them)",
                        SETTLE_MAX_FIXTURES.as_secs()
                    )
                } else if missing > 0 {
                    format!(" ({missing} peers without data yet)")
                } else {
                    String::new()
                }
            );
            let level = if fixtures > 0 {
                LogLevel::Warn
            } else {
                LogLevel::Info
            };
            rosout!(self.log, level, "{msg}");
        }
    }

    /// Real time with `act_on_state`: act on each new state once it is in; the control
    /// timer of a robot that acted restarts, so it only fires while no state comes.
    fn act_on_states(&mut self) {
        if !self.settled {
            return;
        }
        let now = self.t0.elapsed().as_secs_f64();
        // three quarters of a period: the bridge's states at the control rate all count,
        // jitter included; a faster pose stream is thinned to the control rate
        let min_gap_us = (0.75e6 / self.p.control.rate_hz) as i64;
        for h in self.hosted.iter_mut() {
            if state_step(h, &self.log, self.state_wait, min_gap_us, now) {
                // half a period of slack for the bridge's jitter before a repeat
                h.next_tick = Instant::now() + self.period.mul_f64(1.5);
            }
        }
    }

    /// `use_sim_time`: tick every hosted robot when /clock enters a new control period.
    fn tick_sim_time(&mut self) {
        let Some(clock) = self.clock_sub.as_ref() else {
            return;
        };
        let mut latest: Option<f64> = None;
        let mut undecodable = 0u64;
        loop {
            match clock.take() {
                Ok(Some((c, _))) => latest = Some(c.clock.as_secs_f64()),
                Ok(None) => break,
                Err(e) => {
                    debug!("dropped /clock sample: {e:?}");
                    undecodable += 1;
                }
            }
        }
        for h in self.hosted.iter_mut() {
            for _ in 0..undecodable {
                h.brain.counters.drop(DropReason::Decode);
            }
        }
        let Some(st) = latest else {
            return;
        };
        let went_back = st + 1e-9 < self.sim_last_t;
        if went_back {
            info!(
                "sim time went back ({} -> {st}): resetting controller",
                self.sim_last_t
            );
            self.sim_last_index = None;
        }
        self.sim_last_t = st;
        let idx = (st * self.p.control.rate_hz + 1e-6).floor() as i64;
        let skipped = match self.sim_last_index {
            Some(l) if idx > l + 1 => (idx - l - 1) as u64,
            _ => 0,
        };
        let due = self.sim_last_index.is_none_or(|l| idx > l);
        if due {
            self.sim_last_index = Some(idx);
        }
        let now = self.now_s();
        for h in self.hosted.iter_mut() {
            if went_back {
                h.brain.reset();
            }
            h.brain.counters.ticks_missed += skipped;
            if due && !self.settled {
                hold(h);
            } else if due {
                tick_now(h, &self.log, now);
            }
        }
    }

    /// Wall clock: tick each hosted robot whose period is due (their ticks are spread over
    /// the period, [`fanout::tick_offset`]).
    fn tick_wall_clock(&mut self) {
        let period = self.period;
        for h in self.hosted.iter_mut() {
            let now = Instant::now();
            if now < h.next_tick {
                continue;
            }
            let late = now - h.next_tick;
            let c = &mut h.brain.counters;
            c.tick_late_max_us = c.tick_late_max_us.max(late.as_micros() as u64);
            if late > period {
                // woke more than one period late: the skipped periods are missed ticks
                c.ticks_missed +=
                    (late.as_secs_f64() / period.as_secs_f64()).floor().max(1.0) as u64;
            }
            h.next_tick += period;
            if h.next_tick < now {
                h.next_tick = now + period; // overrun: skip, do not burst
            }
            let t = self.t0.elapsed().as_secs_f64();
            if !self.settled {
                hold(h);
            } else if self.p.realtime.act_on_state {
                heartbeat(h, &self.log, t);
            } else {
                tick_now(h, &self.log, t);
            }
        }
    }

    /// At each stats period: every hosted robot's counters in the log (and on stdout with
    /// `stats_json`).
    fn stats(&mut self) {
        if Instant::now() < self.next_stats {
            return;
        }
        self.next_stats += self.stats_period;
        for h in &self.hosted {
            let (m, s, r) = h.brain.world.known();
            info!(
                "counters {}: {} | known machines={m} storages={s} peers={r}",
                h.me, h.brain.counters
            );
            if self.p.stats.json {
                print_stats_json(&h.me, &h.brain.counters, self.t0, false);
            }
        }
    }

    /// Stop every robot (a zero cmd_vel each), report the final counters; their sum.
    fn shutdown(mut self) -> Counters {
        let mut total = Counters::default();
        for h in self.hosted.iter_mut() {
            h.publish([0.0, 0.0], None);
            rosout!(
                self.log,
                LogLevel::Info,
                "{}stopping: published zero cmd_vel",
                h.tag
            );
            info!("final counters {}: {}", h.me, h.brain.counters);
            if self.p.stats.json {
                print_stats_json(&h.me, &h.brain.counters, self.t0, true);
            }
            total.add(&h.brain.counters);
        }
        if self.multi {
            total.subscriptions = self.readers.open() as u64;
            info!("final counters (all robots): {total}");
        }
        // give the reliable writers a moment to deliver the zero commands before teardown
        let until = Instant::now() + Duration::from_millis(300);
        while Instant::now() < until {
            std::thread::sleep(Duration::from_millis(20));
        }
        if let Some(mut c) = self.clock_sub.take() {
            self.poll.registry().deregister(&mut c).ok();
        }
        total
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const QUIET: bool = true;

    #[test]
    fn robots_act_once_everything_discovered_has_data() {
        assert!(settles(QUIET, 0, 0, Duration::from_millis(300)));
        assert!(!settles(!QUIET, 0, 0, Duration::from_millis(300)));
        assert!(!settles(QUIET, 1, 0, Duration::from_millis(300)));
    }

    #[test]
    fn missing_peers_are_waited_for_briefly() {
        assert!(!settles(QUIET, 3, 0, SETTLE_MAX - Duration::from_millis(1)));
        assert!(settles(QUIET, 3, 0, SETTLE_MAX));
    }

    #[test]
    fn discovery_still_adding_topics_is_waited_for() {
        // machines not discovered yet cannot be counted as missing: a scan still finding
        // topics says the world is not complete
        assert!(!settles(!QUIET, 3, 0, SETTLE_MAX));
        assert!(settles(!QUIET, 3, 0, SETTLE_MAX_FIXTURES));
    }

    #[test]
    fn missing_machines_or_storages_are_waited_for_longer() {
        // the 2026-12-03 start-ups that touched machines had settled here
        assert!(!settles(QUIET, 9, 9, SETTLE_MAX));
        assert!(!settles(
            !QUIET,
            9,
            9,
            SETTLE_MAX_FIXTURES - Duration::from_millis(1)
        ));
        assert!(settles(QUIET, 9, 9, SETTLE_MAX_FIXTURES));
    }
}
