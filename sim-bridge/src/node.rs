//! The DDS side of the bridge: publishers per entity, cmd_vel discovery, the step loop.
#![allow(clippy::map_entry)] // writers are created fallibly before insertion

use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context as _};
use ros2_client::dds::rustdds::mio1::{Events, Interest, Poll, Token};
use ros2_client::dds::{Context, ContextOptions, Node, Publisher, Subscription};
use ros2_client::{Name, NodeName, NodeOptions};
use tracing::{info, warn};

use msgs::dds::{stamp_key_info, StampedWriter};
use msgs::topics::{self, machine, robot, storage, Entity, Leaf};
use msgs::{
    Bool, Clock, DiagnosticArray, MarkerArray, PoseStamped, Profile, RosMessage, StdString, Twist,
};

use crate::core::{Core, MetricsLine};
use crate::delay::DelayQueue;
use crate::params::{BridgeParams, Mode};
use crate::watchdog::{Stage, Watchdog};

fn dds_err<E: std::fmt::Debug>(what: &str) -> impl FnOnce(E) -> anyhow::Error + '_ {
    move |e| anyhow!("{what}: {e:?}")
}

fn publisher<M: RosMessage>(
    node: &mut Node,
    name: &str,
    profile: Profile,
) -> anyhow::Result<Publisher<M>> {
    let qos = profile.qos();
    let t = node
        .create_topic(
            &Name::parse(name).map_err(dds_err("topic name"))?,
            M::type_name(),
            &qos,
        )
        .map_err(dds_err("create topic"))?;
    node.create_publisher(&t, Some(qos))
        .map_err(dds_err("create publisher"))
}

fn subscription<M: RosMessage>(
    node: &mut Node,
    name: &str,
    profile: Profile,
) -> anyhow::Result<Subscription<M>> {
    let qos = profile.qos();
    let t = node
        .create_topic(
            &Name::parse(name).map_err(dds_err("topic name"))?,
            M::type_name(),
            &qos,
        )
        .map_err(dds_err("create topic"))?;
    node.create_subscription(&t, Some(qos))
        .map_err(dds_err("create subscription"))
}

struct EntityWriters {
    pose: StampedWriter<PoseStamped>,
    flag: Option<StampedWriter<Bool>>,
}

/// One step's outgoing state, built right after the step; published at once or, with
/// `-p test_state_delay_ms`, when it is due.
struct StateFrame {
    /// The step's stamp (sim time, ns): the source timestamp of every sample.
    ns: i64,
    robots: Vec<(String, PoseStamped, bool)>,
    machines: Vec<(u32, PoseStamped, bool)>,
    storages: Vec<(u32, PoseStamped)>,
    markers: MarkerArray,
    diag: DiagnosticArray,
    clock: Clock,
}

const COMMAND_TOKEN: Token = Token(usize::MAX - 1);

fn wall_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

/// `-p record:=DIR`: every message the bridge publishes and every cmd_vel and command it
/// receives, into a rosbag2 MCAP bag (log time = wall clock, like `tending record`).
struct Recorder {
    w: bag::BagWriter,
    errors: u64,
}

impl Recorder {
    fn put<M: RosMessage>(&mut self, topic: &str, msg: &M) {
        if let Err(e) = self.w.write_contract(topic, wall_ns(), msg) {
            self.errors += 1;
            if self.errors <= 5 || self.errors.is_power_of_two() {
                warn!("recording {topic} failed ({} errors): {e:#}", self.errors);
            }
        }
    }
}

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
    let now_s = || t0.elapsed().as_secs_f64();
    wd.stage(Stage::Core);
    let mut core = Core::new(p.clone(), 0.0)?;
    wd.stage(Stage::Context);
    let ctx = Context::with_options(ContextOptions::new().domain_id(p.domain_id))
        .map_err(dds_err("DDS context"))?;
    wd.stage(Stage::Node);
    let mut node = ctx
        .new_node(
            NodeName::new(&p.namespace, &p.node_name).map_err(dds_err("node name"))?,
            NodeOptions::new().enable_rosout(p.enable_rosout),
        )
        .map_err(dds_err("create node"))?;
    let spinner = node.spinner().map_err(dds_err("spinner"))?;
    let spin_thread = std::thread::Builder::new()
        .name("ros2-spinner".into())
        .spawn(move || {
            if let Err(e) = smol::block_on(spinner.spin()) {
                warn!("spinner stopped with error: {e:?}");
            }
        })?;
    let r = event_loop(&p, stop, &ctx, &mut node, &mut core, &now_s, wd);
    wd.stage(Stage::Done);
    drop(node);
    let _ = spin_thread.join();
    r
}

