//! `tending bag info`: topics, types, QoS, counts, duration; the QoS YAML of a bag's topics.

use super::*;

pub(super) fn info(path: &std::path::Path) -> Result<()> {
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
pub(super) struct QosFields {
    reliable: bool,
    transient_local: bool,
    keep_all: bool,
    depth: usize,
}

pub(super) fn qos_fields(yaml: &str) -> QosFields {
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

pub(super) fn qos_summary(yaml: &str) -> String {
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
pub(super) fn qos_from_yaml(yaml: &str) -> QosProfile {
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
