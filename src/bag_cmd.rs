//! `tending bag ...` and `tending record`: rosbag2 MCAP bags of a fleet (see the `bag` crate
//! and docs/adr/0002-rosbag-mcap.md).
//!
//! * `bag info`: topics, types, QoS, counts, duration.
//! * `bag metrics`: parts delivered, collisions, MU and robots over time, from
//!   `/tending/metrics` when recorded and independently from `has_part` transitions
//!   (true -> false = a delivery, false -> true = a pick) and pose topics.
//! * `bag recover`: rewrite a bag cut by SIGKILL into a complete one.
//! * `bag render`: GIF/SVG/PNG frames of the poses and part_ready flags.
//! * `bag play`: republish every message with its topic's original QoS and timing.
//! * `record`: subscribe to every contract topic found by discovery and write a bag until
//!   Ctrl-C / SIGTERM (the bag is finalized on both) or `--duration`.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Result};
use bag::{BagReader, BagWriter};
use clap::{Args, Subcommand};
use msgs::topics::{self, Entity, Leaf};
use msgs::{
    schema, Bool, Clock, DiagnosticArray, MarkerArray, MsgDef, PoseStamped, Profile, RosMessage,
    StdString, Time, Twist,
};
use ros2_client::dds::{Node, Publisher, Subscription};
use ros2_client::qos::{Durability, History, Reliability};
use ros2_client::QosProfile;

#[derive(Args)]
pub struct BagArgs {
    #[command(subcommand)]
    cmd: BagCmd,
}

#[derive(Subcommand)]
enum BagCmd {
    /// Topics, types, QoS, message counts, duration and completeness of a bag.
    Info { bag: PathBuf },
    /// Parts delivered, collisions, MU and robots over time, recomputed from the bag alone.
    Metrics {
        bag: PathBuf,
        /// Table row period, seconds of bag time.
        #[arg(long, default_value_t = 1.0)]
        period: f64,
    },
    /// Rewrite a bag cut by SIGKILL (no summary/footer) into a complete bag directory.
    Recover { input: PathBuf, output: PathBuf },
    /// Draw robots, machines and storages from the poses: .gif, .svg (last frame) or a
    /// directory of PNG frames.
    Render {
        bag: PathBuf,
        out: PathBuf,
        /// Bag time between frames, seconds.
        #[arg(long, default_value_t = 0.1)]
        frame_period: f64,
    },
    /// Republish every message on its topic with its original QoS and timing.
    Play {
        bag: PathBuf,
        #[arg(long, default_value_t = 1.0)]
        rate: f64,
        /// ROS domain (default: ROS_DOMAIN_ID or 0).
        #[arg(long)]
        domain_id: Option<u16>,
        /// Seconds to wait for subscribers to match before the first message.
        #[arg(long, default_value_t = 1.0)]
        wait: f64,
    },
    /// Test helper: write a synthetic fleet episode (contract topics) as a bag; with
    /// --realtime it paces itself like a recorder and finalizes on SIGINT/SIGTERM.
    #[command(hide = true)]
    Synth {
        dir: PathBuf,
        #[arg(long, default_value_t = 10.0)]
        duration: f64,
        #[arg(long, default_value_t = 2)]
        robots: usize,
        #[arg(long)]
        realtime: bool,
    },
}

#[derive(Args)]
pub struct RecordArgs {
    /// The bag directory to create.
    dir: PathBuf,
    /// Stop after this many seconds (default: until Ctrl-C / SIGTERM).
    #[arg(long)]
    duration: Option<f64>,
    /// ROS domain (default: ROS_DOMAIN_ID or 0).
    #[arg(long)]
    domain_id: Option<u16>,
    /// Seconds between topic discovery scans.
    #[arg(long, default_value_t = 0.5)]
    discovery_period: f64,
}

