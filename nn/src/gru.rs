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

use super::fastmath::{sigmoid, tanh};
use super::gemm::{gemm, rm, tr};
use super::init::{fill, Init};
use super::params::{ParamStore, Slot};
use super::simd::dispatch;
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
    whh_t: Vec<f32>, // H x 3H: W_hh transposed once per forward, not once per step's GEMM
    dgates: Vec<f32>,
    dgh: Vec<f32>,
    dhm: Vec<f32>,
    dh: Vec<f32>,
}

/// One row of [`step_rows`]. Every slice is its own argument so the compiler knows they do
/// not overlap (slices split inside one function do not carry that), and the lengths are
/// pinned up front: both are needed for the loop to vectorise.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn gates_row(
    gr: &mut [f32],
    gz: &mut [f32],
    gn: &mut [f32],
    hr: &[f32],
    hz: &[f32],
    hn: &[f32],
    hprev: &[f32],
    o: &mut [f32],
    ghn: &mut [f32],
) {
    let h = o.len();
    let (gr, gz, gn) = (&mut gr[..h], &mut gz[..h], &mut gn[..h]);
    let (hr, hz, hn, hprev, ghn) = (&hr[..h], &hz[..h], &hn[..h], &hprev[..h], &mut ghn[..h]);
    for k in 0..h {
        let r = sigmoid(gr[k] + hr[k]);
        let z = sigmoid(gz[k] + hz[k]);
        let n = tanh(gn[k] + r * hn[k]);
        gr[k] = r;
        gz[k] = z;
        gn[k] = n;
        ghn[k] = hn[k];
        o[k] = (1.0 - z) * n + z * hprev[k];
    }
}

/// One row of [`step_rows_backward`] (separate arguments for the same reason as
/// [`gates_row`]).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn gates_row_backward(
    gr: &[f32],
    gz: &[f32],
    gnn: &[f32],
    gn: &[f32],
    hp: &[f32],
    dor: &[f32],
    dhr: &[f32],
    d_r: &mut [f32],
    d_z: &mut [f32],
    d_n: &mut [f32],
    e_r: &mut [f32],
    e_z: &mut [f32],
    e_n: &mut [f32],
    dhmr: &mut [f32],
) {
    let h = dhmr.len();
    let (gr, gz, gnn, gn, hp) = (&gr[..h], &gz[..h], &gnn[..h], &gn[..h], &hp[..h]);
    let (dor, dhr) = (&dor[..h], &dhr[..h]);
    let (d_r, d_z, d_n) = (&mut d_r[..h], &mut d_z[..h], &mut d_n[..h]);
    let (e_r, e_z, e_n) = (&mut e_r[..h], &mut e_z[..h], &mut e_n[..h]);
    for k in 0..h {
        let (r, z, n) = (gr[k], gz[k], gnn[k]);
        let d = dor[k] + dhr[k];
        let dn_pre = d * (1.0 - z) * (1.0 - n * n);
        let dz_pre = d * (hp[k] - n) * z * (1.0 - z);
        let dr_pre = dn_pre * gn[k] * r * (1.0 - r);
        d_r[k] = dr_pre;
        d_z[k] = dz_pre;
        d_n[k] = dn_pre;
        e_r[k] = dr_pre;
        e_z[k] = dz_pre;
        e_n[k] = dn_pre * r;
        dhmr[k] = d * z;
    }
}

dispatch! {
    /// Gates and new hidden state of one step for B rows (the elementwise part), with the
    /// branch-free `fastmath` sigmoid/tanh so the loop vectorises.
    fn step_rows(
        gates: &mut [f32],
        gh: &[f32],
        hm: &[f32],
        out: &mut [f32],
        ghn: &mut [f32],
        b: usize,
        h: usize,
    ) {
        for bb in 0..b {
            let g = &mut gates[bb * 3 * h..(bb + 1) * 3 * h];
            let ghr = &gh[bb * 3 * h..(bb + 1) * 3 * h];
            let hprev = &hm[bb * h..(bb + 1) * h];
            let o = &mut out[bb * h..(bb + 1) * h];
            let gn = &mut ghn[bb * h..(bb + 1) * h];
            let (gr, rest) = g.split_at_mut(h);
            let (gz, gnn) = rest.split_at_mut(h);
            let (hr, rest) = ghr.split_at(h);
            let (hz, hn) = rest.split_at(h);
            gates_row(gr, gz, gnn, hr, hz, hn, hprev, o, gn);
        }
    }
}

