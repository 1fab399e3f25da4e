//! GRU cell unrolled over a chunk of T steps (PyTorch gate layout r, z, n):
//!
//! r = sigma(W_ir x + b_ir + W_hr h + b_hr)
//! z = sigma(W_iz x + b_iz + W_hz h + b_hz)
//! n = tanh(W_in x + b_in + r * (W_hn h + b_hn))
//! h' = (1 - z) * n + z * h
//!
//! Before step t the hidden state is multiplied by `masks[t, b]` (MAPPO convention: 1.0 =
//! episode continues, 0.0 = episode starts here and the hidden state is zeroed).
//! Rows are step-major: row `t * B + b`.

use super::gemm::{gemm, rm, tr};
use super::init::{fill, Init};
use super::params::{ParamStore, Slot};
use rand::Rng;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GruConfig {
    pub d_in: usize,
    pub hidden: usize,
}

#[derive(Debug, Clone, Copy)]
pub struct Gru {
    pub cfg: GruConfig,
    pub w_ih: Slot,
    pub w_hh: Slot,
    pub b_ih: Slot,
    pub b_hh: Slot,
}

#[derive(Debug, Clone, Default)]
pub struct GruCache {
    gates: Vec<f32>, // TB x 3H: r, z, n after their nonlinearity
    ghn: Vec<f32>,   // TB x H: W_hn h + b_hn
    hm: Vec<f32>,    // TB x H: masked previous hidden state
    masks: Vec<f32>, // TB
    gh: Vec<f32>,    // B x 3H scratch
    dgates: Vec<f32>,
    dgh: Vec<f32>,
    dhm: Vec<f32>,
    dh: Vec<f32>,
}

#[inline]
fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

fn sized(v: &mut Vec<f32>, n: usize) -> &mut [f32] {
    v.resize(n, 0.0);
    &mut v[..n]
}

impl Gru {
    /// Orthogonal weights (per gate block, as MAPPO's nn.init.orthogonal_ on the whole
    /// matrix), zero biases. Names follow PyTorch: weight_ih_l0, weight_hh_l0, bias_*.
    pub fn new(cfg: GruConfig, store: &mut ParamStore, name: &str, rng: &mut impl Rng) -> Self {
        let (i, h) = (cfg.d_in, cfg.hidden);
        let w_ih = store.alloc(&format!("{name}.weight_ih_l0"), &[3 * h, i]);
        let w_hh = store.alloc(&format!("{name}.weight_hh_l0"), &[3 * h, h]);
        let b_ih = store.alloc(&format!("{name}.bias_ih_l0"), &[3 * h]);
        let b_hh = store.alloc(&format!("{name}.bias_hh_l0"), &[3 * h]);
        let init = Init::Orthogonal { gain: 1.0 };
        fill(init, &mut store.data[w_ih.r()], 3 * h, i, rng);
        fill(init, &mut store.data[w_hh.r()], 3 * h, h, rng);
        Self {
            cfg,
            w_ih,
            w_hh,
            b_ih,
            b_hh,
        }
    }

    /// x: (T*B) x d_in, h0: B x H, masks: T*B; writes out: (T*B) x H (hidden after each step).
    #[allow(clippy::too_many_arguments)]
    pub fn forward(
        &self,
        p: &[f32],
        x: &[f32],
        t: usize,
        b: usize,
        h0: &[f32],
        masks: &[f32],
        c: &mut GruCache,
        out: &mut [f32],
    ) {
        let (di, h) = (self.cfg.d_in, self.cfg.hidden);
        let tb = t * b;
        assert!(h0.len() >= b * h && masks.len() >= tb && out.len() >= tb * h);
        c.masks.clear();
        c.masks.extend_from_slice(&masks[..tb]);
        let gates = sized(&mut c.gates, tb * 3 * h);
        let bih = &p[self.b_ih.r()];
        for row in gates.chunks_exact_mut(3 * h) {
            row.copy_from_slice(bih);
        }
        gemm(
            tb,
            di,
            3 * h,
            1.0,
            rm(x, di),
            tr(&p[self.w_ih.r()], di),
            1.0,
            gates,
            3 * h,
        );
        let ghn = sized(&mut c.ghn, tb * h);
        let hm = sized(&mut c.hm, tb * h);
        let gh = sized(&mut c.gh, b * 3 * h);
        let bhh = &p[self.b_hh.r()];
        let whh = &p[self.w_hh.r()];
        for s in 0..t {
            let rows = s * b..(s + 1) * b;
            {
                let (prev_all, _) = out.split_at(s * b * h);
                let prev = if s == 0 {
                    &h0[..b * h]
                } else {
                    &prev_all[(s - 1) * b * h..]
                };
                let hm_s = &mut hm[rows.start * h..rows.end * h];
                for bb in 0..b {
                    let m = masks[s * b + bb];
                    for k in 0..h {
                        hm_s[bb * h + k] = prev[bb * h + k] * m;
                    }
                }
            }
            for row in gh.chunks_exact_mut(3 * h) {
                row.copy_from_slice(bhh);
            }
            let hm_s = &hm[rows.start * h..rows.end * h];
            gemm(b, h, 3 * h, 1.0, rm(hm_s, h), tr(whh, h), 1.0, gh, 3 * h);
            for bb in 0..b {
                let row = s * b + bb;
                let g = &mut gates[row * 3 * h..(row + 1) * 3 * h];
                let ghr = &gh[bb * 3 * h..(bb + 1) * 3 * h];
                let hprev = &hm_s[bb * h..(bb + 1) * h];
                let o = &mut out[row * h..(row + 1) * h];
                let gn = &mut ghn[row * h..(row + 1) * h];
                for k in 0..h {
                    let r = sigmoid(g[k] + ghr[k]);
                    let z = sigmoid(g[h + k] + ghr[h + k]);
                    let n = (g[2 * h + k] + r * ghr[2 * h + k]).tanh();
                    g[k] = r;
                    g[h + k] = z;
                    g[2 * h + k] = n;
                    gn[k] = ghr[2 * h + k];
                    o[k] = (1.0 - z) * n + z * hprev[k];
                }
            }
        }
    }

