//! The DDS side: one ros2-client node per robot. Subscribes to its own pose/has_part,
//! discovers machines, storages and peers from topic discovery, ticks the [`Brain`] at the
//! control rate (wall clock, or `/clock` with `use_sim_time`) and publishes `cmd_vel`.
//!
//! Single-threaded event loop on a mio 1 `Poll` (every subscription is a mio source);
//! the ros2-client spinner (graph events, parameters, rosout discovery) runs on a
//! helper thread with a smol executor.

use std::collections::HashSet;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context as _};
use ros2_client::dds::rustdds::mio1::{Events, Interest, Poll, Token};
use ros2_client::dds::{Context, ContextOptions, Node, Subscription};
use ros2_client::log::LogLevel;
use ros2_client::{rosout, Name, NodeName, NodeOptions};
use tracing::{debug, info, warn};

use msgs::topics::{self, Leaf};
use msgs::{Bool, Clock, EntityTopic, PoseStamped, Profile, RosMessage, Twist};

use crate::args::{ControllerKind, Params};
use crate::controller::{Controller, GreedyController, PolicyController};
use crate::tick::{Brain, Outcome};
use crate::world::{Accepted, Counters, DropReason, World, WorldConfig, WriterId};
use msgs::dds::{stamp_key_info, StampedWriter};
use obs::greedy::GreedyParams;

/// Build the controller the parameters ask for, and the speed limit of its commands.
///
/// `policy`: a [`PolicyController`] from the checkpoint (a wrong or corrupt file is an
/// error naming the file and the problem); its k_speed comes from the checkpoint's
/// training metadata when present, else from the `k_speed` parameter.
pub fn make_controller(p: &Params) -> anyhow::Result<(Box<dyn Controller>, f64)> {
    match p.controller {
        ControllerKind::Greedy => {
            let gp = greedy_params(p);
            Ok((Box::new(GreedyController::new(gp)), p.k_speed))
        }
        ControllerKind::Policy => {
            let path = p.policy.as_ref().ok_or_else(|| {
                anyhow!("controller `policy` needs a checkpoint: -p policy:=PATH")
            })?;
            let (c, from_meta) = PolicyController::load(path, p.k_speed as f32)?;
            let k = c.k_speed as f64;
            info!(
                "policy {} loaded ({}), k_speed {k} m/s from {}",
                path.display(),
                "checkpoint",
                if from_meta {
                    "checkpoint metadata"
                } else {
                    "the k_speed parameter"
                }
            );
            Ok((Box::new(c), k))
        }
    }
}

/// The greedy controller's knowledge of the fleet: sizes, speed and control period.
pub fn greedy_params(p: &Params) -> GreedyParams {
    GreedyParams {
        robot_radius: p.robot_radius as f32,
        machine_half: [p.machine_half[0] as f32, p.machine_half[1] as f32],
        storage_half: [p.storage_half[0] as f32, p.storage_half[1] as f32],
        k_speed: p.k_speed as f32,
        dt: (1.0 / p.control_rate_hz) as f32,
    }
}

enum SubKind {
    Pose(Subscription<PoseStamped>),
    Flag(Subscription<Bool>),
}

struct Sub {
    topic: EntityTopic,
    kind: SubKind,
}

const CLOCK_TOKEN: Token = Token(usize::MAX - 1);

fn dds_err<E: std::fmt::Debug>(what: &str) -> impl FnOnce(E) -> anyhow::Error + '_ {
    move |e| anyhow!("{what}: {e:?}")
}

fn subscribe<M: RosMessage>(
    node: &mut Node,
    ros_name: &str,
    profile: Profile,
) -> anyhow::Result<Subscription<M>> {
    let name = Name::parse(ros_name).map_err(dds_err("topic name"))?;
    let qos = profile.qos();
    let topic = node
        .create_topic(&name, M::type_name(), &qos)
        .map_err(dds_err("create topic"))?;
    node.create_subscription::<M>(&topic, Some(qos))
        .map_err(dds_err("create subscription"))
}

