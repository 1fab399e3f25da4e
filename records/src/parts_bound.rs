//! `bound.csv` of `tending bound`: per setup and seed, the mean over that seed's episodes of
//! `sim::parts_bound` (`tending plot limits` reads it, so does bench/safety/targets.py).

use serde::{Deserialize, Serialize};

/// One (setup, seed). Field order is the column order.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PartsBoundRecord {
    pub setup: String,
    pub seed: u64,
    pub episodes: u64,
    /// The bound: the smaller of the next two.
    pub parts_bound: f64,
    /// Every machine served the moment it is ready, each pick carried at the earliest.
    pub machine_bound: f64,
    /// The fleet's robot-steps, each delivery a round trip on its machine's shortest gap.
    pub robot_bound: f64,
    /// Machines x ceil(episode steps / prep steps): the paper's P_max.
    pub p_max: f64,
}

#[cfg(test)]
mod tests {
    use super::super::{read, to_text};
    use super::*;

    #[test]
    fn committed_bounds_read_and_write_back_the_same_columns() {
        let p =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/safety/eval/bound.csv");
        let rows: Vec<PartsBoundRecord> = read(&p).unwrap().into_iter().map(|l| l.record).collect();
        assert!(rows.len() >= 30);
        // Per episode the bound is the smaller of its parts, so their means are at least it;
        // none is above P_max.
        for r in &rows {
            assert!(
                r.parts_bound <= r.machine_bound.min(r.robot_bound) + 1e-9,
                "{r:?}"
            );
            assert!(r.parts_bound <= r.p_max, "{r:?}");
        }
        let header = std::fs::read_to_string(&p).unwrap();
        let header = header.lines().next().unwrap();
        assert_eq!(to_text(&rows[..1]).unwrap().lines().next().unwrap(), header);
    }
}
