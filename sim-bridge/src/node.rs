//! The DDS side of the bridge: cmd_vel discovery and readers, the step loop (what it
//! publishes is in [`crate::outputs`]).

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context as _;
use ros2_client::dds::rustdds::mio1::{Events, Interest, Poll, Token};
use ros2_client::dds::{Context, Node, Subscription};
use tracing::{info, warn};

use msgs::cells::CellGrid;
use msgs::topics::{self, robot, Entity, Leaf};
use msgs::{Profile, RosMessage, StdString, Twist};
use ros::{stamp_key_info, subscription, RosNode};

use crate::core::{CmdOutcome, Core, MetricsLine, WriterId};
use crate::delay::DelayQueue;
use crate::outputs::{Outputs, Recorder, StateFrame};
use crate::params::{BridgeParams, Mode};
use crate::watchdog::{NodeStage, Watchdog};

const COMMAND_TOKEN: Token = Token(usize::MAX - 1);

/// Commands typed on stdin (`-p stdin_commands:=true`), one per line.
fn stdin_lines() -> std::sync::mpsc::Receiver<String> {
    let (tx, rx) = std::sync::mpsc::channel();
    let _ = std::thread::Builder::new()
        .name("stdin-commands".into())
        .spawn(move || {
            use std::io::BufRead;
            for line in std::io::stdin().lock().lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
    rx
}

/// Run until `stop` is set or `max_steps` is reached; returns the last metrics.
pub fn run(p: BridgeParams, stop: &AtomicBool) -> anyhow::Result<MetricsLine> {
    run_watched(p, stop, &Watchdog::disabled())
}

/// [`run`], recording each start-up stage and every step-loop iteration in `wd` (whose
/// thread, started by the caller, ends a hung process).
pub fn run_watched(
    p: BridgeParams,
    stop: &AtomicBool,
    wd: &Watchdog,
) -> anyhow::Result<MetricsLine> {
    let t0 = Instant::now();
    wd.stage(NodeStage::Core);
    let mut core = Core::new(p.clone(), 0.0)?;
    wd.stage(NodeStage::Context);
    let ctx = ros::context(p.node.domain_id, p.node.enclave.as_deref())?;
    wd.stage(NodeStage::Node);
    let mut ros = RosNode::start(&ctx, &p.node.spec(), "ros2-spinner")?;
    let r = event_loop(&p, stop, &ctx, ros.node(), &mut core, t0, wd);
    wd.stage(NodeStage::Done);
    drop(ros); // stops the spinner
    r
}

fn event_loop(
    p: &BridgeParams,
    stop: &AtomicBool,
    ctx: &Context,
    node: &mut Node,
    core: &mut Core,
    t0: Instant,
    wd: &Watchdog,
) -> anyhow::Result<MetricsLine> {
    let mut b = Bridge::new(p, ctx, node, core, t0, wd)?;
    wd.stage(NodeStage::Running);
    while !stop.load(Ordering::SeqCst) {
        wd.beat();
        b.wait()?;
        let t = b.now_s();
        b.take_commands(t);
        b.discover();
        match p.mode {
            Mode::Realtime => b.step_realtime(t)?,
            Mode::Lockstep => b.step_lockstep(t)?,
        }
        b.send_due_frames();
        if b.core.done() {
            break;
        }
        b.metrics();
        b.flush_bag();
    }
    Ok(b.shutdown())
}

fn print_metrics(m: &MetricsLine) {
    if let Ok(s) = serde_json::to_string(m) {
        println!("{s}");
    }
}

/// The step loop's state: the core, the endpoints, the fault-injection queues and the
/// deadlines of each phase.
struct Bridge<'a> {
    p: &'a BridgeParams,
    ctx: &'a Context,
    node: &'a mut Node,
    core: &'a mut Core,
    wd: &'a Watchdog,
    /// Sim-bridge start: the core's clock (`now_s`) counts from here.
    t0: Instant,
    poll: Poll,
    events: Events,
    command_sub: Subscription<StdString>,
    cmd_subs: Vec<(String, Subscription<Twist>)>,
    out: Outputs,
    rec: Option<Recorder>,
    stdin_rx: Option<std::sync::mpsc::Receiver<String>>,
    /// test_cmd_delay_ms: received commands (robot, command, stamp, writer) waiting to
    /// reach the core.
    delayed: DelayQueue<(String, Twist, Option<i64>, WriterId)>,
    /// test_state_delay_ms: state frames waiting to be published.
    state_q: DelayQueue<StateFrame>,
    /// The robots of the setup: lockstep starts once all their cmd_vel are discovered.
    initial: Vec<String>,
    period: Duration,
    next_tick: Instant,
    next_discovery: Instant,
    metrics_period: Duration,
    next_metrics: Instant,
    /// Lockstep start: when every initial robot's cmd_vel was discovered (+ settle).
    all_discovered_at: Option<Instant>,
    /// The simulator steps (lockstep: the first state went out; realtime: every initial
    /// robot commands from state, see `wait_for_robots`).
    started: bool,
    /// Lockstep: when (s since start) the current state last went out, first or resent.
    state_sent_at: f64,
}

impl<'a> Bridge<'a> {
    /// Start-up: the fixed endpoints, a cmd_vel reader per initial robot, the recorder,
    /// and every entity's writers (with the first state in real time).
    fn new(
        p: &'a BridgeParams,
        ctx: &'a Context,
        node: &'a mut Node,
        core: &'a mut Core,
        t0: Instant,
        wd: &'a Watchdog,
    ) -> anyhow::Result<Self> {
        wd.stage(NodeStage::Endpoints);
        let grid = if p.cell_size > 0.0 {
            let room = core.env.config().world.room_size as f64;
            Some(CellGrid::new(room, p.cell_size).context("cell_size")?)
        } else {
            None
        };
        let out = Outputs::new(node, grid)?;
        let poll = Poll::new().context("mio poll")?;
        let mut command_sub: Subscription<StdString> =
            subscription(node, topics::COMMAND, Profile::RobotStream)?;
        poll.registry()
            .register(&mut command_sub, COMMAND_TOKEN, Interest::READABLE)?;
        let rec = match &p.record {
            Some(dir) => {
                let w = bag::BagWriter::create(dir)
                    .with_context(|| format!("creating the bag {}", dir.display()))?;
                info!("recording into {}", dir.display());
                Some(Recorder { w, errors: 0 })
            }
            None => None,
        };
        let delayed = DelayQueue::new(p.test_cmd_delay_ms);
        let state_q = DelayQueue::new(p.test_state_delay_ms);
        if delayed.is_active() || state_q.is_active() {
            warn!(
                "fault injection: cmd_vel held {} ms, state held {} ms",
                p.test_cmd_delay_ms, p.test_state_delay_ms
            );
        }
        let initial: Vec<String> = core.robot_names().cloned().collect();
        let t_start = Instant::now(); // placeholder, set below
        let metrics_period = Duration::from_secs_f64(p.metrics_period_s);
        let mut b = Bridge {
            p,
            ctx,
            node,
            core,
            wd,
            t0,
            poll,
            events: Events::with_capacity(256),
            command_sub,
            cmd_subs: Vec::new(),
            out,
            rec,
            stdin_rx: p.stdin_commands.then(stdin_lines),
            delayed,
            state_q,
            all_discovered_at: None,
            initial,
            period: Duration::from_secs_f64(1.0 / p.rate_hz),
            next_tick: t_start,
            next_discovery: t_start,
            metrics_period,
            next_metrics: t_start + metrics_period,
            started: p.mode == Mode::Realtime && !p.wait_for_robots,
            state_sent_at: 0.0,
        };
        for n in b.initial.clone() {
            b.subscribe_cmd(&n)?;
        }
        // the loop's clocks start once the readers exist
        let t_start = Instant::now();
        b.next_tick = t_start;
        b.next_discovery = t_start;
        b.next_metrics = t_start + metrics_period;
        if b.initial.is_empty() {
            b.all_discovered_at = Some(t_start);
        }
        info!(
            "sim_bridge up: setup {}, seed {}, mode {:?}, {} Hz, {} robots, cmd_vel timeout {} s (realtime), stale timeout {} s",
            p.setup,
            p.seed,
            p.mode,
            p.rate_hz,
            b.core.env.n_robots(),
            p.cmd_vel_timeout_s,
            p.stale_timeout_s
        );
        // Writers exist from the start, so readers have matched them before the first state
        // (a volatile sample sent before matching is lost).
        b.publish_state(p.mode == Mode::Realtime)?;
        Ok(b)
    }

    fn now_s(&self) -> f64 {
        self.t0.elapsed().as_secs_f64()
    }

    /// A cmd_vel reader for robot `name` (once), registered with mio.
    fn subscribe_cmd(&mut self, name: &str) -> anyhow::Result<()> {
        if self.cmd_subs.iter().any(|(n, _)| n == name) {
            return Ok(());
        }
        self.wd.beat(); // start-up progress: one reader per robot
        let mut s: Subscription<Twist> = subscription(
            self.node,
            &robot(name, Leaf::CmdVel).ros_name(),
            Profile::RobotStream,
        )?;
        self.poll
            .registry()
            .register(&mut s, Token(self.cmd_subs.len()), Interest::READABLE)?;
        self.cmd_subs.push((name.to_string(), s));
        Ok(())
    }

    /// Bring the writers up to date with the entities; with `send`, build the state and
    /// publish it now, or hold it (test_state_delay_ms).
    fn publish_state(&mut self, send: bool) -> anyhow::Result<()> {
        self.out.sync(self.ctx, self.node, self.core, self.wd)?;
        if !send {
            return Ok(());
        }
        let f = StateFrame::of(self.core, self.out.grid.as_ref());
        if self.state_q.is_active() {
            self.state_q.push(Instant::now(), f);
        } else {
            self.out.send(f, &mut self.rec);
        }
        Ok(())
    }

    /// Wait for a command or the next deadline (at most 50 ms, to notice `stop`).
    fn wait(&mut self) -> anyhow::Result<()> {
        let now = Instant::now();
        let mut deadline = self
            .next_discovery
            .min(self.next_metrics)
            .min(now + Duration::from_millis(50));
        if self.p.mode == Mode::Realtime {
            deadline = deadline.min(self.next_tick);
        }
        for due in [self.delayed.next_due(), self.state_q.next_due()]
            .into_iter()
            .flatten()
        {
            deadline = deadline.min(due);
        }
        let timeout = deadline.saturating_duration_since(now);
        if let Err(e) = self.poll.poll(&mut self.events, Some(timeout)) {
            if e.kind() != std::io::ErrorKind::Interrupted {
                return Err(e).context("mio poll");
            }
        }
        Ok(())
    }

    /// Commands in: every robot's cmd_vel (to the core, or held with test_cmd_delay_ms),
    /// then the typed commands of /tending/command and stdin.
    fn take_commands(&mut self, t: f64) {
        for (name, sub) in &self.cmd_subs {
            for _ in 0..1000 {
                match sub.take() {
                    Ok(Some((tw, info))) => {
                        if let Some(r) = self.rec.as_mut() {
                            r.put(&robot(name, Leaf::CmdVel).ros_name(), &tw);
                        }
                        let stamp = stamp_key_info(&info);
                        let writer = info.publisher_gid().to_bytes16();
                        if self.delayed.is_active() {
                            let item = (name.clone(), tw, stamp, writer);
                            self.delayed.push(Instant::now(), item);
                            continue;
                        }
                        on_cmd(self.core, name, &tw, stamp, writer, t);
                    }
                    Ok(None) => break,
                    Err(_) => self.core.on_undecodable_cmd(),
                }
            }
        }
        while let Some((name, tw, stamp, writer)) = self.delayed.pop_due(Instant::now()) {
            on_cmd(self.core, &name, &tw, stamp, writer, t);
        }
        let mut lines: Vec<String> = Vec::new();
        while let Ok(Some((line, _))) = self.command_sub.take() {
            lines.push(line.data);
        }
        if let Some(rx) = &self.stdin_rx {
            lines.extend(rx.try_iter().map(|l| l.trim().to_string()));
        }
        for line in lines.into_iter().filter(|l| !l.is_empty()) {
            if let Some(r) = self.rec.as_mut() {
                r.put(topics::COMMAND, &StdString { data: line.clone() });
            }
            match self.core.apply_command(&line, t) {
                Ok(s) => info!("command `{line}`: {s}"),
                Err(e) => warn!("command `{line}` refused: {e}"),
            }
        }
    }

    /// At each discovery period: a reader for every new robot's cmd_vel; in lockstep,
    /// note when every initial robot's cmd_vel has been seen.
    fn discover(&mut self) {
        if Instant::now() < self.next_discovery {
            return;
        }
        self.next_discovery = Instant::now() + Duration::from_secs_f64(self.p.discovery_period_s);
        for d in self.ctx.discovered_topics() {
            let Some(topic) = topics::parse_topic(&d.name) else {
                continue;
            };
            if topic.leaf != Leaf::CmdVel || d.type_name != Twist::DEF.dds_name() {
                continue;
            }
            if let Entity::Robot(name) = &topic.entity {
                if !self.cmd_subs.iter().any(|(n, _)| n == name) {
                    self.wd.stage(NodeStage::EntityEndpoints);
                    match self.subscribe_cmd(name) {
                        Ok(()) => info!("discovered /{name}/cmd_vel"),
                        Err(e) => warn!("cannot subscribe to /{name}/cmd_vel: {e:#}"),
                    }
                    self.wd.stage(NodeStage::Running);
                }
            }
        }
        if self.all_discovered_at.is_none() {
            let found: Vec<String> = self
                .ctx
                .discovered_topics()
                .iter()
                .filter_map(|d| topics::parse_topic(&d.name))
                .filter(|t| t.leaf == Leaf::CmdVel)
                .map(|t| t.entity.namespace())
                .collect();
            if self
                .initial
                .iter()
                .all(|n| found.iter().any(|f| f.trim_start_matches('/') == n))
            {
                info!("every initial robot's cmd_vel discovered");
                self.all_discovered_at = Some(Instant::now());
            }
        }
    }

    /// Real time: step at the rate, whatever the robots sent (once started: see
    /// `wait_for_robots`).
    fn step_realtime(&mut self, t: f64) -> anyhow::Result<()> {
        if Instant::now() < self.next_tick {
            return Ok(());
        }
        self.next_tick += self.period;
        if self.next_tick < Instant::now() {
            self.next_tick = Instant::now() + self.period;
        }
        if !self.started {
            let waiting = self.core.initial_robots_waiting();
            if !waiting.is_empty() && t < self.p.startup_grace_s {
                // the first state again, at the rate: robots still starting get it too
                return self.publish_state(true);
            }
            if waiting.is_empty() {
                info!("every initial robot commands from state: the simulator starts");
            } else {
                warn!(
                    "realtime start after {:.1} s without commands from {}",
                    self.p.startup_grace_s,
                    waiting.join(", ")
                );
            }
            self.started = true;
        }
        for n in self.core.expire(t) {
            info!("removed /{n}: cmd_vel stale");
        }
        for n in self.core.step(t, false)? {
            warn!(
                "/{n}: no cmd_vel for {} s (cmd_vel_timeout_s): commanding zero velocity",
                self.p.cmd_vel_timeout_s
            );
        }
        self.publish_state(true)
    }

    /// Lockstep (docs/adr/0003-lockstep.md): publish the first state once every initial
    /// robot is discovered (or the start-up grace ran out), then step when every robot
    /// answered the last state (or the wait timed out).
    fn step_lockstep(&mut self, t: f64) -> anyhow::Result<()> {
        if !self.started {
            let settled = self
                .all_discovered_at
                .is_some_and(|a| a.elapsed() >= Duration::from_secs_f64(self.p.settle_s));
            let gave_up = t >= self.p.startup_grace_s;
            if settled || gave_up {
                if !settled {
                    warn!("lockstep start without every initial robot discovered");
                }
                self.started = true;
                self.publish_state(true)?;
                self.core.mark_published(t);
                self.state_sent_at = t;
            }
            return Ok(());
        }
        let (all, timed_out) = self.core.lockstep_status(t);
        if all || timed_out {
            for n in self.core.expire(t) {
                info!("removed /{n}: cmd_vel stale");
            }
            self.core.step(t, !all)?;
            self.publish_state(true)?;
            self.core.mark_published(t);
            self.state_sent_at = t;
        } else if self.p.lockstep_resend_s > 0.0
            && t - self.state_sent_at >= self.p.lockstep_resend_s
        {
            // Same state, same stamps: a robot that already acted on it ignores it (and
            // resends its answer instead, robot_node's `lockstep_resend_s`).
            self.publish_state(true)?;
            self.core.count_state_resend();
            self.state_sent_at = t;
        }
        Ok(())
    }

    /// test_state_delay_ms: publish the held frames that are due.
    fn send_due_frames(&mut self) {
        while let Some(f) = self.state_q.pop_due(Instant::now()) {
            self.out.send(f, &mut self.rec);
        }
    }

    /// At each metrics period: the metrics line on stdout.
    fn metrics(&mut self) {
        if Instant::now() >= self.next_metrics {
            self.next_metrics += self.metrics_period;
            print_metrics(&self.core.metrics());
        }
    }

    fn flush_bag(&mut self) {
        if let Some(r) = self.rec.as_mut() {
            if let Err(e) = r.w.flush_due() {
                r.errors += 1;
                warn!("bag flush failed: {e:#}");
            }
        }
    }

    /// Finish the bag and print the final metrics; returns them.
    fn shutdown(mut self) -> MetricsLine {
        let m = self.core.metrics();
        if let Some(r) = self.rec.take() {
            let dir = r.w.dir().to_path_buf();
            match r.w.finish() {
                Ok(meta) => info!(
                    "bag {} finished: {} messages, {} recording errors",
                    dir.display(),
                    meta.message_count,
                    r.errors
                ),
                Err(e) => warn!("finishing the bag {} failed: {e:#}", dir.display()),
            }
        }
        print_metrics(&m);
        m
    }
}

/// A cmd_vel from `writer` to the core (logging a robot it spawned, and the first and
/// every power of two of the samples refused from a second writer).
fn on_cmd(core: &mut Core, name: &str, tw: &Twist, stamp: Option<i64>, writer: WriterId, t: f64) {
    let changes = core.counters.cmd_writer_changes;
    match core.on_cmd_from(name, tw, stamp, writer, t) {
        CmdOutcome::Spawned(id) => info!("spawned a body (id {}) for /{name}", id.0),
        CmdOutcome::DroppedForeignWriter => {
            let n = core.counters.cmds_foreign_writer;
            if n.is_power_of_two() {
                warn!(
                    "/{name}/cmd_vel: refused a command from a second writer ({n} so far): \
                     another fleet's robot or another node commands /{name} on ROS domain {}",
                    core.p.node.domain_id
                );
            }
        }
        _ if core.counters.cmd_writer_changes > changes => {
            info!("/{name}/cmd_vel: a new writer took over (the previous one fell silent)")
        }
        _ => {}
    }
}
