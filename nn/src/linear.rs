//! Fully connected layer: y = x W^T + b, W stored [d_out, d_in] as in PyTorch.

use super::gemm::{gemm, rm, tr};
use super::init::{fill, Init};
use super::params::{ParamStore, Slot};
use rand::Rng;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LinearConfig {
    pub d_in: usize,
    pub d_out: usize,
    pub init: Init,
}

#[derive(Debug, Clone, Copy)]
pub struct Linear {
    pub cfg: LinearConfig,
    pub w: Slot,
    pub b: Slot,
}

impl Linear {
    /// Allocates `<name>.weight` [d_out, d_in] and `<name>.bias` [d_out] (zeros).
    pub fn new(cfg: LinearConfig, store: &mut ParamStore, name: &str, rng: &mut impl Rng) -> Self {
        let w = store.alloc(&format!("{name}.weight"), &[cfg.d_out, cfg.d_in]);
        let b = store.alloc(&format!("{name}.bias"), &[cfg.d_out]);
        fill(cfg.init, &mut store.data[w.r()], cfg.d_out, cfg.d_in, rng);
        Self { cfg, w, b }
    }

    /// y[n, d_out] = x[n, d_in] W^T + b.
    pub fn forward(&self, p: &[f32], x: &[f32], n: usize, y: &mut [f32]) {
        let (di, d_o) = (self.cfg.d_in, self.cfg.d_out);
        debug_assert!(x.len() >= n * di && y.len() >= n * d_o);
        let b = &p[self.b.r()];
        for row in y[..n * d_o].chunks_exact_mut(d_o) {
            row.copy_from_slice(b);
        }
        gemm(
            n,
            di,
            d_o,
            1.0,
            rm(x, di),
            tr(&p[self.w.r()], di),
            1.0,
            y,
            d_o,
        );
    }

    /// Accumulates dW += dy^T x and db += sum(dy). If `dx` is given, writes dx = dy W
    /// (or adds it when `acc_dx`).
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        &self,
        p: &[f32],
        g: &mut [f32],
        x: &[f32],
        dy: &[f32],
        n: usize,
        dx: Option<&mut [f32]>,
        acc_dx: bool,
    ) {
        let (di, d_o) = (self.cfg.d_in, self.cfg.d_out);
        if di <= 4 {
            // Entity encoders (d_in 2-3) over ~10^5 rows: sgemm would pack the transposed
            // dy (rows x d_out) with a strided gather; a direct pass over the rows is faster.
            let mut acc = [[0.0f32; 256]; 4];
            let dw = &mut g[self.w.r()];
            for c0 in (0..d_o).step_by(256) {
                let w = (d_o - c0).min(256);
                acc.iter_mut()
                    .for_each(|a| a[..w].iter_mut().for_each(|v| *v = 0.0));
                for r in 0..n {
                    let dyr = &dy[r * d_o + c0..r * d_o + c0 + w];
                    for (i, a) in acc.iter_mut().enumerate().take(di) {
                        let xi = x[r * di + i];
                        for (v, d) in a[..w].iter_mut().zip(dyr) {
                            *v += xi * d;
                        }
                    }
                }
                for (i, a) in acc.iter().enumerate().take(di) {
                    for o in 0..w {
                        dw[(c0 + o) * di + i] += a[o];
                    }
                }
            }
        } else {
            gemm(
                d_o,
                n,
                di,
                1.0,
                tr(dy, d_o),
                rm(x, di),
                1.0,
                &mut g[self.w.r()],
                di,
            );
        }
        let gb = &mut g[self.b.r()];
        for row in dy[..n * d_o].chunks_exact(d_o) {
            for (a, b) in gb.iter_mut().zip(row) {
                *a += b;
            }
        }
        if let Some(dx) = dx {
            let beta = if acc_dx { 1.0 } else { 0.0 };
            gemm(
                n,
                d_o,
                di,
                1.0,
                rm(dy, d_o),
                rm(&p[self.w.r()], di),
                beta,
                dx,
                di,
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gradcheck::*;
    use rand::SeedableRng;

    #[test]
    fn forward_matches_naive() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(0);
        let mut s = ParamStore::new();
        let cfg = LinearConfig {
            d_in: 3,
            d_out: 2,
            init: Init::Uniform { scale: 1.0 },
        };
        let l = Linear::new(cfg, &mut s, "l", &mut rng);
        s.data[l.b.r()].copy_from_slice(&[0.5, -0.5]);
        let x = [1.0, 2.0, 3.0];
        let mut y = [0.0; 2];
        l.forward(&s.data, &x, 1, &mut y);
        let w = &s.data[l.w.r()];
        for o in 0..2 {
            let want: f32 = (0..3).map(|i| w[o * 3 + i] * x[i]).sum::<f32>() + [0.5, -0.5][o];
            assert!((y[o] - want).abs() < 1e-5);
        }
    }

    #[test]
    fn small_input_path_matches_finite_differences() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(4);
        let mut s = ParamStore::new();
        let cfg = LinearConfig {
            d_in: 3,
            d_out: 300,
            init: Init::Uniform { scale: 1.0 },
        };
        let l = Linear::new(cfg, &mut s, "l", &mut rng);
        let n = 4;
        let x = rand_vec(n * 3, 5);
        let r = rand_vec(n * 300, 6);
        let (p, g) = s.split();
        l.backward(p, g, &x, &r, n, None, false);
        let num = numeric_grad(&mut s.data.clone(), |p| {
            let mut y = vec![0.0; n * 300];
            l.forward(p, &x, n, &mut y);
            dot_loss(&y, &r)
        });
        assert_grad_close("params", &s.grad, &num);
    }

    #[test]
    fn gradients_match_finite_differences() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(1);
        let mut s = ParamStore::new();
        let cfg = LinearConfig {
            d_in: 5,
            d_out: 4,
            init: Init::Orthogonal { gain: 1.0 },
        };
        let l = Linear::new(cfg, &mut s, "l", &mut rng);
        s.data[l.b.r()].copy_from_slice(&[0.1, 0.2, -0.3, 0.4]);
        let n = 3;
        let x = rand_vec(n * 5, 2);
        let r = rand_vec(n * 4, 3);
        let mut dx = vec![0.0; n * 5];
        let (p, g) = s.split();
        l.backward(p, g, &x, &r, n, Some(&mut dx), false);
        let loss = |p: &[f32], x: &[f32]| {
            let mut y = vec![0.0; n * 4];
            l.forward(p, x, n, &mut y);
            dot_loss(&y, &r)
        };
        let mut pd = s.data.clone();
        let num_p = numeric_grad(&mut pd, |p| loss(p, &x));
        assert_grad_close("params", &s.grad, &num_p);
        let num_x = numeric_grad(&mut x.clone(), |xx| loss(&s.data, xx));
        assert_grad_close("x", &dx, &num_x);
        assert!(s.grad.iter().all(|g| *g != 0.0));
        // accumulate mode adds
        let mut dx2 = dx.clone();
        l.backward(
            &s.data,
            &mut vec![0.0; s.len()],
            &x,
            &r,
            n,
            Some(&mut dx2),
            true,
        );
        for (a, b) in dx2.iter().zip(&dx) {
            assert!((a - 2.0 * b).abs() < 1e-5);
        }
    }
}
