//! `log.csv` of a training run: one row per PPO update (`tending train` writes it,
//! `tending train --resume` and `tending plot curves` read it).

use super::decimals::{dp1, dp3, dp4, dp5, dp6};
use learn::UpdateStats;
use serde::{Deserialize, Serialize};

/// One update. Field order is the column order; the decimals are those log.csv has
/// always had. `contact_rate` and `lambda` came with the safety work: logs written
/// before (policy/pretrained/*.log.csv) lack them.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TrainLogRecord {
    pub update: u64,
    pub episodes: u64,
    pub agent_steps: u64,
    /// Curriculum stage index (0 with --randomize).
    pub stage: usize,
    /// The update's setup N.M_K (with --randomize, its draw).
    pub setup: String,
    #[serde(serialize_with = "dp4")]
    pub team_reward: f64,
    #[serde(serialize_with = "dp4")]
    pub parts_delivered: f64,
    #[serde(serialize_with = "dp4")]
    pub collisions: f64,
    #[serde(serialize_with = "dp5")]
    pub mu: f64,
    #[serde(serialize_with = "dp6")]
    pub policy_loss: f64,
    #[serde(serialize_with = "dp6")]
    pub value_loss: f64,
    #[serde(serialize_with = "dp6")]
    pub entropy: f64,
    #[serde(serialize_with = "dp6")]
    pub approx_kl: f64,
    #[serde(serialize_with = "dp5")]
    pub clip_frac: f64,
    #[serde(serialize_with = "dp5")]
    pub actor_grad_norm: f64,
    #[serde(serialize_with = "dp5")]
    pub critic_grad_norm: f64,
    #[serde(serialize_with = "dp4")]
    pub rollout_secs: f64,
    #[serde(serialize_with = "dp4")]
    pub train_secs: f64,
    /// Training wall time so far, summed over invocations (resume continues it).
    #[serde(serialize_with = "dp3")]
    pub wall_secs: f64,
    #[serde(serialize_with = "dp1")]
    pub agent_steps_per_sec: f64,
    #[serde(serialize_with = "dp5")]
    pub contact_rate: Option<f64>,
    #[serde(serialize_with = "dp4")]
    pub lambda: Option<f64>,
}

impl TrainLogRecord {
    pub fn new(s: &UpdateStats, wall_secs: f64, agent_steps_per_sec: f64) -> Self {
        Self {
            update: s.update,
            episodes: s.episodes,
            agent_steps: s.agent_steps,
            stage: s.stage,
            setup: s.setup.clone(),
            team_reward: s.team_reward,
            parts_delivered: s.parts_delivered,
            collisions: s.collisions,
            mu: s.mu,
            policy_loss: s.policy_loss.into(),
            value_loss: s.value_loss.into(),
            entropy: s.entropy.into(),
            approx_kl: s.approx_kl.into(),
            clip_frac: s.clip_frac.into(),
            actor_grad_norm: s.actor_grad_norm.into(),
            critic_grad_norm: s.critic_grad_norm.into(),
            rollout_secs: s.rollout_secs,
            train_secs: s.train_secs,
            wall_secs,
            agent_steps_per_sec,
            contact_rate: Some(s.contact_rate),
            lambda: Some(s.lambda.into()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{parse, read, to_text};
    use super::*;
    use std::path::{Path, PathBuf};

    /// The log.csv header of this version (byte for byte what earlier versions wrote).
    const HEADER: &str = "update,episodes,agent_steps,stage,setup,team_reward,\
parts_delivered,collisions,mu,policy_loss,value_loss,entropy,approx_kl,clip_frac,\
actor_grad_norm,critic_grad_norm,rollout_secs,train_secs,wall_secs,agent_steps_per_sec,\
contact_rate,lambda";

    fn committed(rel: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(rel)
    }

    #[test]
    fn writer_keeps_the_header_and_decimals() {
        let s = UpdateStats {
            update: 3,
            episodes: 24,
            agent_steps: 9600,
            setup: "6.4_2".into(),
            team_reward: -5.85764,
            mu: 0.103125,
            policy_loss: -0.0096891,
            lambda: 0.5,
            ..Default::default()
        };
        let text = to_text(&[TrainLogRecord::new(&s, 6.3664, 1508.04)]).unwrap();
        let mut lines = text.lines();
        assert_eq!(lines.next(), Some(HEADER));
        assert_eq!(
            lines.next(),
            Some(
                "3,24,9600,0,6.4_2,-5.8576,0.0000,0.0000,0.10312,-0.009689,0.000000,0.000000,\
0.000000,0.00000,0.00000,0.00000,0.0000,0.0000,6.366,1508.0,0.00000,0.5000"
            )
        );
    }

    /// Every committed log reads; those of this version's columns write back byte for byte.
    #[test]
    fn committed_logs_read_and_round_trip() {
        let mut files = vec![];
        for dir in ["policy/pretrained", "docs/safety"] {
            for e in std::fs::read_dir(committed(dir)).unwrap().flatten() {
                if e.file_name().to_string_lossy().ends_with(".log.csv") {
                    files.push(e.path());
                }
            }
        }
        assert!(files.len() >= 6, "{files:?}");
        for path in files {
            let rel = path.display();
            let rows: Vec<TrainLogRecord> =
                read(&path).unwrap().into_iter().map(|l| l.record).collect();
            // Short fine-tune stages are committed too (75 updates): no minimum length,
            // but updates must follow one another, with episodes growing.
            assert!(!rows.is_empty(), "{rel}");
            assert!(
                rows.windows(2)
                    .all(|w| w[1].update == w[0].update + 1 && w[1].episodes > w[0].episodes),
                "{rel}"
            );
            let text = std::fs::read_to_string(&path).unwrap();
            if text.starts_with(HEADER) {
                assert_eq!(to_text(&rows).unwrap(), text, "{rel}");
            } else {
                assert!(rows.iter().all(|r| r.lambda.is_none()), "{rel}");
            }
        }
        let e = parse::<TrainLogRecord>(Path::new("r/log.csv"), "episodes,team_reward\n8,1\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("r/log.csv:2") && e.contains("update"), "{e}");
    }
}
