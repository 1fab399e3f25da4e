//! Is the fleet's ROS domain free? Two fleets on one domain command each other's robots:
//! a robot_node reads every `/robot_0/pose` on the domain and the bridge takes every
//! `/robot_0/cmd_vel` (issue 38: the README's main job started twice on domain 0, 95
//! contact steps, both runs "healthy"). So before it starts anything, `tending fleet`
//! watches the ROS 2 graph of its domain for `--domain-check-s` (discovery takes 1-2 s) and
//! refuses to start when it sees another fleet there: its nodes (`sim_bridge`,
//! `robot_node`, another `tending fleet`'s guard) by their names in `ros_discovery_info`, or
//! writers on the contract's topics (`/robot_0/cmd_vel`, `/machine_1/pose`, ...) by DDS
//! discovery. `--domain auto` moves to the first free domain instead, and says so.
//!
//! The participant that looked stays on the domain while the fleet runs (the guard, a node
//! named `tending_fleet_<start ms>_<pid>`), so that a fleet started a moment later sees this
//! one before its children are up. Two fleets that look at the same time see each other's
//! guards: the one that started later yields (docs/adr/0032-one-fleet-per-domain.md).

use std::collections::{BTreeMap, BTreeSet};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::{anyhow, bail, Result};
use ros2_client::dds::rustdds::{RTPSEntity, GUID};
use ros2_client::dds::Subscription;
use ros2_client::entities_info::ParticipantEntitiesInfo;
use ros2_client::gid::Gid;
use ros2_client::qos::{Durability, History, Liveliness, Reliability, WhenFull};
use ros2_client::{MessageTypeName, QosProfile};

use ros::security::Security;
use ros::{NodeSpec, RosNode};

/// The highest ROS domain id (RTPS port arithmetic).
pub(super) const MAX_DOMAIN: u16 = 232;
/// How many domains `--domain auto` tries before giving up.
const AUTO_TRIES: u16 = 16;
/// Prefix of a guard's node name.
const GUARD_PREFIX: &str = "tending_fleet_";

/// `--domain`: an id, or `auto`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DomainArg {
    Id(u16),
    Auto,
}

/// clap's parser of `--domain`.
pub fn parse_domain(s: &str) -> Result<DomainArg, String> {
    if s == "auto" {
        return Ok(DomainArg::Auto);
    }
    match s.parse::<u16>() {
        Ok(d) if d <= MAX_DOMAIN => Ok(DomainArg::Id(d)),
        _ => Err(format!(
            "expected a ROS domain id 0..={MAX_DOMAIN} or `auto`, got `{s}`"
        )),
    }
}

/// This fleet's guard: who it is (its start and pid order it against other guards) and,
/// once it has looked, the participant holding its node on the domain.
pub(super) struct Guard {
    start_ms: u64,
    pid: u32,
    ros: Option<RosNode>,
}

impl Guard {
    pub(super) fn new() -> Self {
        let start_ms = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_millis() as u64);
        Guard {
            start_ms,
            pid: std::process::id(),
            ros: None,
        }
    }

    fn node_name(&self) -> String {
        format!("{GUARD_PREFIX}{}_{}", self.start_ms, self.pid)
    }

    /// Another guard's node name: started before this one (it wins)? Unparsable names
    /// count as older (refuse rather than share a domain).
    fn is_older(&self, name: &str) -> bool {
        let mut it = name.strip_prefix(GUARD_PREFIX).unwrap_or("").split('_');
        let ms = it.next().and_then(|x| x.parse::<u64>().ok());
        let pid = it.next().and_then(|x| x.parse::<u32>().ok());
        match (ms, pid) {
            (Some(ms), Some(pid)) => (ms, pid) < (self.start_ms, self.pid),
            _ => true,
        }
    }
}

/// What the graph of one domain showed of other fleets.
#[derive(Debug, Default, Clone, PartialEq)]
pub(super) struct Seen {
    /// Fleet nodes, fully qualified: `/sim_bridge`, `/robot_0/robot_node`, an older guard.
    pub nodes: BTreeSet<String>,
    /// Contract topics with a writer of another participant: `/robot_0/cmd_vel`, ...
    pub topics: BTreeSet<String>,
    /// How many other participants those belong to.
    pub participants: usize,
}

/// At most `n` items of a list (those `first` picks, then the others), and how many more.
fn some_of(items: &BTreeSet<String>, n: usize, first: impl Fn(&str) -> bool) -> String {
    let (a, b): (Vec<&str>, Vec<&str>) = items.iter().map(String::as_str).partition(|x| first(x));
    let shown: Vec<&str> = a.into_iter().chain(b).take(n).collect();
    match items.len().saturating_sub(n) {
        0 => shown.join(", "),
        more => format!("{} and {more} more", shown.join(", ")),
    }
}