pub fn run(a: BagArgs) -> Result<()> {
    match a.cmd {
        BagCmd::Info { bag } => info(&bag),
        BagCmd::Metrics { bag, period } => metrics(&bag, period),
        BagCmd::Recover { input, output } => {
            let r = bag::recover(&input, &output)?;
            println!(
                "recovered {} messages on {} topics from {} ({}) into {}",
                r.messages,
                r.topics,
                r.input.display(),
                if r.input_was_complete {
                    "complete file".to_string()
                } else {
                    format!(
                        "cut file: {}",
                        r.stopped_early.as_deref().unwrap_or("no footer")
                    )
                },
                output.display()
            );
            Ok(())
        }
        BagCmd::Render {
            bag,
            out,
            frame_period,
        } => render(&bag, &out, frame_period),
        BagCmd::Play {
            bag,
            rate,
            domain_id,
            wait,
        } => play(&bag, rate, domain_id, wait),
        BagCmd::Synth {
            dir,
            duration,
            robots,
            realtime,
        } => synth(&dir, duration, robots, realtime),
    }
}

// ------------------------------------------------------------------------------- info

fn secs(ns: u64) -> f64 {
    ns as f64 * 1e-9
}

fn info(path: &std::path::Path) -> Result<()> {
    let r = BagReader::open(path)?;
    println!("file:      {}", r.path.display());
    println!(
        "complete:  {}",
        if r.complete {
            "yes".to_string()
        } else {
            format!(
                "NO ({}; `tending bag recover` rewrites it)",
                r.stopped_early.as_deref().unwrap_or("?")
            )
        }
    );
    println!("messages:  {}", r.messages.len());
    if let Some((a, b)) = r.time_range() {
        println!("start:     {:.3} s", secs(a));
        println!("duration:  {:.3} s", secs(b - a));
    }
    println!();
    let w = r
        .topics
        .iter()
        .map(|t| t.name.len())
        .max()
        .unwrap_or(5)
        .max(5);
    println!("{:<w$}  {:<36} {:>8}  qos", "topic", "type", "count");
    for t in &r.topics {
        println!(
            "{:<w$}  {:<36} {:>8}  {}",
            t.name,
            t.type_name,
            t.message_count,
            qos_summary(&t.qos_yaml)
        );
    }
    Ok(())
}

/// The QoS fields that decide matching, from an `offered_qos_profiles` YAML string.
struct QosFields {
    reliable: bool,
    transient_local: bool,
    keep_all: bool,
    depth: usize,
}

fn qos_fields(yaml: &str) -> QosFields {
    let mut q = QosFields {
        reliable: true,
        transient_local: false,
        keep_all: false,
        depth: 10,
    };
    for line in yaml.lines() {
        let l = line.trim_start_matches(['-', ' ']);
        if let Some(v) = l.strip_prefix("reliability:") {
            q.reliable = v.trim() != "best_effort";
        } else if let Some(v) = l.strip_prefix("durability:") {
            q.transient_local = v.trim() == "transient_local";
        } else if let Some(v) = l.strip_prefix("history:") {
            q.keep_all = v.trim() == "keep_all";
        } else if let Some(v) = l.strip_prefix("depth:") {
            if let Ok(d) = v.trim().parse::<usize>() {
                q.depth = d.max(1);
            }
        }
    }
    q
}

fn qos_summary(yaml: &str) -> String {
    if yaml.is_empty() {
        return "-".into();
    }
    let q = qos_fields(yaml);
    format!(
        "{}, {}, {}",
        if q.reliable {
            "reliable"
        } else {
            "best effort"
        },
        if q.transient_local {
            "transient local"
        } else {
            "volatile"
        },
        if q.keep_all {
            "keep all".to_string()
        } else {
            format!("keep last {}", q.depth)
        }
    )
}

/// A ros2-client QoS profile from a bag's QoS YAML (reliability, durability, history).
fn qos_from_yaml(yaml: &str) -> QosProfile {
    let q = qos_fields(yaml);
    let mut p = msgs::qos::robot_stream();
    if !q.reliable {
        p.reliability = Reliability::BestEffort;
    }
    if q.transient_local {
        p.durability = Durability::TransientLocal;
    }
    p.history = if q.keep_all {
        History::KeepAll
    } else {
        History::KeepLast { depth: q.depth }
    };
    p
}

