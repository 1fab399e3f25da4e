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
        let full = n / ROWS * ROWS;
        for r0 in (0..full).step_by(ROWS) {
            self.forward_rows::<ROWS>(gm, bt, x, r0, y, mean, rstd, d);
        }
        for r0 in full..n {
            self.forward_rows::<1>(gm, bt, x, r0, y, mean, rstd, d);
        }
    }

    /// [`forward`](Self::forward) of rows r0..r0+R. Each row's sums run in its own order
    /// (left to right, as `Iterator::sum`), but the R rows' chains are interleaved: one
    /// row's 64 dependent additions were latency-bound.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn forward_rows<const R: usize>(
        &self,
        gm: &[f32],
        bt: &[f32],
        x: &[f32],
        r0: usize,
        y: &mut [f32],
        mean: &mut [f32],
        rstd: &mut [f32],
        d: usize,
    ) {
        let x = &x[r0 * d..(r0 + R) * d];
        let mut m = [SUM_START; R];
        for i in 0..d {
            for j in 0..R {
                m[j] += x[j * d + i];
            }
        }
        let mut var = [SUM_START; R];
        for mj in m.iter_mut() {
            *mj /= d as f32;
        }
        for i in 0..d {
            for j in 0..R {
                let t = x[j * d + i] - m[j];
                var[j] += t * t;
            }
        }
        for j in 0..R {
            let rs = 1.0 / (var[j] / d as f32 + self.cfg.eps).sqrt();
            mean[r0 + j] = m[j];
            rstd[r0 + j] = rs;
            let (xr, yr) = (
                &x[j * d..(j + 1) * d],
                &mut y[(r0 + j) * d..(r0 + j + 1) * d],
            );
            for i in 0..d {
                yr[i] = (xr[i] - m[j]) * rs * gm[i] + bt[i];
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
        let full = n / ROWS * ROWS;
        for r0 in (0..full).step_by(ROWS) {
            backward_rows::<ROWS>(gm, gg, gb, x, dy, r0, mean, rstd, dx, d);
        }
        for r0 in full..n {
            backward_rows::<1>(gm, gg, gb, x, dy, r0, mean, rstd, dx, d);
        }
    }
}

/// Rows whose sums are interleaved (independent dependency chains in flight).
const ROWS: usize = 8;

/// The start of `Iterator::sum` for f32 (the sums here must keep its bits).
const SUM_START: f32 = -0.0;

/// [`LayerNorm::backward`] of rows r0..r0+R: per row the sums s1, s2 in index order and the
/// gamma/beta gradients in row order, as one row at a time, with the R rows' chains
/// interleaved.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn backward_rows<const R: usize>(
    gm: &[f32],
    gg: &mut [f32],
    gb: &mut [f32],
    x: &[f32],
    dy: &[f32],
    r0: usize,
    mean: &[f32],
    rstd: &[f32],
    dx: &mut [f32],
    d: usize,
) {
    let (x, dy) = (&x[r0 * d..(r0 + R) * d], &dy[r0 * d..(r0 + R) * d]);
    let (m, rs) = (&mean[r0..r0 + R], &rstd[r0..r0 + R]);
    let mut s1 = [0.0f32; R];
    let mut s2 = [0.0f32; R];
    for i in 0..d {
        for j in 0..R {
            let xh = (x[j * d + i] - m[j]) * rs[j];
            let dyi = dy[j * d + i];
            gg[i] += dyi * xh;
            gb[i] += dyi;
            let dxh = dyi * gm[i];
            s1[j] += dxh;
            s2[j] += dxh * xh;
        }
    }
    for j in 0..R {
        s1[j] /= d as f32;
        s2[j] /= d as f32;
        let dxr = &mut dx[(r0 + j) * d..(r0 + j + 1) * d];
        for i in 0..d {
            let xh = (x[j * d + i] - m[j]) * rs[j];
            dxr[i] = rs[j] * (dy[j * d + i] * gm[i] - s1[j] - xh * s2[j]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gradcheck::*;

    /// The interleaved rows give the bits of the plain one-row-at-a-time loops (kept here
    /// as the reference), including rows of signed zeros and a remainder block.
    #[test]
    fn interleaved_rows_have_the_one_row_bits() {
        let (d, n) = (64, 19);
        let mut s = ParamStore::new();
        let ln = LayerNorm::new(LayerNormConfig::new(d), &mut s, "ln");
        s.data = rand_vec(s.data.len(), 7);
        let mut x = rand_vec(n * d, 8);
        x[..d].iter_mut().for_each(|v| *v = -0.0);
        x[d..2 * d]
            .iter_mut()
            .enumerate()
            .for_each(|(i, v)| *v = if i % 2 == 0 { 0.0 } else { -0.0 });
        let dy = rand_vec(n * d, 9);
        let (gm, bt) = (&s.data[ln.gamma.r()], &s.data[ln.beta.r()]);
        // reference
        let (mut y0, mut m0, mut r0) = (vec![0.0; n * d], vec![0.0; n], vec![0.0; n]);
        let (mut gg0, mut gb0, mut dx0) = (vec![0.0f32; d], vec![0.0f32; d], vec![0.0; n * d]);
        for r in 0..n {
            let xr = &x[r * d..(r + 1) * d];
            let m = xr.iter().sum::<f32>() / d as f32;
            let var = xr.iter().map(|v| (v - m) * (v - m)).sum::<f32>() / d as f32;
            let rs = 1.0 / (var + ln.cfg.eps).sqrt();
            (m0[r], r0[r]) = (m, rs);
            for i in 0..d {
                y0[r * d + i] = (xr[i] - m) * rs * gm[i] + bt[i];
            }
            let dyr = &dy[r * d..(r + 1) * d];
            let (mut s1, mut s2) = (0.0f32, 0.0f32);
            for i in 0..d {
                let xh = (xr[i] - m) * rs;
                gg0[i] += dyr[i] * xh;
                gb0[i] += dyr[i];
                let dxh = dyr[i] * gm[i];
                s1 += dxh;
                s2 += dxh * xh;
            }
            s1 /= d as f32;
            s2 /= d as f32;
            for i in 0..d {
                let xh = (xr[i] - m) * rs;
                dx0[r * d + i] = rs * (dyr[i] * gm[i] - s1 - xh * s2);
            }
        }
        let (mut y, mut m, mut r) = (vec![0.0; n * d], vec![0.0; n], vec![0.0; n]);
        ln.forward(&s.data, &x, n, &mut y, &mut m, &mut r);
        let mut g = vec![0.0f32; s.data.len()];
        let mut dx = vec![0.0; n * d];
        ln.backward(&s.data, &mut g, &x, &dy, n, &m, &r, &mut dx);
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&y), bits(&y0));
        assert_eq!(bits(&m), bits(&m0));
        assert_eq!(bits(&r), bits(&r0));
        assert_eq!(bits(&dx), bits(&dx0));
        assert_eq!(bits(&g[ln.gamma.r()]), bits(&gg0));
        assert_eq!(bits(&g[ln.beta.r()]), bits(&gb0));
    }

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
