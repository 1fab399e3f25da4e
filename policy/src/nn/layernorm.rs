//! Layer normalisation over the last dimension with learnable gamma (weight) / beta (bias).

use super::params::{ParamStore, Slot};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LayerNormConfig {
    pub dim: usize,
    pub eps: f32,
}

impl LayerNormConfig {
    pub fn new(dim: usize) -> Self {
        Self { dim, eps: 1e-5 }
    }
}

#[derive(Debug, Clone, Copy)]
pub struct LayerNorm {
    pub cfg: LayerNormConfig,
    pub gamma: Slot,
    pub beta: Slot,
}

impl LayerNorm {
    /// `<name>.weight` (ones) and `<name>.bias` (zeros), as PyTorch names them.
    pub fn new(cfg: LayerNormConfig, store: &mut ParamStore, name: &str) -> Self {
        let gamma = store.alloc(&format!("{name}.weight"), &[cfg.dim]);
        let beta = store.alloc(&format!("{name}.bias"), &[cfg.dim]);
        store.data[gamma.r()].iter_mut().for_each(|x| *x = 1.0);
        Self { cfg, gamma, beta }
    }

    /// y = (x - mean) * rstd * gamma + beta per row; keeps mean and rstd (n each).
    pub fn forward(
        &self,
        p: &[f32],
        x: &[f32],
        n: usize,
        y: &mut [f32],
        mean: &mut [f32],
        rstd: &mut [f32],
    ) {
        let d = self.cfg.dim;
        let (gm, bt) = (&p[self.gamma.r()], &p[self.beta.r()]);
        for r in 0..n {
            let xr = &x[r * d..(r + 1) * d];
            let m = xr.iter().sum::<f32>() / d as f32;
            let var = xr.iter().map(|v| (v - m) * (v - m)).sum::<f32>() / d as f32;
            let rs = 1.0 / (var + self.cfg.eps).sqrt();
            mean[r] = m;
            rstd[r] = rs;
            let yr = &mut y[r * d..(r + 1) * d];
            for i in 0..d {
                yr[i] = (xr[i] - m) * rs * gm[i] + bt[i];
            }
        }
    }

    /// Accumulates dgamma, dbeta; writes dx.
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        &self,
        p: &[f32],
        g: &mut [f32],
        x: &[f32],
        dy: &[f32],
        n: usize,
        mean: &[f32],
        rstd: &[f32],
        dx: &mut [f32],
    ) {
        let d = self.cfg.dim;
        let gm = &p[self.gamma.r()];
        let (gg, gb) = {
            let (a, b) = (self.gamma.r(), self.beta.r());
            debug_assert!(a.end <= b.start || b.end <= a.start);
            // gamma and beta are allocated back to back: split once.
            let (lo, hi) = g.split_at_mut(b.start);
            (&mut lo[a], &mut hi[..b.len()])
        };
        for r in 0..n {
            let xr = &x[r * d..(r + 1) * d];
            let dyr = &dy[r * d..(r + 1) * d];
            let (m, rs) = (mean[r], rstd[r]);
            let mut s1 = 0.0f32;
            let mut s2 = 0.0f32;
            for i in 0..d {
                let xh = (xr[i] - m) * rs;
                gg[i] += dyr[i] * xh;
                gb[i] += dyr[i];
                let dxh = dyr[i] * gm[i];
                s1 += dxh;
                s2 += dxh * xh;
            }
            s1 /= d as f32;
            s2 /= d as f32;
            let dxr = &mut dx[r * d..(r + 1) * d];
            for i in 0..d {
                let xh = (xr[i] - m) * rs;
                dxr[i] = rs * (dyr[i] * gm[i] - s1 - xh * s2);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::gradcheck::*;

    #[test]
    fn normalises_rows() {
        let mut s = ParamStore::new();
        let ln = LayerNorm::new(LayerNormConfig::new(4), &mut s, "ln");
        let x = [1.0, 2.0, 3.0, 4.0];
        let (mut y, mut m, mut r) = ([0.0; 4], [0.0], [0.0]);
        ln.forward(&s.data, &x, 1, &mut y, &mut m, &mut r);
        assert!((y.iter().sum::<f32>()).abs() < 1e-5);
        assert!((y.iter().map(|v| v * v).sum::<f32>() / 4.0 - 1.0).abs() < 1e-3);
    }

    #[test]
    fn gradients_match_finite_differences() {
        let mut s = ParamStore::new();
        let ln = LayerNorm::new(LayerNormConfig::new(6), &mut s, "ln");
        let rv = rand_vec(12, 9);
        for (i, v) in s.data.iter_mut().enumerate() {
            *v += 0.3 * rv[i];
        }
        let n = 3;
        let x = rand_vec(n * 6, 10);
        let r = rand_vec(n * 6, 11);
        let run = |p: &[f32], x: &[f32]| {
            let (mut y, mut m, mut rs) = (vec![0.0; n * 6], vec![0.0; n], vec![0.0; n]);
            ln.forward(p, x, n, &mut y, &mut m, &mut rs);
            (dot_loss(&y, &r), m, rs)
        };
        let (_, m, rs) = run(&s.data, &x);
        let mut dx = vec![0.0; n * 6];
        let (p, g) = s.split();
        ln.backward(p, g, &x, &r, n, &m, &rs, &mut dx);
        let num_p = numeric_grad(&mut s.data.clone(), |p| run(p, &x).0);
        assert_grad_close("params", &s.grad, &num_p);
        let num_x = numeric_grad(&mut x.clone(), |xx| run(&s.data, xx).0);
        assert_grad_close("x", &dx, &num_x);
        assert!(s.grad.iter().all(|g| *g != 0.0));
    }
}
