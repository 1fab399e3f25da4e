//! `results.csv` of `tending eval`: per setup and seed, the mean over that seed's episodes
//! (`tending plot bars` and `tending plot pareto` read it, so does bench/experiments).

use crate::Numbers;
use serde::{Deserialize, Serialize};

/// One (setup, seed). Field order is the column order. The contact kinds and rates came
/// with the safety work: results written before (docs/results/) lack them; collision
/// events (onsets) came with issue 47, as the last column.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct EvalResultRecord {
    /// The controller: a model kind, with mode and checkpoint file, or a scripted baseline
    /// (`smappo+orca (smappo_6.4_2.safetensors)`, `greedy`).
    pub policy: String,
    pub setup: String,
    pub seed: u64,
    pub episodes: u64,
    pub parts_delivered: f64,
    pub collisions: f64,
    pub collisions_robot_robot: Option<f64>,
    pub collisions_robot_machine: Option<f64>,
    pub collisions_robot_storage: Option<f64>,
    pub collisions_robot_wall: Option<f64>,
    pub contacts_per_robot_step: Option<f64>,
    pub robot_robot_per_robot_step: Option<f64>,
    pub mu: f64,
    pub team_reward: f64,
    pub collision_events: Option<f64>,
}

impl EvalResultRecord {
    pub fn new(policy: &str, setup: &str, seed: u64, episodes: u64, n: &Numbers) -> Self {
        Self {
            policy: policy.to_string(),
            setup: setup.to_string(),
            seed,
            episodes,
            parts_delivered: n.parts_delivered,
            collisions: n.collisions,
            collisions_robot_robot: Some(n.collisions_robot_robot),
            collisions_robot_machine: Some(n.collisions_robot_machine),
            collisions_robot_storage: Some(n.collisions_robot_storage),
            collisions_robot_wall: Some(n.collisions_robot_wall),
            contacts_per_robot_step: Some(n.contacts_per_robot_step),
            robot_robot_per_robot_step: Some(n.robot_robot_per_robot_step),
            mu: n.mu,
            team_reward: n.team_reward,
            collision_events: Some(n.collision_events),
        }
    }

    /// The model the row is about: the first word of `policy`, lower case (`smappo+orca`
    /// for a filtered SMAPPO), or None for an empty `policy`.
    pub fn model(&self) -> Option<String> {
        self.policy
            .split_whitespace()
            .next()
            .map(str::to_ascii_lowercase)
    }
}

#[cfg(test)]
mod tests {
    use super::super::{read, to_text};
    use super::*;
    use std::path::Path;

    const HEADER: &str = "policy,setup,seed,episodes,parts_delivered,collisions,\
collisions_robot_robot,collisions_robot_machine,collisions_robot_storage,\
collisions_robot_wall,contacts_per_robot_step,robot_robot_per_robot_step,mu,team_reward,\
collision_events";
    const SAFETY_HEADER: &str = "policy,setup,seed,episodes,parts_delivered,collisions,\
collisions_robot_robot,collisions_robot_machine,collisions_robot_storage,\
collisions_robot_wall,contacts_per_robot_step,robot_robot_per_robot_step,mu,team_reward";
    const OLD_HEADER: &str = "policy,setup,seed,episodes,parts_delivered,collisions,mu,team_reward";

    /// Every committed results.csv reads; those of this version write back byte for byte.
    #[test]
    fn committed_results_read_and_round_trip() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let mut files = vec![];
        for dir in ["docs/results", "docs/safety/eval"] {
            for e in walk(&root.join(dir)) {
                // `tending bound` writes its bound.csv beside the eval results.
                if e.extension().is_some_and(|x| x == "csv")
                    && e.file_name().is_some_and(|n| n != "bound.csv")
                {
                    files.push(e);
                }
            }
        }
        assert!(files.len() >= 16, "{files:?}");
        for f in files {
            let rows: Vec<EvalResultRecord> =
                read(&f).unwrap().into_iter().map(|l| l.record).collect();
            let text = std::fs::read_to_string(&f).unwrap();
            if text.starts_with(HEADER) {
                assert_eq!(to_text(&rows).unwrap(), text, "{}", f.display());
            } else if text.starts_with(SAFETY_HEADER) {
                assert!(rows.iter().all(|r| r.collision_events.is_none()));
                assert!(rows.iter().all(|r| r.contacts_per_robot_step.is_some()));
            } else {
                assert!(text.starts_with(OLD_HEADER), "{}", f.display());
                assert!(rows.iter().all(|r| r.contacts_per_robot_step.is_none()));
            }
            assert!(rows.iter().all(|r| r.model().is_some()), "{}", f.display());
        }
    }

    fn walk(dir: &Path) -> Vec<std::path::PathBuf> {
        let mut out = vec![];
        for e in std::fs::read_dir(dir).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                out.extend(walk(&p));
            } else {
                out.push(p);
            }
        }
        out
    }

    #[test]
    fn writer_header_is_this_versions() {
        let n = Numbers {
            parts_delivered: 3.0,
            ..Default::default()
        };
        let text = to_text(&[EvalResultRecord::new("greedy", "6.4_2", 1, 2, &n)]).unwrap();
        assert_eq!(text.lines().next(), Some(HEADER));
        assert_eq!(
            text.lines().nth(1),
            Some("greedy,6.4_2,1,2,3.0,0.0,0.0,0.0,0.0,0.0,0.0,0.0,0.0,0.0,0.0")
        );
    }
}