    /// Backward through the whole chunk. Accumulates parameter grads, writes dx
    /// ((T*B) x d_in) and, if given, dh0 (B x H).
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        &self,
        p: &[f32],
        g: &mut [f32],
        x: &[f32],
        t: usize,
        b: usize,
        c: &mut GruCache,
        dout: &[f32],
        dx: &mut [f32],
        dh0: Option<&mut [f32]>,
    ) {
        let (di, h) = (self.cfg.d_in, self.cfg.hidden);
        let tb = t * b;
        let whh = &p[self.w_hh.r()];
        let dgates = sized(&mut c.dgates, tb * 3 * h);
        let dgh = sized(&mut c.dgh, tb * 3 * h);
        let dhm = sized(&mut c.dhm, b * h);
        let dh = sized(&mut c.dh, b * h);
        dh.iter_mut().for_each(|v| *v = 0.0);
        for s in (0..t).rev() {
            for bb in 0..b {
                let row = s * b + bb;
                let gt = &c.gates[row * 3 * h..(row + 1) * 3 * h];
                let gn = &c.ghn[row * h..(row + 1) * h];
                let hp = &c.hm[row * h..(row + 1) * h];
                let dg = &mut dgates[row * 3 * h..(row + 1) * 3 * h];
                let dgg = &mut dgh[row * 3 * h..(row + 1) * 3 * h];
                for k in 0..h {
                    let (r, z, n) = (gt[k], gt[h + k], gt[2 * h + k]);
                    let d = dout[row * h + k] + dh[bb * h + k];
                    let dn_pre = d * (1.0 - z) * (1.0 - n * n);
                    let dz_pre = d * (hp[k] - n) * z * (1.0 - z);
                    let dr_pre = dn_pre * gn[k] * r * (1.0 - r);
                    dg[k] = dr_pre;
                    dg[h + k] = dz_pre;
                    dg[2 * h + k] = dn_pre;
                    dgg[k] = dr_pre;
                    dgg[h + k] = dz_pre;
                    dgg[2 * h + k] = dn_pre * r;
                    dhm[bb * h + k] = d * z;
                }
            }
            let dgs = &dgh[s * b * 3 * h..(s + 1) * b * 3 * h];
            gemm(b, 3 * h, h, 1.0, rm(dgs, 3 * h), rm(whh, h), 1.0, dhm, h);
            for bb in 0..b {
                let m = c.masks[s * b + bb];
                for k in 0..h {
                    dh[bb * h + k] = dhm[bb * h + k] * m;
                }
            }
        }
        // parameter gradients over the whole chunk
        gemm(
            3 * h,
            tb,
            h,
            1.0,
            tr(dgh, 3 * h),
            rm(&c.hm, h),
            1.0,
            &mut g[self.w_hh.r()],
            h,
        );
        gemm(
            3 * h,
            tb,
            di,
            1.0,
            tr(dgates, 3 * h),
            rm(x, di),
            1.0,
            &mut g[self.w_ih.r()],
            di,
        );
        for (slot, src) in [(self.b_hh, &*dgh), (self.b_ih, &*dgates)] {
            let gb = &mut g[slot.r()];
            for row in src.chunks_exact(3 * h) {
                for (a, v) in gb.iter_mut().zip(row) {
                    *a += v;
                }
            }
        }
        gemm(
            tb,
            3 * h,
            di,
            1.0,
            rm(dgates, 3 * h),
            rm(&p[self.w_ih.r()], di),
            0.0,
            dx,
            di,
        );
        if let Some(d0) = dh0 {
            d0[..b * h].copy_from_slice(dh);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::gradcheck::*;
    use rand::SeedableRng;

    fn make(i: usize, h: usize) -> (ParamStore, Gru) {
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let mut s = ParamStore::new();
        let g = Gru::new(GruConfig { d_in: i, hidden: h }, &mut s, "gru", &mut rng);
        let rb = rand_vec(s.len(), 4);
        for r in [g.b_ih.r(), g.b_hh.r()] {
            for k in r {
                s.data[k] = 0.3 * rb[k];
            }
        }
        (s, g)
    }

    /// One textbook step for one row, f64.
    fn step_ref(gr: &Gru, p: &[f32], x: &[f32], hprev: &[f64]) -> Vec<f64> {
        let (i, h) = (gr.cfg.d_in, gr.cfg.hidden);
        let wih = &p[gr.w_ih.r()];
        let whh = &p[gr.w_hh.r()];
        let bih = &p[gr.b_ih.r()];
        let bhh = &p[gr.b_hh.r()];
        let gi = |r: usize| {
            bih[r] as f64
                + (0..i)
                    .map(|k| wih[r * i + k] as f64 * x[k] as f64)
                    .sum::<f64>()
        };
        let gh = |r: usize| {
            bhh[r] as f64
                + (0..h)
                    .map(|k| whh[r * h + k] as f64 * hprev[k])
                    .sum::<f64>()
        };
        let sg = |v: f64| 1.0 / (1.0 + (-v).exp());
        (0..h)
            .map(|k| {
                let r = sg(gi(k) + gh(k));
                let z = sg(gi(h + k) + gh(h + k));
                let n = (gi(2 * h + k) + r * gh(2 * h + k)).tanh();
                (1.0 - z) * n + z * hprev[k]
            })
            .collect()
    }

    #[test]
    fn matches_textbook_gru_with_resets() {
        let (s, g) = make(3, 4);
        let (t, b) = (3, 2);
        let x = rand_vec(t * b * 3, 1);
        let h0 = rand_vec(b * 4, 2);
        let masks = [1.0, 1.0, 0.0, 1.0, 1.0, 0.0];
        let mut c = GruCache::default();
        let mut out = vec![0.0; t * b * 4];
        g.forward(&s.data, &x, t, b, &h0, &masks, &mut c, &mut out);
        for bb in 0..b {
            let mut hp: Vec<f64> = h0[bb * 4..(bb + 1) * 4].iter().map(|v| *v as f64).collect();
            for st in 0..t {
                let m = masks[st * b + bb] as f64;
                hp.iter_mut().for_each(|v| *v *= m);
                let row = st * b + bb;
                hp = step_ref(&g, &s.data, &x[row * 3..(row + 1) * 3], &hp);
                for k in 0..4 {
                    assert!((out[row * 4 + k] as f64 - hp[k]).abs() < 1e-5);
                }
            }
        }
    }

    #[test]
    fn gradients_match_finite_differences() {
        let (mut s, g) = make(3, 4);
        let (t, b) = (3, 2);
        let x = rand_vec(t * b * 3, 1);
        let h0 = rand_vec(b * 4, 2);
        let masks = [1.0, 1.0, 1.0, 0.0, 1.0, 1.0];
        let r = rand_vec(t * b * 4, 3);
        let run = |p: &[f32], x: &[f32], h0: &[f32]| {
            let mut c = GruCache::default();
            let mut out = vec![0.0; t * b * 4];
            g.forward(p, x, t, b, h0, &masks, &mut c, &mut out);
            dot_loss(&out, &r)
        };
        let mut c = GruCache::default();
        let mut out = vec![0.0; t * b * 4];
        g.forward(&s.data, &x, t, b, &h0, &masks, &mut c, &mut out);
        let mut dx = vec![0.0; t * b * 3];
        let mut dh0 = vec![0.0; b * 4];
        let (p, gr) = s.split();
        g.backward(p, gr, &x, t, b, &mut c, &r, &mut dx, Some(&mut dh0));
        let num_p = numeric_grad(&mut s.data.clone(), |p| run(p, &x, &h0));
        assert_grad_close("params", &s.grad, &num_p);
        let num_x = numeric_grad(&mut x.clone(), |xx| run(&s.data, xx, &h0));
        assert_grad_close("x", &dx, &num_x);
        let num_h = numeric_grad(&mut h0.clone(), |hh| run(&s.data, &x, hh));
        assert_grad_close("h0", &dh0, &num_h);
        for e in &s.entries {
            assert!(s.grad[e.slot.r()].iter().any(|v| *v != 0.0), "{}", e.name);
        }
    }
}
