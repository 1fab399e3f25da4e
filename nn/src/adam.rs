//! Adam (PyTorch semantics, bias-corrected) and global gradient-norm clipping.

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AdamConfig {
    pub lr: f32,
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
}

impl Default for AdamConfig {
    /// MAPPO: lr 5e-4, eps 1e-5.
    fn default() -> Self {
        Self {
            lr: 5e-4,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-5,
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Adam {
    pub cfg: AdamConfig,
    pub m: Vec<f32>,
    pub v: Vec<f32>,
    pub t: u64,
}

impl Adam {
    pub fn new(cfg: AdamConfig, n_params: usize) -> Self {
        Self {
            cfg,
            m: vec![0.0; n_params],
            v: vec![0.0; n_params],
            t: 0,
        }
    }

    pub fn step(&mut self, params: &mut [f32], grads: &[f32]) {
        assert_eq!(params.len(), self.m.len());
        assert_eq!(grads.len(), self.m.len());
        self.t += 1;
        let c = self.cfg;
        let bc1 = 1.0 - (c.beta1 as f64).powi(self.t as i32);
        let bc2 = 1.0 - (c.beta2 as f64).powi(self.t as i32);
        let step = (c.lr as f64 / bc1) as f32;
        let bc2_sqrt = bc2.sqrt() as f32;
        for i in 0..params.len() {
            let g = grads[i];
            let m = c.beta1 * self.m[i] + (1.0 - c.beta1) * g;
            let v = c.beta2 * self.v[i] + (1.0 - c.beta2) * g * g;
            self.m[i] = m;
            self.v[i] = v;
            params[i] -= step * m / (v.sqrt() / bc2_sqrt + c.eps);
        }
    }
}

impl Adam {
    /// One training step of `params`: clip the global gradient norm to `max_grad_norm`
    /// (MAPPO: 10), Adam step, zero the gradients. Returns the norm before clipping.
    pub fn step_clipped(&mut self, params: &mut super::ParamStore, max_grad_norm: f32) -> f32 {
        let norm = clip_grad_norm(&mut params.grad, max_grad_norm);
        self.step(&mut params.data, &params.grad);
        params.zero_grad();
        norm
    }
}

/// Scale `grads` so their global L2 norm is at most `max_norm` (torch clip_grad_norm_:
/// factor max_norm / (norm + 1e-6) when norm > max_norm). Returns the norm before clipping.
pub fn clip_grad_norm(grads: &mut [f32], max_norm: f32) -> f32 {
    let norm = grads
        .iter()
        .map(|g| (*g as f64) * (*g as f64))
        .sum::<f64>()
        .sqrt() as f32;
    if norm > max_norm {
        let f = max_norm / (norm + 1e-6);
        grads.iter_mut().for_each(|g| *g *= f);
    }
    norm
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_step_moves_by_lr_against_gradient_sign() {
        let mut a = Adam::new(AdamConfig::default(), 2);
        let mut p = [1.0, 1.0];
        a.step(&mut p, &[0.5, -2.0]);
        assert!((p[0] - (1.0 - 5e-4)).abs() < 1e-6);
        assert!((p[1] - (1.0 + 5e-4)).abs() < 1e-6);
        assert_eq!(a.t, 1);
    }

    #[test]
    fn minimises_a_quadratic() {
        let mut a = Adam::new(
            AdamConfig {
                lr: 0.05,
                ..Default::default()
            },
            3,
        );
        let target = [1.0, -2.0, 0.5];
        let mut p = [0.0f32; 3];
        for _ in 0..2000 {
            let g: Vec<f32> = p.iter().zip(&target).map(|(x, t)| 2.0 * (x - t)).collect();
            a.step(&mut p, &g);
        }
        for (x, t) in p.iter().zip(&target) {
            assert!((x - t).abs() < 1e-2, "{x} vs {t}");
        }
    }

    #[test]
    fn clipping_scales_to_max_norm() {
        let mut g = [3.0, 4.0];
        let n = clip_grad_norm(&mut g, 1.0);
        assert!((n - 5.0).abs() < 1e-6);
        assert!(((g[0] * g[0] + g[1] * g[1]).sqrt() - 1.0).abs() < 1e-5);
        let mut small = [0.1, 0.1];
        clip_grad_norm(&mut small, 1.0);
        assert_eq!(small, [0.1, 0.1]);
    }
}