/// Run the node until `stop` is set. Returns the final counters (summed over robots in
/// multi-robot mode).
pub fn run(p: &Params, stop: &AtomicBool) -> anyhow::Result<Counters> {
    if !p.robots.is_empty() {
        return run_many(p, stop);
    }
    let (controller, k_speed) = make_controller(p)?;
    let me = p.robot_id();
    if me.is_empty() {
        return Err(anyhow!(
            "no robot namespace: start with --ros-args -r __ns:=/robot_N"
        ));
    }
    let ctx = Context::with_options(ContextOptions::new().domain_id(p.domain_id))
        .map_err(dds_err("DDS context"))?;
    run_on(&ctx, p, stop, controller, k_speed)
}

/// Several robots in one process (`-p robots:=robot_0,robot_1,...`): one DDS context (one
/// participant: one set of RustDDS threads and sockets) shared by one node per robot, in
/// namespace `/<robot>`; each robot runs the single-robot event loop on its own thread.
/// Every robot still has its own subscriptions and controller.
fn run_many(p: &Params, stop: &AtomicBool) -> anyhow::Result<Counters> {
    let mut per = Vec::with_capacity(p.robots.len());
    for name in &p.robots {
        let mut q = p.clone();
        q.namespace = format!("/{name}");
        q.robots = Vec::new();
        let (controller, k_speed) = make_controller(&q).with_context(|| format!("robot {name}"))?;
        per.push((q, controller, k_speed));
    }
    let ctx = Context::with_options(ContextOptions::new().domain_id(p.domain_id))
        .map_err(dds_err("DDS context"))?;
    info!("{} robots in one process", per.len());
    let results: Vec<anyhow::Result<Counters>> = std::thread::scope(|s| {
        let handles: Vec<_> = per
            .into_iter()
            .enumerate()
            .map(|(i, (q, controller, k_speed))| {
                let ctx = &ctx;
                std::thread::Builder::new()
                    .name(q.robot_id())
                    .spawn_scoped(s, move || {
                        // staggered start: RustDDS queues entity creation on a bounded
                        // channel, which overflows when all robots create theirs at once
                        let until = Instant::now() + STAGGER * i as u32;
                        while Instant::now() < until && !stop.load(Ordering::SeqCst) {
                            std::thread::sleep(Duration::from_millis(10));
                        }
                        run_on(ctx, &q, stop, controller, k_speed)
                            .with_context(|| format!("robot {}", q.robot_id()))
                    })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| match h {
                Ok(h) => h
                    .join()
                    .unwrap_or_else(|_| Err(anyhow!("robot thread panicked"))),
                Err(e) => Err(anyhow!("cannot start a robot thread: {e}")),
            })
            .collect()
    });
    let mut total = Counters::default();
    for r in results {
        total.add(&r?);
    }
    info!("final counters (all robots): {total}");
    Ok(total)
}

/// Multi-robot mode: delay between the starts of two robots.
const STAGGER: Duration = Duration::from_millis(100);

/// Retry a DDS set-up step that can fail transiently (RustDDS reports a full internal
/// channel as a poisoned entity when many entities are created at once): 40 attempts,
/// 250 ms apart, unless stopping.
fn retry<T>(
    what: &str,
    stop: &AtomicBool,
    mut f: impl FnMut() -> anyhow::Result<T>,
) -> anyhow::Result<T> {
    let mut attempt = 1;
    loop {
        match f() {
            Ok(x) => return Ok(x),
            Err(e) if attempt < 40 && !stop.load(Ordering::SeqCst) => {
                if attempt == 1 {
                    warn!("{what}: {e:#} (retrying)");
                }
                attempt += 1;
                std::thread::sleep(Duration::from_millis(250));
            }
            Err(e) => return Err(e),
        }
    }
}

/// One robot's node on a (possibly shared) DDS context, until `stop` is set.
fn run_on(
    ctx: &Context,
    p: &Params,
    stop: &AtomicBool,
    controller: Box<dyn Controller>,
    k_speed: f64,
) -> anyhow::Result<Counters> {
    let me = p.robot_id();
    let (mut node, spinner) = retry("node", stop, || {
        let mut node = ctx
            .new_node(
                NodeName::new(&p.namespace, &p.node_name).map_err(dds_err("node name"))?,
                NodeOptions::new().enable_rosout(p.enable_rosout),
            )
            .map_err(dds_err("create node"))?;
        let spinner = node.spinner().map_err(dds_err("spinner"))?;
        Ok((node, spinner))
    })?;
    let spin_thread = std::thread::Builder::new()
        .name(format!("spin-{me}"))
        .spawn(move || {
            if let Err(e) = smol::block_on(spinner.spin()) {
                warn!("spinner stopped with error: {e:?}");
            }
        })?;

    let result = event_loop(p, stop, ctx, &mut node, controller, k_speed, &me);
    drop(node); // signals the spinner to stop
    if spin_thread.join().is_err() {
        warn!("spinner thread panicked");
    }
    result
}

fn event_loop(
    p: &Params,
    stop: &AtomicBool,
    ctx: &Context,
    node: &mut Node,
    controller: Box<dyn Controller>,
    k_speed: f64,
    me: &str,
) -> anyhow::Result<Counters> {
    let world = World::new(
        me,
        WorldConfig {
            stale_timeout_s: p.stale_timeout_s,
            static_stale_timeout_s: p.static_stale_timeout_s,
            room: msgs::RoomBounds {
                half_extent: msgs::validate::ROOM_HALF_EXTENT,
                margin: p.room_margin,
            },
        },
    );
    let mut brain = Brain::new(world, controller, k_speed);

    // cmd_vel carries the stamp of the state it answers as its DDS source timestamp
    // (lockstep); otherwise the wall clock, like any ROS 2 publisher.
    let cmd_name = topics::robot(me, Leaf::CmdVel).ros_name();
    let cmd_pub: StampedWriter<Twist> = retry("cmd_vel writer", stop, || {
        StampedWriter::new(ctx, node, &cmd_name, Profile::RobotStream)
            .map_err(|e| anyhow!("cmd_vel writer: {e}"))
    })?;

    let mut poll = Poll::new().context("mio poll")?;
    let mut events = Events::with_capacity(256);
    let mut subs: Vec<Sub> = Vec::new();
    let mut known: HashSet<EntityTopic> = HashSet::new();

    let add_sub = |node: &mut Node,
                   poll: &Poll,
                   subs: &mut Vec<Sub>,
                   topic: EntityTopic|
     -> anyhow::Result<()> {
        let profile = topic
            .profile()
            .ok_or_else(|| anyhow!("no profile for {topic:?}"))?;
        let name = topic.ros_name();
        let token = Token(subs.len());
        let kind = match topic.leaf {
            Leaf::Pose => {
                let mut s = subscribe::<PoseStamped>(node, &name, profile)?;
                poll.registry()
                    .register(&mut s, token, Interest::READABLE)?;
                SubKind::Pose(s)
            }
            Leaf::HasPart | Leaf::PartReady => {
                let mut s = subscribe::<Bool>(node, &name, profile)?;
                poll.registry()
                    .register(&mut s, token, Interest::READABLE)?;
                SubKind::Flag(s)
            }
            Leaf::CmdVel => return Err(anyhow!("robot_node does not subscribe to cmd_vel")),
        };
        debug!("subscribed to {name}");
        subs.push(Sub { topic, kind });
        Ok(())
    };

    for leaf in [Leaf::Pose, Leaf::HasPart] {
        let t = topics::robot(me, leaf);
        known.insert(t.clone());
        retry("own subscription", stop, || {
            add_sub(node, &poll, &mut subs, t.clone())
        })?;
    }
    let mut clock_sub: Option<Subscription<Clock>> = if p.use_sim_time {
        let mut s = subscribe::<Clock>(node, topics::CLOCK, Profile::Clock)?;
        poll.registry()
            .register(&mut s, CLOCK_TOKEN, Interest::READABLE)?;
        Some(s)
    } else {
        None
    };

    let log = node.logging_handle();
    rosout!(
        log,
        LogLevel::Info,
        "robot_node {} up: domain {}, controller {}, {} Hz ({}), k_speed {} m/s, stale {} s / static {} s",
        p.fully_qualified_name(),
        p.domain_id,
        brain.controller.name(),
        p.control_rate_hz,
        if p.use_sim_time { "sim time from /clock" } else { "wall clock" },
        p.k_speed,
        p.stale_timeout_s,
        p.static_stale_timeout_s
    );

    let t0 = Instant::now();
    let now_s = |t0: Instant| t0.elapsed().as_secs_f64();
    let period = Duration::from_secs_f64(1.0 / p.control_rate_hz);
    let mut next_tick = t0;
    let mut next_discovery = t0;
    let stats_period = Duration::from_secs_f64(p.stats_period_s);
    let mut next_stats = t0 + stats_period;
    let mut last_outcome: Option<Outcome> = None;
    let mut wrong_type_warned: HashSet<String> = HashSet::new();
    let mut sub_failed_warned: HashSet<EntityTopic> = HashSet::new();
    // sim time: last tick index = floor(t * rate), last clock value
    let mut sim_last_index: Option<i64> = None;
    let mut sim_last_t: f64 = f64::NEG_INFINITY;

    let publish = |brain: &mut Brain, v: [f64; 2], stamp: Option<i64>| {
        if cmd_pub
            .write(Twist::planar(v[0], v[1]), stamp.map(|us| us * 1000))
            .is_err()
        {
            brain.counters.publish_errors += 1;
        }
    };
    // lockstep: the last state acted on, and the state waited for (since when)
    let mut last_acted: Option<i64> = None;
    let mut pending: Option<(i64, Instant)> = None;
    let lockstep_wait = Duration::from_secs_f64(p.lockstep_wait_s);

    while !stop.load(Ordering::SeqCst) {
        // ---- wait for data or the next deadline (at most 100 ms, to notice `stop`)
        let now = Instant::now();
        let mut deadline = next_discovery
            .min(next_stats)
            .min(now + Duration::from_millis(100));
        if clock_sub.is_none() {
            deadline = deadline.min(next_tick);
        }
        if let Some((_, since)) = pending {
            deadline = deadline.min(since + lockstep_wait);
        }
        let timeout = deadline.saturating_duration_since(now);
        if let Err(e) = poll.poll(&mut events, Some(timeout)) {
            if e.kind() != std::io::ErrorKind::Interrupted {
                return Err(e).context("mio poll");
            }
        }

        // ---- drain every subscription (mio is edge triggered; draining all is cheap
        //      and avoids missing a wake-up)
        let t = now_s(t0);
        for sub in &subs {
            drain(sub, &mut brain, t);
        }

        // ---- discovery
        let now = Instant::now();
        if now >= next_discovery {
            next_discovery = now + Duration::from_secs_f64(p.discovery_period_s);
            for d in ctx.discovered_topics() {
                let Some(topic) = topics::parse_topic(&d.name) else {
                    continue;
                };
                if topic.leaf == Leaf::CmdVel || known.contains(&topic) {
                    continue;
                }
                let expected = topic.msg_def().map(|m| m.dds_name());
                if expected.as_deref() != Some(d.type_name.as_str()) {
                    if wrong_type_warned.insert(d.name.clone()) {
                        warn!(
                            "ignoring topic {} of type {} (expected {:?})",
                            d.name, d.type_name, expected
                        );
                    }
                    continue;
                }
                known.insert(topic.clone());
                match add_sub(node, &poll, &mut subs, topic.clone()) {
                    Ok(()) => {
                        brain.world.touch(&topic.entity);
                        brain.counters.subscriptions = subs.len() as u64;
                        info!("discovered {}", topic.ros_name());
                    }
                    Err(e) => {
                        // transient (e.g. RustDDS's entity channel full while many
                        // entities are created at once): retried at the next scan
                        if sub_failed_warned.insert(topic.clone()) {
                            warn!(
                                "cannot subscribe to {} (will retry): {e:#}",
                                topic.ros_name()
                            );
                        }
                        known.remove(&topic);
                    }
                }
            }
            brain.counters.subscriptions = subs.len() as u64;
        }

        // ---- lockstep: act once per simulator state (docs/adr/0003-lockstep.md)
        if p.lockstep {
            if let Some(clock) = clock_sub.as_ref() {
                while let Ok(Some(_)) = clock.take() {} // /clock is not used in lockstep
            }
            if let Some(s) = brain.world.own_pose_stamp() {
                if last_acted.is_some_and(|l| s < l) {
                    info!("sim time went back: resetting controller");
                    brain.reset();
                    last_acted = None;
                    pending = None;
                }
                if last_acted.is_none_or(|l| s > l) {
                    let since = match pending {
                        Some((ps, since)) if ps == s => since,
                        _ => {
                            let now = Instant::now();
                            pending = Some((s, now));
                            now
                        }
                    };
                    let missing = brain.world.lockstep_missing(s, last_acted, now_s(t0));
                    let timed_out = since.elapsed() >= lockstep_wait;
                    if missing == Some(0) || timed_out {
                        if missing != Some(0) {
                            brain.counters.lockstep_wait_timeouts += 1;
                            debug!("lockstep: acting on {s} us with {missing:?} entities missing");
                        }
                        let r = brain.tick_lockstep(s);
                        publish(&mut brain, r.velocity, Some(s));
                        last_acted = Some(s);
                        pending = None;
                        if last_outcome
                            .as_ref()
                            .is_none_or(|l| !l.same_kind(&r.outcome))
                        {
                            match &r.outcome {
                                Outcome::Command => rosout!(
                                    log,
                                    LogLevel::Info,
                                    "controlling (lockstep): observation counts {:?}",
                                    r.counts
                                ),
                                other => rosout!(
                                    log,
                                    LogLevel::Warn,
                                    "commanding zero velocity: {other:?}"
                                ),
                            }
                        }
                        last_outcome = Some(r.outcome);
                    }
                }
            }
        }

        // ---- tick
        let due = if p.lockstep {
            false
        } else if let Some(clock) = clock_sub.as_ref() {
            let mut latest: Option<f64> = None;
            loop {
                match clock.take() {
                    Ok(Some((c, _))) => latest = Some(c.clock.as_secs_f64()),
                    Ok(None) => break,
                    Err(e) => {
                        debug!("dropped /clock sample: {e:?}");
                        brain.counters.drop(DropReason::Decode);
                    }
                }
            }
            match latest {
                Some(st) => {
                    if st + 1e-9 < sim_last_t {
                        info!("sim time went back ({sim_last_t} -> {st}): resetting controller");
                        brain.reset();
                        sim_last_index = None;
                    }
                    sim_last_t = st;
                    let idx = (st * p.control_rate_hz + 1e-6).floor() as i64;
                    if let Some(l) = sim_last_index {
                        if idx > l + 1 {
                            brain.counters.ticks_missed += (idx - l - 1) as u64;
                        }
                    }
                    if sim_last_index.is_none_or(|l| idx > l) {
                        sim_last_index = Some(idx);
                        true
                    } else {
                        false
                    }
                }
                None => false,
            }
        } else {
            let now = Instant::now();
            if now >= next_tick {
                let late = now - next_tick;
                brain.counters.tick_late_max_us =
                    brain.counters.tick_late_max_us.max(late.as_micros() as u64);
                if late > period {
                    // woke more than one period late: the skipped periods are missed ticks
                    brain.counters.ticks_missed +=
                        (late.as_secs_f64() / period.as_secs_f64()).floor().max(1.0) as u64;
                }
                next_tick += period;
                if next_tick < now {
                    next_tick = now + period; // overrun: skip, do not burst
                }
                true
            } else {
                false
            }
        };
        if due {
            let r = brain.tick(now_s(t0));
            publish(&mut brain, r.velocity, None);
            let changed = last_outcome
                .as_ref()
                .is_none_or(|l| !l.same_kind(&r.outcome));
            if changed {
                match &r.outcome {
                    Outcome::Command => rosout!(
                        log,
                        LogLevel::Info,
                        "controlling: observation counts {:?}",
                        r.counts
                    ),
                    other => rosout!(log, LogLevel::Warn, "commanding zero velocity: {other:?}"),
                }
            }
            last_outcome = Some(r.outcome);
        }

        // ---- stats
        if Instant::now() >= next_stats {
            next_stats += stats_period;
            let (m, s, r) = brain.world.known();
            info!(
                "counters {me}: {} | known machines={m} storages={s} peers={r}",
                brain.counters
            );
            if p.stats_json {
                print_stats_json(me, &brain.counters, t0, false);
            }
        }
    }

    // ---- shutdown: stop the robot
    publish(&mut brain, [0.0, 0.0], None);
    rosout!(log, LogLevel::Info, "stopping: published zero cmd_vel");
    info!("final counters {me}: {}", brain.counters);
    if p.stats_json {
        print_stats_json(me, &brain.counters, t0, true);
    }
    // give the reliable writer a moment to deliver the zero command before teardown
    let until = Instant::now() + Duration::from_millis(300);
    while Instant::now() < until {
        std::thread::sleep(Duration::from_millis(20));
    }
    if let Some(mut c) = clock_sub.take() {
        poll.registry().deregister(&mut c).ok();
    }
    Ok(brain.counters)
}

/// One machine-readable stats line on stdout (`-p stats_json:=true`).
fn print_stats_json(me: &str, c: &Counters, t0: Instant, last: bool) {
    use std::io::Write;
    let mut v = c.to_json();
    v["robot"] = me.into();
    v["uptime_s"] = t0.elapsed().as_secs_f64().into();
    v["final"] = last.into();
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{v}");
    let _ = out.flush();
}

fn drain(sub: &Sub, brain: &mut Brain, now: f64) {
    // bounded, so a flood on one topic cannot starve the loop
    for _ in 0..1000 {
        let res = match &sub.kind {
            SubKind::Pose(s) => match s.take() {
                Ok(Some((m, info))) => Some(brain.world.on_pose_from(
                    &sub.topic,
                    &m,
                    writer_id(&info),
                    now,
                )),
                Ok(None) => None,
                Err(e) => {
                    debug!("undecodable sample on {}: {e:?}", sub.topic.ros_name());
                    Some(Err(DropReason::Decode))
                }
            },
            SubKind::Flag(s) => match s.take() {
                Ok(Some((m, info))) => Some(brain.world.on_flag_stamped(
                    &sub.topic,
                    m.data,
                    stamp_key_info(&info),
                    writer_id(&info),
                    now,
                )),
                Ok(None) => None,
                Err(e) => {
                    debug!("undecodable sample on {}: {e:?}", sub.topic.ros_name());
                    Some(Err(DropReason::Decode))
                }
            },
        };
        match res {
            None => return,
            Some(Ok(a)) => {
                brain.counters.accepted += 1;
                if a == Accepted::NewWriter {
                    brain.counters.writer_changes += 1;
                    warn!(
                        "{}: the pinned writer's data went stale; now pinned to a new writer",
                        sub.topic.ros_name()
                    );
                }
            }
            Some(Err(r)) => {
                if brain.counters.dropped() < 20 || brain.counters.dropped().is_power_of_two() {
                    warn!("dropped a sample on {}: {r:?}", sub.topic.ros_name());
                }
                brain.counters.drop(r);
            }
        }
    }
}

/// The DDS writer a received sample came from (its GUID).
fn writer_id(info: &ros2_client::message_info::MessageInfo) -> WriterId {
    info.publisher_gid().to_bytes16()
}