// ---------------------------------------------------------------------------- metrics

fn metrics(path: &std::path::Path, period: f64) -> Result<()> {
    let r = BagReader::open(path)?;
    if !r.complete {
        eprintln!(
            "warning: {} is not complete ({}); using what is readable",
            r.path.display(),
            r.stopped_early.as_deref().unwrap_or("?")
        );
    }
    let m = bag::metrics(&r, period)?;
    print_metrics_table(&r.path, &m);
    print_metrics_totals(&m);
    Ok(())
}

/// The bins: from has_part (and poses), next to /tending/metrics when recorded.
fn print_metrics_table(path: &std::path::Path, m: &bag::BagMetrics) {
    let has_metrics = m.has_metrics;
    println!(
        "bag {}: {:.1} s, {} robots seen (pose/has_part topics){}",
        path.display(),
        m.duration_s,
        m.robots_seen,
        if has_metrics {
            ", /tending/metrics recorded"
        } else {
            ", no /tending/metrics"
        }
    );
    println!(
        "from has_part: delivered = true->false transitions, picks = false->true; robots = pose topics with data in the row's period"
    );
    print!(
        "{:>8} {:>6} {:>6} {:>10}",
        "t [s]", "robots", "picks", "delivered"
    );
    if has_metrics {
        print!(
            " | {:>14} {:>10} {:>7} {:>7}",
            "rep. delivered", "collisions", "MU", "robots"
        );
    }
    println!();
    for row in &m.rows {
        print!(
            "{:>8.1} {:>6} {:>6} {:>10}",
            row.t, row.robots_alive, row.picks, row.deliveries
        );
        if has_metrics {
            print!(
                " | {:>14} {:>10} {:>7} {:>7}",
                get(&row.reported, "parts_delivered"),
                get(&row.reported, "collisions"),
                get(&row.reported, "machine_utilization"),
                get(&row.reported, "robots"),
            );
        }
        println!();
    }
    println!();
}

fn get(m: &BTreeMap<String, String>, k: &str) -> String {
    m.get(k).cloned().unwrap_or("-".into())
}

/// The episode's totals, and where has_part and /tending/metrics disagree.
fn print_metrics_totals(m: &bag::BagMetrics) {
    let last = m.last();
    let last_reported = &last.reported;
    let p_max: Option<f64> = last_reported.get("p_max").and_then(|v| v.parse().ok());
    println!(
        "total from has_part: {} delivered, {} picked{}",
        last.deliveries,
        last.picks,
        match p_max {
            Some(p) if p > 0.0 => format!(
                ", MU = picks / p_max = {} / {} = {:.3}",
                last.picks,
                p,
                last.picks as f64 / p
            ),
            _ => ", MU n/a (no p_max recorded)".into(),
        }
    );
    if m.has_metrics {
        println!(
            "total from /tending/metrics: {} delivered, {} collected, {} collisions, MU {}",
            get(last_reported, "parts_delivered"),
            get(last_reported, "parts_collected"),
            get(last_reported, "collisions"),
            get(last_reported, "machine_utilization")
        );
        // bridges before the per-kind counts recorded only the total
        if last_reported.contains_key("collisions_robot_robot") {
            println!(
                "collisions by kind from /tending/metrics: robot-robot {}, robot-machine {}, robot-storage {}, robot-wall {}",
                get(last_reported, "collisions_robot_robot"),
                get(last_reported, "collisions_robot_machine"),
                get(last_reported, "collisions_robot_storage"),
                get(last_reported, "collisions_robot_wall")
            );
        } else {
            println!("collisions by kind: n/a (recorded by a bridge that reported only totals)");
        }
        if let Some(rep) = last_reported
            .get("parts_delivered")
            .and_then(|v| v.parse::<u64>().ok())
        {
            if rep != last.deliveries {
                println!(
                    "note: has_part transitions give {} deliveries, /tending/metrics {} (a robot despawned while carrying, or a recording that started mid-episode)",
                    last.deliveries, rep
                );
            }
        }
    } else {
        println!("collisions: n/a (only /tending/metrics carries them)");
    }
}