impl Seen {
    pub(super) fn busy(&self) -> bool {
        !self.nodes.is_empty() || !self.topics.is_empty()
    }

    /// `nodes /sim_bridge, ...; writers on /robot_0/cmd_vel, ... (7 participants)`.
    pub(super) fn describe(&self) -> String {
        let mut parts = Vec::new();
        if !self.nodes.is_empty() {
            let robots_later = |n: &str| !n.ends_with("/robot_node");
            parts.push(format!("nodes {}", some_of(&self.nodes, 8, robots_later)));
        }
        if !self.topics.is_empty() {
            let cmd_vel = |t: &str| t.ends_with("/cmd_vel");
            parts.push(format!("writers on {}", some_of(&self.topics, 4, cmd_vel)));
        }
        format!(
            "{} ({} participant{})",
            parts.join("; "),
            self.participants,
            if self.participants == 1 { "" } else { "s" }
        )
    }
}

/// A topic a fleet writes (DDS name `rt/robot_0/cmd_vel`, ...), as its ROS name.
fn fleet_topic(dds_name: &str) -> Option<String> {
    if let Some(t) = msgs::topics::parse_topic(dds_name) {
        return Some(t.ros_name());
    }
    let ros = format!("/{}", dds_name.strip_prefix("rt/")?);
    [msgs::topics::METRICS, msgs::topics::MARKERS]
        .contains(&ros.as_str())
        .then_some(ros)
}

/// A node of a fleet: the bridge, a robot, or another fleet's guard older than `guard`.
fn fleet_node(name: &str, guard: &Guard) -> bool {
    name == "sim_bridge"
        || name == "robot_node"
        || (name.starts_with(GUARD_PREFIX) && guard.is_older(name))
}

/// The first 12 bytes of a GUID: its participant.
fn prefix(g: GUID) -> [u8; 12] {
    let b = Gid::from(g).to_bytes16();
    std::array::from_fn(|i| b[i])
}

/// `ros_discovery_info` as every ROS 2 node publishes it (reliable, transient local),
/// kept per writer however many arrive (a keyless reader's depth is shared by all).
fn discovery_qos() -> QosProfile {
    QosProfile {
        reliability: Reliability::Reliable {
            when_full: WhenFull::Wait(Duration::from_millis(100)),
        },
        durability: Durability::TransientLocal,
        history: History::KeepLast { depth: 1024 },
        deadline: None,
        lifespan: None,
        liveliness: Liveliness::Automatic,
        liveliness_lease: None,
    }
}

/// Watch domain `domain` for `for_s` seconds with a guard node; the participant and what
/// it saw of other fleets.
fn look(domain: u16, security: &Security, guard: &Guard, for_s: f64) -> Result<(RosNode, Seen)> {
    let ctx = ros::context_with(domain, security)?;
    let name = guard.node_name();
    let spec = NodeSpec {
        namespace: "/",
        name: &name,
        enable_rosout: false,
    };
    let mut ros = RosNode::start(&ctx, &spec, "fleet-domain-check")?;
    let qos = discovery_qos();
    let (ctx, node) = ros.parts();
    let topic = ctx
        .create_topic(
            "ros_discovery_info".into(),
            MessageTypeName::new("rmw_dds_common", "ParticipantEntitiesInfo"),
            &qos,
        )
        .map_err(|e| anyhow!("ros_discovery_info topic: {e:?}"))?;
    let sub: Subscription<ParticipantEntitiesInfo> = node
        .create_subscription(&topic, Some(qos))
        .map_err(|e| anyhow!("ros_discovery_info reader: {e:?}"))?;
    let mut infos: BTreeMap<[u8; 12], Vec<String>> = BTreeMap::new();
    let until = Instant::now() + Duration::from_secs_f64(for_s);
    while Instant::now() < until {
        std::thread::sleep(Duration::from_millis(50));
        while let Ok(Some((info, _))) = sub.take() {
            let gid = info.gid().to_bytes16();
            let names = info.nodes().iter().map(|n| n.fully_qualified_name());
            infos.insert(std::array::from_fn(|i| gid[i]), names.collect());
        }
    }
    let dp = ctx.domain_participant();
    let me = prefix(dp.guid());
    let mut seen = Seen::default();
    let mut who = BTreeSet::new();
    for (p, names) in infos.iter().filter(|(p, _)| **p != me) {
        for n in names {
            let base = n.rsplit('/').next().unwrap_or(n);
            if fleet_node(base, guard) {
                seen.nodes.insert(n.clone());
                who.insert(*p);
            }
        }
    }
    for w in dp.discovered_writers() {
        let p = prefix(w.writer_proxy.remote_writer_guid);
        if p == me {
            continue;
        }
        if let Some(t) = fleet_topic(&w.publication_topic_data.topic_name) {
            seen.topics.insert(t);
            who.insert(p);
        }
    }
    seen.participants = who.len();
    Ok((ros, seen))
}