dispatch! {
    /// Backward of [`step_rows`] for the B rows of one step: gate gradients (input side
    /// `dg`, hidden side `dgg`) and the direct hidden-state gradient `dhm` = d * z.
    fn step_rows_backward(
        gates: &[f32],
        ghn: &[f32],
        hm: &[f32],
        dout: &[f32],
        dh: &[f32],
        dg: &mut [f32],
        dgg: &mut [f32],
        dhm: &mut [f32],
        b: usize,
        h: usize,
    ) {
        for bb in 0..b {
            let gt = &gates[bb * 3 * h..(bb + 1) * 3 * h];
            let gn = &ghn[bb * h..(bb + 1) * h];
            let hp = &hm[bb * h..(bb + 1) * h];
            let dor = &dout[bb * h..(bb + 1) * h];
            let dhr = &dh[bb * h..(bb + 1) * h];
            let dgr = &mut dg[bb * 3 * h..(bb + 1) * 3 * h];
            let dggr = &mut dgg[bb * 3 * h..(bb + 1) * 3 * h];
            let dhmr = &mut dhm[bb * h..(bb + 1) * h];
            let (gr, rest) = gt.split_at(h);
            let (gz, gnn) = rest.split_at(h);
            let (d_r, rest) = dgr.split_at_mut(h);
            let (d_z, d_n) = rest.split_at_mut(h);
            let (e_r, rest) = dggr.split_at_mut(h);
            let (e_z, e_n) = rest.split_at_mut(h);
            gates_row_backward(gr, gz, gnn, gn, hp, dor, dhr, d_r, d_z, d_n, e_r, e_z, e_n, dhmr);
        }
    }
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
        // W_hh^T row-major, copied once for all T steps when the steps are GEMMs; a single
        // robot's decision (a few rows) reads W_hh in place (dot products, no copy).
        let whh_view = if b > 4 {
            let whh_t = sized(&mut c.whh_t, h * 3 * h);
            for (o, row) in whh.chunks_exact(h).enumerate() {
                for (i, x) in row.iter().enumerate() {
                    whh_t[i * 3 * h + o] = *x;
                }
            }
            rm(&c.whh_t[..h * 3 * h], 3 * h)
        } else {
            tr(whh, h)
        };
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
            gemm(b, h, 3 * h, 1.0, rm(hm_s, h), whh_view, 1.0, gh, 3 * h);
            let rr = rows.start * 3 * h..rows.end * 3 * h;
            let hr = rows.start * h..rows.end * h;
            step_rows(
                &mut gates[rr],
                gh,
                hm_s,
                &mut out[hr.clone()],
                &mut ghn[hr],
                b,
                h,
            );
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
            let rr = s * b * 3 * h..(s + 1) * b * 3 * h;
            let hr = s * b * h..(s + 1) * b * h;
            step_rows_backward(
                &c.gates[rr.clone()],
                &c.ghn[hr.clone()],
                &c.hm[hr.clone()],
                &dout[hr],
                dh,
                &mut dgates[rr.clone()],
                &mut dgh[rr],
                dhm,
                b,
                h,
            );
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
    use crate::gradcheck::*;
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

    /// The dispatched gate loops give the same bits at every SIMD level (they vectorise
    /// only where the CPU has AVX2 / AVX-512).
    #[test]
    fn same_bits_at_every_simd_level() {
        let (s, g) = make(5, 64);
        let (t, b) = (3, 7);
        let x = rand_vec(t * b * 5, 1);
        let h0 = rand_vec(b * 64, 2);
        let masks = [1.0; 21];
        let r = rand_vec(t * b * 64, 3);
        let runs = crate::simd::tests::at_every_level(|| {
            let mut c = GruCache::default();
            let mut out = vec![0.0; t * b * 64];
            g.forward(&s.data, &x, t, b, &h0, &masks, &mut c, &mut out);
            let mut gr = vec![0.0; s.len()];
            let mut dx = vec![0.0; t * b * 5];
            g.backward(&s.data, &mut gr, &x, t, b, &mut c, &r, &mut dx, None);
            (out, gr, dx)
        });
        assert!(runs.windows(2).all(|w| w[0] == w[1]));
    }
}