// ----------------------------------------------------------------------------- render

fn render(path: &std::path::Path, out: &std::path::Path, frame_period: f64) -> Result<()> {
    anyhow::ensure!(frame_period > 0.0, "--frame-period must be positive");
    let r = BagReader::open(path)?;
    let Some((t0, t1)) = r.time_range() else {
        bail!("{} holds no messages", r.path.display());
    };
    // Sizes from the first MarkerArray if recorded, else the default scenario's base sizes.
    let mut robot_radius = 0.05f32;
    let mut machine_half = [0.1f32, 0.1];
    let mut storage_half = [0.1f32, 0.1];
    if let Some((_, ma)) = r
        .decode_topic::<MarkerArray>(topics::MARKERS)
        .unwrap_or_default()
        .into_iter()
        .next()
    {
        for m in &ma.markers {
            let half = [m.scale.x as f32 / 2.0, m.scale.y as f32 / 2.0];
            match m.ns.as_str() {
                "robots" => robot_radius = half[0],
                "machines" => machine_half = half,
                "storages" => storage_half = half,
                _ => {}
            }
        }
    }
    #[derive(Default)]
    struct State {
        pos: Option<([f32; 2], u64)>,
        flag: bool,
    }
    let mut robots: BTreeMap<String, State> = BTreeMap::new();
    let mut machines: BTreeMap<u32, State> = BTreeMap::new();
    let mut storages: BTreeMap<u32, State> = BTreeMap::new();
    let mut frames = Vec::new();
    let period_ns = (frame_period * 1e9) as u64;
    let stale_ns = 1_000_000_000u64.max(2 * period_ns);
    let mut next = t0;
    let mut delivered = 0u32;
    let mut idx = 0;
    let mut msgs_sorted: Vec<&bag::BagMessage> = r.messages.iter().collect();
    msgs_sorted.sort_by_key(|m| m.log_time);
    let parsed: Vec<Option<topics::EntityTopic>> = r
        .topics
        .iter()
        .map(|t| topics::parse_topic(&t.name))
        .collect();
    while next <= t1 {
        while idx < msgs_sorted.len() && msgs_sorted[idx].log_time <= next {
            let m = msgs_sorted[idx];
            idx += 1;
            let Some(et) = &parsed[m.topic_index] else {
                continue;
            };
            let st = match &et.entity {
                Entity::Robot(n) => robots.entry(n.clone()).or_default(),
                Entity::Machine(j) => machines.entry(*j).or_default(),
                Entity::Storage(k) => storages.entry(*k).or_default(),
            };
            match et.leaf {
                Leaf::Pose => {
                    if let Ok(p) = msgs::cdr::decode::<PoseStamped>(&m.data) {
                        let q = p.pose.position;
                        st.pos = Some(([q.x as f32, q.y as f32], m.log_time));
                    }
                }
                Leaf::HasPart | Leaf::PartReady => {
                    if let Ok(b) = msgs::cdr::decode::<Bool>(&m.data) {
                        if et.leaf == Leaf::HasPart && st.flag && !b.data {
                            delivered += 1;
                        }
                        st.flag = b.data;
                    }
                }
                Leaf::CmdVel => {}
            }
        }
        let live = |s: &State| s.pos.filter(|(_, t)| next.saturating_sub(*t) <= stale_ns);
        frames.push(crate::render::Frame {
            robots: robots
                .values()
                .filter_map(|s| live(s).map(|(p, _)| (p, s.flag)))
                .collect(),
            // machines and storages are latched: no staleness
            machines: machines
                .values()
                .filter_map(|s| s.pos.map(|(p, _)| (p, machine_half, s.flag)))
                .collect(),
            storages: storages
                .values()
                .filter_map(|s| s.pos.map(|(p, _)| (p, storage_half)))
                .collect(),
            robot_radius,
            step: frames.len() as u32,
            delivered,
        });
        next += period_ns;
    }
    let mut cfg = sim::ScenarioConfig::default();
    cfg.world.dt = frame_period as f32;
    crate::render::write(out, &cfg, &frames)?;
    println!(
        "{} frames ({:.1} s of bag time, {} robots, {} machines, {} storages) -> {}",
        frames.len(),
        secs(t1 - t0),
        robots.len(),
        machines.len(),
        storages.len(),
        out.display()
    );
    Ok(())
}