/// The refusal for a busy domain.
fn refusal(domain: u16, seen: &Seen) -> String {
    format!(
        "ROS domain {domain} already has a fleet on it: {}. Two fleets on one domain command \
         each other's robots, so this one does not start. Stop the other fleet, or start this \
         one on a free domain: --domain N (or ROS_DOMAIN_ID=N, N in 0..={MAX_DOMAIN}), or \
         --domain auto to take the first free one after {domain}",
        seen.describe()
    )
}

/// Make sure domain `domain` has no other fleet (with `auto`, find the first free domain
/// from `domain` up); returns the domain to run on. `guard` keeps its participant on that
/// domain when `keep` (the run's guard; with DDS Security the extra participant would cost
/// every child a handshake, so a secure fleet looks and leaves).
pub(super) fn claim(
    guard: &mut Guard,
    domain: u16,
    auto: bool,
    security: &Security,
    for_s: f64,
    keep: bool,
) -> Result<u16> {
    let last = if auto {
        domain.saturating_add(AUTO_TRIES - 1).min(MAX_DOMAIN)
    } else {
        domain
    };
    let mut busy = Vec::new();
    for d in domain..=last {
        let (ros, seen) = look(d, security, guard, for_s)?;
        if !seen.busy() {
            if !busy.is_empty() {
                let list: Vec<String> = busy.iter().map(u16::to_string).collect();
                let (what, verb) = match list.len() {
                    1 => ("domain", "is"),
                    _ => ("domains", "are"),
                };
                eprintln!(
                    "fleet: --domain auto: ROS domain {d} is free: this fleet runs on \
                     ROS_DOMAIN_ID={d} ({what} {} {verb} in use); tools that should see it \
                     need ROS_DOMAIN_ID={d}",
                    list.join(", ")
                );
            }
            guard.ros = keep.then_some(ros);
            return Ok(d);
        }
        if !auto {
            bail!("{}", refusal(d, &seen));
        }
        eprintln!(
            "fleet: --domain auto: ROS domain {d} is in use: {}",
            seen.describe()
        );
        busy.push(d);
    }
    bail!(
        "--domain auto: ROS domains {domain}..={last} all have a fleet on them; pick one \
         with --domain N"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn domain_argument() {
        assert_eq!(parse_domain("auto"), Ok(DomainArg::Auto));
        assert_eq!(parse_domain("7"), Ok(DomainArg::Id(7)));
        assert_eq!(parse_domain("232"), Ok(DomainArg::Id(232)));
        for bad in ["233", "-1", "x", ""] {
            assert!(parse_domain(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn fleet_nodes_and_topics() {
        let g = Guard {
            start_ms: 1000,
            pid: 50,
            ros: None,
        };
        assert!(fleet_node("sim_bridge", &g) && fleet_node("robot_node", &g));
        assert!(!fleet_node("tending_record", &g) && !fleet_node("rviz2", &g));
        // the guard that started first wins; a later one yields
        assert!(fleet_node("tending_fleet_999_70", &g));
        assert!(fleet_node("tending_fleet_1000_49", &g));
        assert!(!fleet_node("tending_fleet_1000_50", &g));
        assert!(!fleet_node("tending_fleet_1001_1", &g));
        assert!(fleet_node("tending_fleet_x", &g));
        assert_eq!(
            fleet_topic("rt/robot_3/cmd_vel").as_deref(),
            Some("/robot_3/cmd_vel")
        );
        assert_eq!(
            fleet_topic("rt/machine_1/pose").as_deref(),
            Some("/machine_1/pose")
        );
        assert_eq!(
            fleet_topic("rt/tending/metrics").as_deref(),
            Some("/tending/metrics")
        );
        assert_eq!(fleet_topic("rt/rosout"), None);
        assert_eq!(fleet_topic("ros_discovery_info"), None);
        assert_eq!(fleet_topic("rt/chatter"), None);
    }

    #[test]
    fn the_refusal_names_the_domain_the_nodes_and_the_way_out() {
        let seen = Seen {
            nodes: ["/sim_bridge", "/robot_0/robot_node"]
                .map(String::from)
                .into(),
            topics: ["/robot_0/cmd_vel"].map(String::from).into(),
            participants: 2,
        };
        let m = refusal(0, &seen);
        for want in [
            "ROS domain 0",
            "/sim_bridge",
            "/robot_0/robot_node",
            "/robot_0/cmd_vel",
            "2 participants",
            "--domain N",
            "ROS_DOMAIN_ID",
            "--domain auto",
        ] {
            assert!(m.contains(want), "{want}: {m}");
        }
        let many = Seen {
            nodes: (0..12).map(|i| format!("/robot_{i}/robot_node")).collect(),
            ..Seen::default()
        };
        assert!(
            many.describe().contains("and 4 more"),
            "{}",
            many.describe()
        );
    }
}
