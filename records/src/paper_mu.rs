//! The paper's machine utilization per experiment, setup and model
//! (`bench/experiments/paper_mu.csv`, marked on `tending plot bars`' MU chart).

use serde::Deserialize;

#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct PaperMuRecord {
    /// Experiment letter of the paper's section V (A, B, C, D).
    pub experiment: String,
    /// N.M_K or N_M_K.
    pub setup: String,
    pub model: String,
    pub mu: f64,
    pub std: Option<f64>,
    /// Where in the paper (table or figure).
    pub source: Option<String>,
}

#[cfg(test)]
mod tests {
    use super::super::read;
    use super::*;

    #[test]
    fn committed_paper_values_read() {
        let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../bench/experiments/paper_mu.csv");
        let rows: Vec<PaperMuRecord> = read(&p).unwrap().into_iter().map(|l| l.record).collect();
        assert!(rows.len() > 40);
        assert!(rows.iter().all(|r| (0.0..=1.0).contains(&r.mu)));
    }
}