// ------------------------------------------------------------------------ DDS helpers

fn domain(d: Option<u16>) -> u16 {
    d.or_else(|| std::env::var("ROS_DOMAIN_ID").ok()?.parse().ok())
        .unwrap_or(0)
}

/// The CLI's own node (no rosout), spinning so that topic discovery works.
fn ros_node(domain_id: u16, name: &str) -> Result<ros::RosNode> {
    let spec = ros::NodeSpec {
        namespace: "/",
        name,
        enable_rosout: false,
    };
    ros::RosNode::start(&ros::context(domain_id)?, &spec, "ros2-spinner")
}

type Drain = Box<dyn FnMut(&mut BagWriter) -> Result<usize>>;

fn wall_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

fn recorder<M: RosMessage>(node: &mut Node, name: &str, qos: QosProfile) -> Result<Drain> {
    let sub: Subscription<M> = ros::subscription_qos(node, name, qos)?;
    let name = name.to_string();
    Ok(Box::new(move |w: &mut BagWriter| {
        let mut n = 0;
        loop {
            match sub.take() {
                Ok(Some((m, info))) => {
                    let now = wall_ns();
                    let publish = info
                        .source_timestamp()
                        .map(|t| t.to_nanos().max(0) as u64)
                        .unwrap_or(now);
                    let bytes = msgs::cdr::encode(&m).map_err(|e| anyhow!("{name}: {e}"))?;
                    w.write_full(&name, now, publish, &bytes)?;
                    n += 1;
                }
                Ok(None) => break,
                Err(e) => {
                    eprintln!("{name}: dropped an undecodable sample: {e:?}");
                    break;
                }
            }
        }
        Ok(n)
    }))
}

fn recorder_for(node: &mut Node, name: &str, def: &MsgDef, qos: QosProfile) -> Result<Drain> {
    match def.full_name().as_str() {
        "geometry_msgs/msg/PoseStamped" => recorder::<PoseStamped>(node, name, qos),
        "std_msgs/msg/Bool" => recorder::<Bool>(node, name, qos),
        "geometry_msgs/msg/Twist" => recorder::<Twist>(node, name, qos),
        "rosgraph_msgs/msg/Clock" => recorder::<Clock>(node, name, qos),
        "visualization_msgs/msg/MarkerArray" => recorder::<MarkerArray>(node, name, qos),
        "diagnostic_msgs/msg/DiagnosticArray" => recorder::<DiagnosticArray>(node, name, qos),
        "std_msgs/msg/String" => recorder::<StdString>(node, name, qos),
        other => bail!("{name}: no recorder for type {other}"),
    }
}

// ----------------------------------------------------------------------------- record

