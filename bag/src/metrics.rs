//! What a recorded episode says, bin by bin (`tending bag metrics`): picks and deliveries
//! from each robot's `has_part` transitions, robots alive from their pose topics, and the
//! bridge's own `/tending/metrics` key/values when they were recorded.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use anyhow::{anyhow, bail, Result};
use msgs::topics::{self, Entity, Leaf};
use msgs::{Bool, DiagnosticArray};

use crate::BagReader;

/// One bin of `period` seconds.
#[derive(Debug, Clone, PartialEq)]
pub struct MetricsRow {
    /// Start of the bin, seconds since the bag's first message.
    pub t: f64,
    /// Robots whose pose topic carried data in the bin.
    pub robots_alive: usize,
    /// Cumulative false -> true `has_part` transitions.
    pub picks: u64,
    /// Cumulative true -> false `has_part` transitions.
    pub deliveries: u64,
    /// The latest value of each `/tending/metrics` key up to the end of the bin.
    pub reported: BTreeMap<String, String>,
}

/// A bag's episode metrics.
#[derive(Debug, Clone)]
pub struct BagMetrics {
    pub duration_s: f64,
    /// Robots with a pose or has_part topic.
    pub robots_seen: usize,
    /// Whether `/tending/metrics` was recorded (else `reported` is empty everywhere).
    pub has_metrics: bool,
    /// At least one row.
    pub rows: Vec<MetricsRow>,
}

impl BagMetrics {
    /// The last row: the episode's totals.
    pub fn last(&self) -> &MetricsRow {
        self.rows.last().expect("at least one bin")
    }
}

fn robot_of(name: &str, leaf: Leaf) -> Option<String> {
    match topics::parse_topic(name)? {
        t if t.leaf == leaf => match t.entity {
            Entity::Robot(r) => Some(r),
            _ => None,
        },
        _ => None,
    }
}

/// Bin the bag's messages by log time into `period`-second rows.
pub fn metrics(r: &BagReader, period: f64) -> Result<BagMetrics> {
    anyhow::ensure!(period > 0.0, "--period must be positive");
    let Some((t0, t1)) = r.time_range() else {
        bail!("{} holds no messages", r.path.display());
    };
    let period_ns = (period * 1e9) as u64;
    let bins = ((t1 - t0) / period_ns + 1) as usize;
    let bin = |t: u64| (((t - t0) / period_ns) as usize).min(bins - 1);
    let mut picks = vec![0u64; bins];
    let mut deliveries = vec![0u64; bins];
    let mut alive: Vec<BTreeSet<String>> = vec![Default::default(); bins];
    let mut last_flag: HashMap<usize, bool> = HashMap::new();
    let mut reported: Vec<BTreeMap<String, String>> = vec![BTreeMap::new(); bins];
    let mut robots_seen = BTreeSet::new();
    let metrics_topic = r.topic_index(topics::METRICS);
    for m in &r.messages {
        let t = &r.topics[m.topic_index];
        let b = bin(m.log_time);
        if let Some(robot) = robot_of(&t.name, Leaf::HasPart) {
            let v: Bool = msgs::cdr::decode(&m.data).map_err(|e| anyhow!("{}: {e}", t.name))?;
            if let Some(prev) = last_flag.insert(m.topic_index, v.data) {
                match (prev, v.data) {
                    (false, true) => picks[b] += 1,
                    (true, false) => deliveries[b] += 1,
                    _ => {}
                }
            }
            robots_seen.insert(robot);
        } else if let Some(robot) = robot_of(&t.name, Leaf::Pose) {
            alive[b].insert(robot.clone());
            robots_seen.insert(robot);
        } else if Some(m.topic_index) == metrics_topic {
            let d: DiagnosticArray =
                msgs::cdr::decode(&m.data).map_err(|e| anyhow!("{}: {e}", t.name))?;
            for s in d.status {
                for kv in s.values {
                    reported[b].insert(kv.key, kv.value);
                }
            }
        }
    }
    let mut rows = Vec::with_capacity(bins);
    let (mut cp, mut cd) = (0, 0);
    let mut last_reported = BTreeMap::new();
    for b in 0..bins {
        cp += picks[b];
        cd += deliveries[b];
        for (k, v) in &reported[b] {
            last_reported.insert(k.clone(), v.clone());
        }
        rows.push(MetricsRow {
            t: b as f64 * period,
            robots_alive: alive[b].len(),
            picks: cp,
            deliveries: cd,
            reported: last_reported.clone(),
        });
    }
    Ok(BagMetrics {
        duration_s: (t1 - t0) as f64 / 1e9,
        robots_seen: robots_seen.len(),
        has_metrics: metrics_topic.is_some(),
        rows,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use msgs::{DiagnosticStatus, KeyValue, PoseStamped, Time};

    #[test]
    fn picks_deliveries_alive_and_reported_per_bin() {
        let dir = std::env::temp_dir().join(format!("bag_metrics_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let mut w = crate::BagWriter::create(&dir).unwrap();
        let s = 1_000_000_000u64;
        let pose = PoseStamped::planar(Time::from_secs_f64(0.0), "map", 0.0, 0.0);
        // robot_0: picks at 0.5 s, delivers at 1.5 s; robot_1 only has a pose, in bin 0
        for (t, v) in [(0, false), (s / 2, true), (3 * s / 2, false)] {
            w.write_contract("/robot_0/has_part", t, &Bool { data: v })
                .unwrap();
            w.write_contract("/robot_0/pose", t, &pose).unwrap();
        }
        w.write_contract("/robot_1/pose", s / 4, &pose).unwrap();
        let kv = |k: &str, v: &str| KeyValue {
            key: k.into(),
            value: v.into(),
        };
        let diag = DiagnosticArray {
            status: vec![DiagnosticStatus {
                values: vec![kv("parts_delivered", "1"), kv("collisions", "0")],
                ..Default::default()
            }],
            ..Default::default()
        };
        w.write_contract(topics::METRICS, 3 * s / 2, &diag).unwrap();
        w.finish().unwrap();
        let m = metrics(&BagReader::open(&dir).unwrap(), 1.0).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        assert_eq!(m.rows.len(), 2);
        assert_eq!(m.robots_seen, 2);
        assert!(m.has_metrics);
        assert_eq!(
            (
                m.rows[0].robots_alive,
                m.rows[0].picks,
                m.rows[0].deliveries
            ),
            (2, 1, 0)
        );
        assert_eq!((m.last().picks, m.last().deliveries), (1, 1));
        assert!(m.rows[0].reported.is_empty());
        assert_eq!(m.last().reported["parts_delivered"], "1");
        assert!((m.duration_s - 1.5).abs() < 1e-9);
    }
}