fn event_loop(
    p: &BridgeParams,
    stop: &AtomicBool,
    ctx: &Context,
    node: &mut Node,
    core: &mut Core,
    now_s: &dyn Fn() -> f64,
    wd: &Watchdog,
) -> anyhow::Result<MetricsLine> {
    wd.stage(Stage::Endpoints);
    let clock_pub: Publisher<Clock> = publisher(node, topics::CLOCK, Profile::Clock)?;
    let markers_pub: Publisher<MarkerArray> =
        publisher(node, topics::MARKERS, Profile::Visualization)?;
    let metrics_pub: Publisher<DiagnosticArray> =
        publisher(node, topics::METRICS, Profile::Visualization)?;

    let mut poll = Poll::new().context("mio poll")?;
    let mut events = Events::with_capacity(256);
    let mut command_sub: Subscription<StdString> =
        subscription(node, topics::COMMAND, Profile::RobotStream)?;
    poll.registry()
        .register(&mut command_sub, COMMAND_TOKEN, Interest::READABLE)?;

    let mut rec: Option<Recorder> = match &p.record {
        Some(dir) => {
            let w = bag::BagWriter::create(dir)
                .with_context(|| format!("creating the bag {}", dir.display()))?;
            info!("recording into {}", dir.display());
            Some(Recorder { w, errors: 0 })
        }
        None => None,
    };
    let stdin_rx = p.stdin_commands.then(stdin_lines);
    // test_cmd_delay_ms: received commands waiting to reach the core
    let mut delayed: DelayQueue<(String, Twist, Option<i64>)> =
        DelayQueue::new(p.test_cmd_delay_ms);
    // test_state_delay_ms: state frames waiting to be published
    let mut state_q: DelayQueue<StateFrame> = DelayQueue::new(p.test_state_delay_ms);
    if delayed.is_active() || state_q.is_active() {
        warn!(
            "fault injection: cmd_vel held {} ms, state held {} ms",
            p.test_cmd_delay_ms, p.test_state_delay_ms
        );
    }

    let mut cmd_subs: Vec<(String, Subscription<Twist>)> = Vec::new();
    let mut robots_w: BTreeMap<String, EntityWriters> = BTreeMap::new();
    let mut machines_w: HashMap<u32, EntityWriters> = HashMap::new();
    let mut storages_w: HashMap<u32, EntityWriters> = HashMap::new();

    let subscribe_cmd = |node: &mut Node,
                         poll: &Poll,
                         subs: &mut Vec<(String, Subscription<Twist>)>,
                         name: &str|
     -> anyhow::Result<()> {
        if subs.iter().any(|(n, _)| n == name) {
            return Ok(());
        }
        wd.beat(); // start-up progress: one reader per robot
        let mut s: Subscription<Twist> = subscription(
            node,
            &robot(name, Leaf::CmdVel).ros_name(),
            Profile::RobotStream,
        )?;
        poll.registry()
            .register(&mut s, Token(subs.len()), Interest::READABLE)?;
        subs.push((name.to_string(), s));
        Ok(())
    };
    let initial: Vec<String> = core.robot_names().cloned().collect();
    for n in &initial {
        subscribe_cmd(node, &poll, &mut cmd_subs, n)?;
    }

    // Build the current state of every entity (creating/dropping writers as entities come
    // and go; with `send` false only the writers); `send_frame` publishes a frame: entity
    // topics, then markers, metrics and /clock last.
    let prepare_state = |core: &Core,
                         node: &Node,
                         robots_w: &mut BTreeMap<String, EntityWriters>,
                         machines_w: &mut HashMap<u32, EntityWriters>,
                         storages_w: &mut HashMap<u32, EntityWriters>,
                         send: bool|
     -> anyhow::Result<Option<StateFrame>> {
        let stamp = core.stamp();
        let ns = stamp.sec as i64 * 1_000_000_000 + stamp.nanosec as i64;
        let pose =
            |c: [f32; 2]| PoseStamped::planar(stamp, topics::FRAME_ID, c[0] as f64, c[1] as f64);
        let states = core.robot_states();
        robots_w.retain(|n, _| states.iter().any(|s| &s.0 == n));
        for (name, _, _) in &states {
            if !robots_w.contains_key(name) {
                wd.beat(); // progress while creating many writers (100 robots at start-up)
                let w = EntityWriters {
                    pose: StampedWriter::new(
                        ctx,
                        node,
                        &robot(name, Leaf::Pose).ros_name(),
                        Profile::RobotStream,
                    )
                    .map_err(|e| anyhow!(e))?,
                    flag: Some(
                        StampedWriter::new(
                            ctx,
                            node,
                            &robot(name, Leaf::HasPart).ros_name(),
                            Profile::RobotStream,
                        )
                        .map_err(|e| anyhow!(e))?,
                    ),
                };
                robots_w.insert(name.clone(), w);
            }
        }
        let ms: Vec<_> = core.env.machines().collect();
        machines_w.retain(|j, _| ms.iter().any(|m| m.id.0 == *j));
        for m in &ms {
            let j = m.id.0;
            if !machines_w.contains_key(&j) {
                wd.beat();
                let w = EntityWriters {
                    pose: StampedWriter::new(
                        ctx,
                        node,
                        &machine(j, Leaf::Pose).ros_name(),
                        Profile::LatchedPose,
                    )
                    .map_err(|e| anyhow!(e))?,
                    flag: Some(
                        StampedWriter::new(
                            ctx,
                            node,
                            &machine(j, Leaf::PartReady).ros_name(),
                            Profile::PartReady,
                        )
                        .map_err(|e| anyhow!(e))?,
                    ),
                };
                machines_w.insert(j, w);
            }
        }
        let ss: Vec<_> = core.env.storages().collect();
        storages_w.retain(|k, _| ss.iter().any(|s| s.id.0 == *k));
        for s in &ss {
            let k = s.id.0;
            if !storages_w.contains_key(&k) {
                wd.beat();
                let w = EntityWriters {
                    pose: StampedWriter::new(
                        ctx,
                        node,
                        &storage(k, Leaf::Pose).ros_name(),
                        Profile::LatchedPose,
                    )
                    .map_err(|e| anyhow!(e))?,
                    flag: None,
                };
                storages_w.insert(k, w);
            }
        }
        if !send {
            return Ok(None);
        }
        Ok(Some(StateFrame {
            ns,
            robots: states
                .iter()
                .map(|(n, pos, has)| (n.clone(), pose(*pos), *has))
                .collect(),
            machines: ms
                .iter()
                .map(|m| (m.id.0, pose(m.centre), m.part_ready))
                .collect(),
            storages: ss.iter().map(|s| (s.id.0, pose(s.centre))).collect(),
            markers: core.markers(),
            diag: core.diagnostics(),
            clock: Clock { clock: stamp },
        }))
    };
    // An entity removed while its frame was held has no writer any more: skipped.
    let send_frame = |f: StateFrame,
                      robots_w: &BTreeMap<String, EntityWriters>,
                      machines_w: &HashMap<u32, EntityWriters>,
                      storages_w: &HashMap<u32, EntityWriters>,
                      rec: &mut Option<Recorder>| {
        let ns = f.ns;
        for (name, ps, has_part) in f.robots {
            let Some(w) = robots_w.get(&name) else {
                continue;
            };
            // flag first, then the pose (robot nodes key everything on the stamp anyway)
            if let Some(fl) = &w.flag {
                let _ = fl.write(Bool { data: has_part }, Some(ns));
            }
            if let Some(r) = rec.as_mut() {
                r.put(
                    &robot(&name, Leaf::HasPart).ros_name(),
                    &Bool { data: has_part },
                );
                r.put(&robot(&name, Leaf::Pose).ros_name(), &ps);
            }
            let _ = w.pose.write(ps, Some(ns));
        }
        for (j, ps, ready) in f.machines {
            let Some(w) = machines_w.get(&j) else {
                continue;
            };
            if let Some(fl) = &w.flag {
                let _ = fl.write(Bool { data: ready }, Some(ns));
            }
            if let Some(r) = rec.as_mut() {
                r.put(
                    &machine(j, Leaf::PartReady).ros_name(),
                    &Bool { data: ready },
                );
                r.put(&machine(j, Leaf::Pose).ros_name(), &ps);
            }
            let _ = w.pose.write(ps, Some(ns));
        }
        for (k, ps) in f.storages {
            let Some(w) = storages_w.get(&k) else {
                continue;
            };
            if let Some(r) = rec.as_mut() {
                r.put(&storage(k, Leaf::Pose).ros_name(), &ps);
            }
            let _ = w.pose.write(ps, Some(ns));
        }
        if let Some(r) = rec.as_mut() {
            r.put(topics::MARKERS, &f.markers);
            r.put(topics::METRICS, &f.diag);
            r.put(topics::CLOCK, &f.clock);
        }
        let _ = markers_pub.publish(f.markers);
        let _ = metrics_pub.publish(f.diag);
        let _ = clock_pub.publish(f.clock);
    };
    // Build the state and publish it now, or hold it (test_state_delay_ms).
    #[allow(clippy::too_many_arguments)]
    let publish_state = |core: &Core,
                         node: &Node,
                         robots_w: &mut BTreeMap<String, EntityWriters>,
                         machines_w: &mut HashMap<u32, EntityWriters>,
                         storages_w: &mut HashMap<u32, EntityWriters>,
                         rec: &mut Option<Recorder>,
                         state_q: &mut DelayQueue<StateFrame>,
                         send: bool|
     -> anyhow::Result<()> {
        if let Some(f) = prepare_state(core, node, robots_w, machines_w, storages_w, send)? {
            if state_q.is_active() {
                state_q.push(Instant::now(), f);
            } else {
                send_frame(f, robots_w, machines_w, storages_w, rec);
            }
        }
        Ok(())
    };

    let print_metrics = |m: &MetricsLine| {
        if let Ok(s) = serde_json::to_string(m) {
            println!("{s}");
        }
    };

    let period = Duration::from_secs_f64(1.0 / p.rate_hz);
    let t_start = Instant::now();
    let mut next_tick = t_start;
    let mut next_discovery = t_start;
    let metrics_period = Duration::from_secs_f64(p.metrics_period_s);
    let mut next_metrics = t_start + metrics_period;
    // lockstep start: when every initial robot's cmd_vel was discovered (+ settle)
    let mut all_discovered_at: Option<Instant> = if initial.is_empty() {
        Some(t_start)
    } else {
        None
    };
    let mut started = p.mode == Mode::Realtime;

    info!(
        "sim_bridge up: setup {}, seed {}, mode {:?}, {} Hz, {} robots",
        p.setup,
        p.seed,
        p.mode,
        p.rate_hz,
        core.env.n_robots()
    );
    // Writers exist from the start, so readers have matched them before the first state
    // (a volatile sample sent before matching is lost).
    publish_state(
        core,
        node,
        &mut robots_w,
        &mut machines_w,
        &mut storages_w,
        &mut rec,
        &mut state_q,
        p.mode == Mode::Realtime,
    )?;

    wd.stage(Stage::Running);
    while !stop.load(Ordering::SeqCst) {
        wd.beat();
        let now = Instant::now();
        let mut deadline = next_discovery
            .min(next_metrics)
            .min(now + Duration::from_millis(50));
        if p.mode == Mode::Realtime {
            deadline = deadline.min(next_tick);
        }
        for due in [delayed.next_due(), state_q.next_due()]
            .into_iter()
            .flatten()
        {
            deadline = deadline.min(due);
        }
        if let Err(e) = poll.poll(&mut events, Some(deadline.saturating_duration_since(now))) {
            if e.kind() != std::io::ErrorKind::Interrupted {
                return Err(e).context("mio poll");
            }
        }
        let t = now_s();

        // ---- commands in
        for (name, sub) in &cmd_subs {
            for _ in 0..1000 {
                match sub.take() {
                    Ok(Some((tw, info))) => {
                        if let Some(r) = rec.as_mut() {
                            r.put(&robot(name, Leaf::CmdVel).ros_name(), &tw);
                        }
                        if delayed.is_active() {
                            delayed.push(Instant::now(), (name.clone(), tw, stamp_key_info(&info)));
                            continue;
                        }
                        let o = core.on_cmd(name, &tw, stamp_key_info(&info), t);
                        if let crate::core::CmdOutcome::Spawned(id) = o {
                            info!("spawned a body (id {}) for /{name}", id.0);
                        }
                    }
                    Ok(None) => break,
                    Err(_) => core.on_undecodable_cmd(),
                }
            }
        }
        while let Some((name, tw, stamp)) = delayed.pop_due(Instant::now()) {
            if let crate::core::CmdOutcome::Spawned(id) = core.on_cmd(&name, &tw, stamp, t) {
                info!("spawned a body (id {}) for /{name}", id.0);
            }
        }
        let mut lines: Vec<String> = Vec::new();
        while let Ok(Some((line, _))) = command_sub.take() {
            lines.push(line.data);
        }
        if let Some(rx) = &stdin_rx {
            lines.extend(rx.try_iter().map(|l| l.trim().to_string()));
        }
        for line in lines.into_iter().filter(|l| !l.is_empty()) {
            if let Some(r) = rec.as_mut() {
                r.put(topics::COMMAND, &StdString { data: line.clone() });
            }
            match core.apply_command(&line, t) {
                Ok(s) => info!("command `{line}`: {s}"),
                Err(e) => warn!("command `{line}` refused: {e}"),
            }
        }

        // ---- discovery of cmd_vel topics
        if Instant::now() >= next_discovery {
            next_discovery = Instant::now() + Duration::from_secs_f64(p.discovery_period_s);
            for d in ctx.discovered_topics() {
                let Some(topic) = topics::parse_topic(&d.name) else {
                    continue;
                };
                if topic.leaf != Leaf::CmdVel || d.type_name != Twist::DEF.dds_name() {
                    continue;
                }
                if let Entity::Robot(name) = &topic.entity {
                    if !cmd_subs.iter().any(|(n, _)| n == name) {
                        wd.stage(Stage::EntityEndpoints);
                        match subscribe_cmd(node, &poll, &mut cmd_subs, name) {
                            Ok(()) => info!("discovered /{name}/cmd_vel"),
                            Err(e) => warn!("cannot subscribe to /{name}/cmd_vel: {e:#}"),
                        }
                        wd.stage(Stage::Running);
                    }
                }
            }
            if all_discovered_at.is_none() {
                let found: Vec<String> = ctx
                    .discovered_topics()
                    .iter()
                    .filter_map(|d| topics::parse_topic(&d.name))
                    .filter(|t| t.leaf == Leaf::CmdVel)
                    .map(|t| t.entity.namespace())
                    .collect();
                if initial
                    .iter()
                    .all(|n| found.iter().any(|f| f.trim_start_matches('/') == n))
                {
                    info!("every initial robot's cmd_vel discovered");
                    all_discovered_at = Some(Instant::now());
                }
            }
        }

        // ---- step
        match p.mode {
            Mode::Realtime => {
                if Instant::now() >= next_tick {
                    next_tick += period;
                    if next_tick < Instant::now() {
                        next_tick = Instant::now() + period;
                    }
                    for n in core.expire(t) {
                        info!("removed /{n}: cmd_vel stale");
                    }
                    core.step(t, false)?;
                    publish_state(
                        core,
                        node,
                        &mut robots_w,
                        &mut machines_w,
                        &mut storages_w,
                        &mut rec,
                        &mut state_q,
                        true,
                    )?;
                }
            }
            Mode::Lockstep => {
                if !started {
                    let settled = all_discovered_at
                        .is_some_and(|a| a.elapsed() >= Duration::from_secs_f64(p.settle_s));
                    let gave_up = t >= p.startup_grace_s;
                    if settled || gave_up {
                        if !settled {
                            warn!("lockstep start without every initial robot discovered");
                        }
                        started = true;
                        publish_state(
                            core,
                            node,
                            &mut robots_w,
                            &mut machines_w,
                            &mut storages_w,
                            &mut rec,
                            &mut state_q,
                            true,
                        )?;
                        core.mark_published(t);
                    }
                } else {
                    let (all, timed_out) = core.lockstep_status(t);
                    if all || timed_out {
                        for n in core.expire(t) {
                            info!("removed /{n}: cmd_vel stale");
                        }
                        core.step(t, !all)?;
                        publish_state(
                            core,
                            node,
                            &mut robots_w,
                            &mut machines_w,
                            &mut storages_w,
                            &mut rec,
                            &mut state_q,
                            true,
                        )?;
                        core.mark_published(t);
                    }
                }
            }
        }

        while let Some(f) = state_q.pop_due(Instant::now()) {
            send_frame(f, &robots_w, &machines_w, &storages_w, &mut rec);
        }

        if core.done() {
            break;
        }
        if Instant::now() >= next_metrics {
            next_metrics += metrics_period;
            print_metrics(&core.metrics());
        }
        if let Some(r) = rec.as_mut() {
            if let Err(e) = r.w.flush_due() {
                r.errors += 1;
                warn!("bag flush failed: {e:#}");
            }
        }
    }
    let m = core.metrics();
    if let Some(r) = rec.take() {
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
    Ok(m)
}