pub fn record(a: RecordArgs) -> Result<()> {
    let stop = ros::stop_flag()?;
    let mut ros = ros_node(domain(a.domain_id), "tending_record")?;
    let mut w = BagWriter::create(&a.dir)?;
    let start = Instant::now();
    let deadline = a
        .duration
        .map(|d| start + Duration::from_secs_f64(d.max(0.0)));
    let period = Duration::from_secs_f64(a.discovery_period.max(0.05));
    let mut next_discovery = start;
    let mut drains: Vec<(String, Drain)> = Vec::new();
    let mut refused = std::collections::HashSet::new();
    eprintln!(
        "recording contract topics into {} (Ctrl-C / SIGTERM to stop)",
        a.dir.display()
    );
    let result = (|| -> Result<()> {
        while !stop.load(Ordering::SeqCst) && deadline.is_none_or(|d| Instant::now() < d) {
            if Instant::now() >= next_discovery {
                next_discovery = Instant::now() + period;
                for d in ros.context().discovered_topics() {
                    let Some((name, def, profile)) = bag::contract_topic(&d.name) else {
                        continue;
                    };
                    if w.has_topic(&name) || refused.contains(&name) {
                        continue;
                    }
                    // ros2-client's spinner reads /clock as builtin_interfaces/Time, so
                    // that type shows up for /clock in every ros2-client graph: record
                    // /clock as the contract's rosgraph_msgs/Clock regardless.
                    let clock_artifact = name == topics::CLOCK
                        && d.type_name == "builtin_interfaces::msg::dds_::Time_";
                    if d.type_name != def.dds_name() && !clock_artifact {
                        eprintln!(
                            "not recording {name}: type {} is not the contract's {}",
                            d.type_name,
                            def.dds_name()
                        );
                        refused.insert(name);
                        continue;
                    }
                    let drain = recorder_for(ros.node(), &name, def, profile.qos())?;
                    w.add_topic(&name, def, &profile.offered_qos_yaml())?;
                    eprintln!("recording {name} ({})", def.full_name());
                    drains.push((name, drain));
                }
            }
            let mut got = 0;
            for (_, d) in drains.iter_mut() {
                got += d(&mut w)?;
            }
            w.flush_due()?;
            if got == 0 {
                std::thread::sleep(Duration::from_millis(2));
            }
        }
        for (_, d) in drains.iter_mut() {
            d(&mut w)?;
        }
        Ok(())
    })();
    let n = w.message_count();
    let meta = w.finish()?;
    drop(ros);
    eprintln!(
        "bag {}: {} messages on {} topics, {:.1} s",
        a.dir.display(),
        n,
        meta.topics.len(),
        meta.time_range.map(|(a, b)| secs(b - a)).unwrap_or(0.0)
    );
    result
}

// ------------------------------------------------------------------------------- play

type SendFn = Box<dyn Fn(&[u8]) -> Result<()>>;

fn player<M: RosMessage + std::fmt::Debug>(
    node: &mut Node,
    name: &str,
    qos: QosProfile,
) -> Result<SendFn> {
    let p: Publisher<M> = ros::publisher_qos(node, name, qos)?;
    let name = name.to_string();
    Ok(Box::new(move |data: &[u8]| {
        let m: M = msgs::cdr::decode(data).map_err(|e| anyhow!("{name}: {e}"))?;
        p.publish(m).map_err(|e| anyhow!("publish {name}: {e:?}"))
    }))
}

fn player_for(node: &mut Node, name: &str, type_name: &str, qos: QosProfile) -> Result<SendFn> {
    match type_name {
        "geometry_msgs/msg/PoseStamped" => player::<PoseStamped>(node, name, qos),
        "std_msgs/msg/Bool" => player::<Bool>(node, name, qos),
        "geometry_msgs/msg/Twist" => player::<Twist>(node, name, qos),
        "rosgraph_msgs/msg/Clock" => player::<Clock>(node, name, qos),
        "visualization_msgs/msg/MarkerArray" => player::<MarkerArray>(node, name, qos),
        "diagnostic_msgs/msg/DiagnosticArray" => player::<DiagnosticArray>(node, name, qos),
        "std_msgs/msg/String" => player::<StdString>(node, name, qos),
        other => bail!("no player for type {other}"),
    }
}

