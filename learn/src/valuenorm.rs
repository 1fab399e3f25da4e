//! MAPPO's `ValueNorm` (onpolicy/utils/valuenorm.py): running mean and mean of squares of
//! the returns with decay `beta` and a debiasing term, so the critic learns normalised
//! targets. Kept in f64 like the reference (float64 buffers there too).

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq)]
pub struct ValueNorm {
    pub beta: f64,
    pub running_mean: f64,
    pub running_mean_sq: f64,
    pub debiasing_term: f64,
}

/// Exact (bit-level) serialisation: JSON floats may lose the last bit on parsing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ValueNormBits {
    pub beta: u64,
    pub mean: u64,
    pub mean_sq: u64,
    pub debias: u64,
}

const EPS: f64 = 1e-5;

impl ValueNorm {
    pub fn new(beta: f64) -> Self {
        Self {
            beta,
            running_mean: 0.0,
            running_mean_sq: 0.0,
            debiasing_term: 0.0,
        }
    }

    /// Fold a batch of (unnormalised) returns into the running statistics.
    pub fn update(&mut self, x: &[f32]) {
        if x.is_empty() {
            return;
        }
        let n = x.len() as f64;
        let mean = x.iter().map(|&v| v as f64).sum::<f64>() / n;
        let mean_sq = x.iter().map(|&v| (v as f64) * (v as f64)).sum::<f64>() / n;
        let b = self.beta;
        self.running_mean = self.running_mean * b + mean * (1.0 - b);
        self.running_mean_sq = self.running_mean_sq * b + mean_sq * (1.0 - b);
        self.debiasing_term = self.debiasing_term * b + (1.0 - b);
    }

    /// Debiased (mean, var); var clamped below at 1e-2 as in the reference.
    pub fn mean_var(&self) -> (f64, f64) {
        let d = self.debiasing_term.max(EPS);
        let mean = self.running_mean / d;
        let mean_sq = self.running_mean_sq / d;
        (mean, (mean_sq - mean * mean).max(1e-2))
    }

    pub fn normalize(&self, x: f32) -> f32 {
        let (m, v) = self.mean_var();
        ((x as f64 - m) / v.sqrt()) as f32
    }

    pub fn denormalize(&self, x: f32) -> f32 {
        let (m, v) = self.mean_var();
        (x as f64 * v.sqrt() + m) as f32
    }

    pub fn to_bits(&self) -> ValueNormBits {
        ValueNormBits {
            beta: self.beta.to_bits(),
            mean: self.running_mean.to_bits(),
            mean_sq: self.running_mean_sq.to_bits(),
            debias: self.debiasing_term.to_bits(),
        }
    }

    pub fn from_bits(b: ValueNormBits) -> Self {
        Self {
            beta: f64::from_bits(b.beta),
            running_mean: f64::from_bits(b.mean),
            running_mean_sq: f64::from_bits(b.mean_sq),
            debiasing_term: f64::from_bits(b.debias),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reference computation written out from valuenorm.py for two updates with
    /// beta = 0.9 (numbers by hand):
    /// batch 1 = [1, 3]: mean 2, mean_sq 5 -> rm = 0.2, rmsq = 0.5, d = 0.1
    ///   debiased mean 2, var 5 - 4 = 1.
    /// batch 2 = [4]: rm = 0.18 + 0.4 = 0.58, rmsq = 0.45 + 1.6 = 2.05, d = 0.19
    ///   mean = 0.58/0.19 = 3.0526315..., mean_sq = 10.789473..., var = 1.4709141...
    #[test]
    fn matches_reference_computation() {
        let mut vn = ValueNorm::new(0.9);
        vn.update(&[1.0, 3.0]);
        let (m, v) = vn.mean_var();
        assert!((m - 2.0).abs() < 1e-12, "{m}");
        assert!((v - 1.0).abs() < 1e-12, "{v}");
        assert!((vn.normalize(3.0) - 1.0).abs() < 1e-6);
        assert!((vn.denormalize(-1.0) - 1.0).abs() < 1e-6);
        vn.update(&[4.0]);
        let (m, v) = vn.mean_var();
        let em = 0.58 / 0.19;
        let ev = 2.05 / 0.19 - em * em;
        assert!((m - em).abs() < 1e-9, "{m} vs {em}");
        assert!((v - ev).abs() < 1e-9, "{v} vs {ev}");
        assert!((em - 3.052_631_578_9).abs() < 1e-9);
        assert!((ev - 1.470_914_127_4).abs() < 1e-9);
        // round trip through normalize / denormalize
        let x = 7.25f32;
        assert!((vn.denormalize(vn.normalize(x)) - x).abs() < 1e-5);
        // exact serialisation
        assert_eq!(ValueNorm::from_bits(vn.to_bits()), vn);
    }

    #[test]
    fn variance_floor_and_empty_state() {
        let vn = ValueNorm::new(0.99999);
        // never updated: mean 0, var floored at 0.01 (debias clamped at eps)
        let (m, v) = vn.mean_var();
        assert_eq!(m, 0.0);
        assert!((v - 1e-2).abs() < 1e-15);
        let mut vn = ValueNorm::new(0.99999);
        vn.update(&[5.0, 5.0, 5.0]);
        let (m, v) = vn.mean_var();
        assert!((m - 5.0).abs() < 1e-6);
        assert!(
            (v - 1e-2).abs() < 1e-6,
            "constant returns hit the floor: {v}"
        );
    }
}