fn play(path: &std::path::Path, rate: f64, domain_id: Option<u16>, wait: f64) -> Result<()> {
    anyhow::ensure!(rate > 0.0, "--rate must be positive");
    let r = BagReader::open(path)?;
    let stop = ros::stop_flag()?;
    let mut ros = ros_node(domain(domain_id), "tending_play")?;
    let mut pubs: Vec<Option<SendFn>> = Vec::new();
    for t in &r.topics {
        let qos = if t.qos_yaml.is_empty() {
            msgs::qos::robot_stream()
        } else {
            qos_from_yaml(&t.qos_yaml)
        };
        match player_for(ros.node(), &t.name, &t.type_name, qos) {
            Ok(p) => pubs.push(Some(p)),
            Err(e) => {
                eprintln!("skipping {}: {e:#}", t.name);
                pubs.push(None);
            }
        }
    }
    std::thread::sleep(Duration::from_secs_f64(wait.max(0.0)));
    let mut order: Vec<&bag::BagMessage> = r.messages.iter().collect();
    order.sort_by_key(|m| m.log_time);
    let Some(t0) = order.first().map(|m| m.log_time) else {
        println!("no messages");
        return Ok(());
    };
    let start = Instant::now();
    let (mut sent, mut failed) = (0u64, 0u64);
    for m in order {
        if stop.load(Ordering::SeqCst) {
            break;
        }
        let due = start + Duration::from_secs_f64(secs(m.log_time - t0) / rate);
        let now = Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
        if let Some(p) = &pubs[m.topic_index] {
            match p(&m.data) {
                Ok(()) => sent += 1,
                Err(e) => {
                    failed += 1;
                    if failed <= 5 {
                        eprintln!("{e:#}");
                    }
                }
            }
        }
    }
    // Let reliable writers deliver the tail before the participant goes away.
    std::thread::sleep(Duration::from_millis(500));
    drop(ros);
    println!(
        "played {sent} messages ({failed} failed) in {:.1} s",
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

// ------------------------------------------------------------------------------ synth

/// A scripted episode on the contract topics: robot i shuttles between machine i % M and
/// storage i % K, picking (has_part false -> true) at the machine and delivering (true ->
/// false) at the storage; /tending/metrics reports the same counts once per second.
fn synth(dir: &std::path::Path, duration: f64, robots: usize, realtime: bool) -> Result<()> {
    let stop = if realtime {
        Some(ros::stop_flag()?)
    } else {
        None
    };
    let mut w = BagWriter::create(dir)?;
    let machines = [[-0.8f64, 0.8], [0.8, 0.8]];
    let storages = [[0.0f64, -0.9]];
    let rs = Profile::RobotStream.offered_qos_yaml();
    w.add_topic(
        topics::CLOCK,
        &schema::CLOCK,
        &Profile::Clock.offered_qos_yaml(),
    )?;
    w.add_topic(
        topics::METRICS,
        &schema::DIAGNOSTIC_ARRAY,
        &Profile::Visualization.offered_qos_yaml(),
    )?;
    for (j, _) in machines.iter().enumerate() {
        w.add_topic(
            &format!("/machine_{j}/pose"),
            &schema::POSE_STAMPED,
            &Profile::LatchedPose.offered_qos_yaml(),
        )?;
        w.add_topic(
            &format!("/machine_{j}/part_ready"),
            &schema::BOOL,
            &Profile::PartReady.offered_qos_yaml(),
        )?;
    }
    for (k, _) in storages.iter().enumerate() {
        w.add_topic(
            &format!("/storage_{k}/pose"),
            &schema::POSE_STAMPED,
            &Profile::LatchedPose.offered_qos_yaml(),
        )?;
    }
    for i in 0..robots {
        w.add_topic(&format!("/robot_{i}/pose"), &schema::POSE_STAMPED, &rs)?;
        w.add_topic(&format!("/robot_{i}/has_part"), &schema::BOOL, &rs)?;
        w.add_topic(&format!("/robot_{i}/cmd_vel"), &schema::TWIST, &rs)?;
    }
    let t0 = wall_ns();
    let start = Instant::now();
    let steps = (duration / 0.1).round() as u64;
    let leg = 15u64; // steps per leg
    let (mut picks, mut deliveries) = (0u64, 0u64);
    let mut step = 0;
    while step < steps {
        if let Some(s) = &stop {
            if s.load(Ordering::SeqCst) {
                break;
            }
            let due = start + Duration::from_millis(100 * step);
            let now = Instant::now();
            if due > now {
                std::thread::sleep(due - now);
            }
        }
        let t = if realtime {
            wall_ns()
        } else {
            t0 + step * 100_000_000
        };
        let stamp = Time::from_secs_f64(step as f64 * 0.1);
        w.write_msg(topics::CLOCK, t, &Clock { clock: stamp })?;
        if step == 0 {
            for (j, m) in machines.iter().enumerate() {
                let p = PoseStamped::planar(stamp, topics::FRAME_ID, m[0], m[1]);
                w.write_msg(&format!("/machine_{j}/pose"), t, &p)?;
            }
            for (k, s) in storages.iter().enumerate() {
                let p = PoseStamped::planar(stamp, topics::FRAME_ID, s[0], s[1]);
                w.write_msg(&format!("/storage_{k}/pose"), t, &p)?;
            }
        }
        let phase = step % (2 * leg);
        if step % 5 == 0 {
            for j in 0..machines.len() {
                w.write_msg(
                    &format!("/machine_{j}/part_ready"),
                    t,
                    &Bool { data: phase < leg },
                )?;
            }
        }
        for i in 0..robots {
            let m = machines[i % machines.len()];
            let s = storages[i % storages.len()];
            let carrying = phase >= leg; // picked at the machine, heading to storage
            let f = (phase % leg) as f64 / leg as f64;
            let (a, b) = if carrying { (m, s) } else { (s, m) };
            let x = a[0] + (b[0] - a[0]) * f;
            let y = a[1] + (b[1] - a[1]) * f + 0.05 * i as f64;
            w.write_msg(
                &format!("/robot_{i}/pose"),
                t,
                &PoseStamped::planar(stamp, topics::FRAME_ID, x, y),
            )?;
            w.write_msg(&format!("/robot_{i}/has_part"), t, &Bool { data: carrying })?;
            w.write_msg(
                &format!("/robot_{i}/cmd_vel"),
                t,
                &Twist::planar((b[0] - a[0]) / 1.5, (b[1] - a[1]) / 1.5),
            )?;
            if step > 0 && phase == leg {
                picks += 1;
            }
            if step > 0 && phase == 0 {
                deliveries += 1;
            }
        }
        if step % 10 == 0 {
            let kv = |k: &str, v: String| msgs::KeyValue {
                key: k.into(),
                value: v,
            };
            let p_max = (machines.len() as u64 * steps / 20).max(1);
            let d = DiagnosticArray {
                header: msgs::Header {
                    stamp,
                    frame_id: String::new(),
                },
                status: vec![msgs::DiagnosticStatus {
                    level: msgs::DiagnosticStatus::OK,
                    name: "tending/metrics".into(),
                    message: String::new(),
                    hardware_id: "synth".into(),
                    values: vec![
                        kv("parts_delivered", deliveries.to_string()),
                        kv("parts_collected", picks.to_string()),
                        kv("collisions", "0".into()),
                        kv(
                            "machine_utilization",
                            format!("{:.4}", picks as f64 / p_max as f64),
                        ),
                        kv("p_max", p_max.to_string()),
                        kv("robots", robots.to_string()),
                        kv("step", step.to_string()),
                    ],
                }],
            };
            w.write_msg(topics::METRICS, t, &d)?;
        }
        step += 1;
    }
    let n = w.message_count();
    w.finish()?;
    println!(
        "{} messages, {step} steps, {picks} picks, {deliveries} deliveries -> {}",
        n,
        dir.display()
    );
    Ok(())
}
