//! Multi-head attention with ONE query per row over a set of S keys/values per row
//! (PyTorch `nn.MultiheadAttention` semantics and parameter layout: `in_proj_weight`
//! [3E, E] = [Wq; Wk; Wv], `in_proj_bias` [3E], `out_proj`).
//!
//! Computed without materialising K and V: for head h,
//! score_j = (q_h . (Wk_h e_j + bk_h)) / sqrt(dh) = (Wk_h^T q_h / sqrt(dh)) . e_j + const,
//! and sum_j a_j (Wv_h e_j + bv_h) = Wv_h (sum_j a_j e_j) + bv_h (the a_j sum to 1).
//! That is the same function (bk_h shifts every score of a row equally, so softmax ignores
//! it, in PyTorch too) at S*H*E instead of S*E*E multiply-adds per row.
//!
//! With S = 0 the attention result is a zero vector, so the output is `out_proj.bias`.

use super::dot;
use super::gemm::{gemm, rm, tr, View};
use super::init::Init;
use super::linear::{Linear, LinearConfig};
use super::params::{ParamStore, Slot};
use rand::Rng;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MhaConfig {
    pub dim: usize,
    pub heads: usize,
}

#[derive(Debug, Clone, Copy)]
pub struct MultiHeadAttention {
    pub cfg: MhaConfig,
    pub in_w: Slot,
    pub in_b: Slot,
    pub out: Linear,
}

/// Activations (forward) and scratch (backward) of one attention instance.
#[derive(Debug, Clone, Default)]
pub struct MhaCache {
    q: Vec<f32>,    // B x E
    u: Vec<f32>,    // B x H x E (scaled Wk_h^T q_h)
    a: Vec<f32>,    // B x H x S (softmax weights)
    ebar: Vec<f32>, // B x H x E (sum_j a_j e_j)
    o: Vec<f32>,    // B x E (concatenated heads, before out_proj)
    d_o: Vec<f32>,
    d_ebar: Vec<f32>,
    d_u: Vec<f32>,
    d_q: Vec<f32>,
    ds: Vec<f32>,
}

#[inline]
fn axpy(y: &mut [f32], alpha: f32, x: &[f32]) {
    for (a, b) in y.iter_mut().zip(x) {
        *a += alpha * b;
    }
}

fn sized(v: &mut Vec<f32>, n: usize) -> &mut [f32] {
    v.resize(n, 0.0);
    &mut v[..n]
}

impl MultiHeadAttention {
    pub fn new(cfg: MhaConfig, store: &mut ParamStore, name: &str, rng: &mut impl Rng) -> Self {
        assert!(
            cfg.heads > 0 && cfg.dim.is_multiple_of(cfg.heads),
            "dim % heads != 0"
        );
        let e = cfg.dim;
        let in_w = store.alloc(&format!("{name}.in_proj_weight"), &[3 * e, e]);
        let in_b = store.alloc(&format!("{name}.in_proj_bias"), &[3 * e]);
        // xavier_uniform on [3E, E] as PyTorch: bound sqrt(6 / (E + 3E))
        let bound = (6.0f32 / (4 * e) as f32).sqrt();
        for x in store.data[in_w.r()].iter_mut() {
            *x = rng.gen_range(-bound..=bound);
        }
        let out = Linear::new(
            LinearConfig {
                d_in: e,
                d_out: e,
                init: Init::Uniform { scale: 1.0 },
            },
            store,
            &format!("{name}.out_proj"),
            rng,
        );
        Self {
            cfg,
            in_w,
            in_b,
            out,
        }
    }

    fn dh(&self) -> usize {
        self.cfg.dim / self.cfg.heads
    }

    /// out[b] = MHA(query = q_in[b], keys = values = kv[b, 0..s]).
    /// q_in: B x E, kv: (B*s) x E, out: B x E.
    #[allow(clippy::too_many_arguments)]
    pub fn forward(
        &self,
        p: &[f32],
        q_in: &[f32],
        kv: &[f32],
        b: usize,
        s: usize,
        c: &mut MhaCache,
        out: &mut [f32],
    ) {
        let (e, h, dh) = (self.cfg.dim, self.cfg.heads, self.dh());
        let w = &p[self.in_w.r()];
        let bias = &p[self.in_b.r()];
        let o = sized(&mut c.o, b * e);
        if s == 0 {
            o.iter_mut().for_each(|x| *x = 0.0);
            self.out.forward(p, o, b, out);
            return;
        }
        let scale = 1.0 / (dh as f32).sqrt();
        // Q = q_in Wq^T + bq
        let q = sized(&mut c.q, b * e);
        for row in q.chunks_exact_mut(e) {
            row.copy_from_slice(&bias[..e]);
        }
        gemm(b, e, e, 1.0, rm(q_in, e), tr(&w[..e * e], e), 1.0, q, e);
        // U[:, hh, :] = scale * Q_h Wk_h
        let u = sized(&mut c.u, b * h * e);
        for hh in 0..h {
            let wk = &w[(e + hh * dh) * e..(e + (hh + 1) * dh) * e];
            let qv = View {
                data: &q[hh * dh..],
                rs: e,
                cs: 1,
            };
            gemm(b, dh, e, scale, qv, rm(wk, e), 0.0, &mut u[hh * e..], h * e);
        }
        // softmax(U . e_j) and ebar = sum_j a_j e_j
        let a = sized(&mut c.a, b * h * s);
        let ebar = sized(&mut c.ebar, b * h * e);
        for r in 0..b {
            let kr = &kv[r * s * e..(r + 1) * s * e];
            for hh in 0..h {
                let ur = &u[(r * h + hh) * e..(r * h + hh + 1) * e];
                let ar = &mut a[(r * h + hh) * s..(r * h + hh + 1) * s];
                let mut mx = f32::NEG_INFINITY;
                for j in 0..s {
                    ar[j] = dot(ur, &kr[j * e..(j + 1) * e]);
                    mx = mx.max(ar[j]);
                }
                let mut sum = 0.0;
                for v in ar.iter_mut() {
                    *v = (*v - mx).exp();
                    sum += *v;
                }
                let inv = 1.0 / sum;
                let er = &mut ebar[(r * h + hh) * e..(r * h + hh + 1) * e];
                er.iter_mut().for_each(|x| *x = 0.0);
                for j in 0..s {
                    ar[j] *= inv;
                    axpy(er, ar[j], &kr[j * e..(j + 1) * e]);
                }
            }
        }
        // O[:, head hh] = ebar_h Wv_h^T + bv_h
        for row in o.chunks_exact_mut(e) {
            row.copy_from_slice(&bias[2 * e..3 * e]);
        }
        for hh in 0..h {
            let wv = &w[(2 * e + hh * dh) * e..(2 * e + (hh + 1) * dh) * e];
            let ev = View {
                data: &ebar[hh * e..],
                rs: h * e,
                cs: 1,
            };
            gemm(b, e, dh, 1.0, ev, tr(wv, e), 1.0, &mut o[hh * dh..], e);
        }
        self.out.forward(p, o, b, out);
    }

    /// Backward of [`forward`](Self::forward) (same inputs, cache from it).
    /// Accumulates parameter grads, ADDS into `dq_in` (B x E) and WRITES `dkv` ((B*s) x E).
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        &self,
        p: &[f32],
        g: &mut [f32],
        q_in: &[f32],
        kv: &[f32],
        b: usize,
        s: usize,
        c: &mut MhaCache,
        dout: &[f32],
        dq_in: &mut [f32],
        dkv: &mut [f32],
    ) {
        let (e, h, dh) = (self.cfg.dim, self.cfg.heads, self.dh());
        let d_o = sized(&mut c.d_o, b * e);
        self.out.backward(p, g, &c.o, dout, b, Some(d_o), false);
        if s == 0 {
            return;
        }
        let scale = 1.0 / (dh as f32).sqrt();
        let w = &p[self.in_w.r()];
        let (q, u, a, ebar) = (&c.q, &c.u, &c.a, &c.ebar);
        // value path
        let d_ebar = sized(&mut c.d_ebar, b * h * e);
        {
            let gw = &mut g[self.in_w.r()];
            for hh in 0..h {
                let wv_r = (2 * e + hh * dh) * e..(2 * e + (hh + 1) * dh) * e;
                let dov_t = View {
                    data: &d_o[hh * dh..],
                    rs: 1,
                    cs: e,
                };
                let ev = View {
                    data: &ebar[hh * e..],
                    rs: h * e,
                    cs: 1,
                };
                gemm(dh, b, e, 1.0, dov_t, ev, 1.0, &mut gw[wv_r.clone()], e);
                let dov = View {
                    data: &d_o[hh * dh..],
                    rs: e,
                    cs: 1,
                };
                gemm(
                    b,
                    dh,
                    e,
                    1.0,
                    dov,
                    rm(&w[wv_r], e),
                    0.0,
                    &mut d_ebar[hh * e..],
                    h * e,
                );
            }
        }
        {
            let gb = &mut g[self.in_b.r()];
            for row in d_o.chunks_exact(e) {
                for (x, y) in gb[2 * e..3 * e].iter_mut().zip(row) {
                    *x += y;
                }
            }
        }
        // softmax / score path, per row and head
        let d_u = sized(&mut c.d_u, b * h * e);
        let ds = sized(&mut c.ds, s);
        dkv[..b * s * e].iter_mut().for_each(|x| *x = 0.0);
        for r in 0..b {
            let kr = &kv[r * s * e..(r + 1) * s * e];
            let dkr = &mut dkv[r * s * e..(r + 1) * s * e];
            for hh in 0..h {
                let base = (r * h + hh) * e;
                let ar = &a[(r * h + hh) * s..(r * h + hh + 1) * s];
                let de = &d_ebar[base..base + e];
                let ur = &u[base..base + e];
                // dA_j and its softmax-weighted mean
                let mut mean = 0.0;
                for j in 0..s {
                    ds[j] = dot(de, &kr[j * e..(j + 1) * e]);
                    mean += ar[j] * ds[j];
                }
                let du = &mut d_u[base..base + e];
                du.iter_mut().for_each(|x| *x = 0.0);
                for j in 0..s {
                    let dsj = ar[j] * (ds[j] - mean);
                    let kj = &kr[j * e..(j + 1) * e];
                    axpy(du, dsj, kj);
                    let dkj = &mut dkr[j * e..(j + 1) * e];
                    for i in 0..e {
                        dkj[i] += ar[j] * de[i] + dsj * ur[i];
                    }
                }
            }
        }
        // U = scale * Q_h Wk_h
        let d_q = sized(&mut c.d_q, b * e);
        {
            let gw = &mut g[self.in_w.r()];
            for hh in 0..h {
                let wk_r = (e + hh * dh) * e..(e + (hh + 1) * dh) * e;
                let duv = View {
                    data: &d_u[hh * e..],
                    rs: h * e,
                    cs: 1,
                };
                gemm(
                    b,
                    e,
                    dh,
                    scale,
                    duv,
                    tr(&w[wk_r.clone()], e),
                    0.0,
                    &mut d_q[hh * dh..],
                    e,
                );
                let qt = View {
                    data: &q[hh * dh..],
                    rs: 1,
                    cs: e,
                };
                gemm(dh, b, e, scale, qt, duv, 1.0, &mut gw[wk_r], e);
            }
            // Q = q_in Wq^T + bq
            gemm(
                e,
                b,
                e,
                1.0,
                tr(d_q, e),
                rm(q_in, e),
                1.0,
                &mut gw[..e * e],
                e,
            );
        }
        {
            let gb = &mut g[self.in_b.r()];
            for row in d_q.chunks_exact(e) {
                for (x, y) in gb[..e].iter_mut().zip(row) {
                    *x += y;
                }
            }
        }
        gemm(b, e, e, 1.0, rm(d_q, e), rm(&w[..e * e], e), 1.0, dq_in, e);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::gradcheck::*;
    use rand::SeedableRng;

    fn make(e: usize, h: usize) -> (ParamStore, MultiHeadAttention) {
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let mut s = ParamStore::new();
        let m = MultiHeadAttention::new(MhaConfig { dim: e, heads: h }, &mut s, "att", &mut rng);
        // non-zero biases so every path is exercised
        let rb = rand_vec(s.len(), 6);
        for r in [m.in_b.r(), m.out.b.r()] {
            for i in r {
                s.data[i] = 0.2 * rb[i];
            }
        }
        (s, m)
    }

    /// Textbook MHA with explicit K and V projections, in f64.
    fn naive(
        m: &MultiHeadAttention,
        p: &[f32],
        q_in: &[f32],
        kv: &[f32],
        b: usize,
        s: usize,
    ) -> Vec<f64> {
        let (e, h) = (m.cfg.dim, m.cfg.heads);
        let dh = e / h;
        let w = &p[m.in_w.r()];
        let bi = &p[m.in_b.r()];
        let proj = |x: &[f32], blk: usize| -> Vec<f64> {
            (0..e)
                .map(|o| {
                    bi[blk * e + o] as f64
                        + (0..e)
                            .map(|i| w[(blk * e + o) * e + i] as f64 * x[i] as f64)
                            .sum::<f64>()
                })
                .collect()
        };
        let wo = &p[m.out.w.r()];
        let bo = &p[m.out.b.r()];
        let mut out = vec![];
        for r in 0..b {
            let q = proj(&q_in[r * e..(r + 1) * e], 0);
            let ks: Vec<_> = (0..s)
                .map(|j| proj(&kv[(r * s + j) * e..(r * s + j + 1) * e], 1))
                .collect();
            let vs: Vec<_> = (0..s)
                .map(|j| proj(&kv[(r * s + j) * e..(r * s + j + 1) * e], 2))
                .collect();
            let mut o = vec![0.0f64; e];
            if s > 0 {
                for hh in 0..h {
                    let sc: Vec<f64> = (0..s)
                        .map(|j| {
                            (0..dh)
                                .map(|d| q[hh * dh + d] * ks[j][hh * dh + d])
                                .sum::<f64>()
                                / (dh as f64).sqrt()
                        })
                        .collect();
                    let mx = sc.iter().cloned().fold(f64::MIN, f64::max);
                    let ex: Vec<f64> = sc.iter().map(|x| (x - mx).exp()).collect();
                    let z: f64 = ex.iter().sum();
                    for d in 0..dh {
                        o[hh * dh + d] = (0..s).map(|j| ex[j] / z * vs[j][hh * dh + d]).sum();
                    }
                }
            }
            for oo in 0..e {
                out.push(bo[oo] as f64 + (0..e).map(|i| wo[oo * e + i] as f64 * o[i]).sum::<f64>());
            }
        }
        out
    }

    #[test]
    fn matches_textbook_attention_including_empty_set() {
        let (st, m) = make(8, 2);
        let b = 3;
        for s in [0usize, 1, 4] {
            let q_in = rand_vec(b * 8, 1);
            let kv = rand_vec(b * s * 8, 2);
            let mut c = MhaCache::default();
            let mut out = vec![0.0; b * 8];
            m.forward(&st.data, &q_in, &kv, b, s, &mut c, &mut out);
            let want = naive(&m, &st.data, &q_in, &kv, b, s);
            for (x, y) in out.iter().zip(&want) {
                assert!((*x as f64 - y).abs() < 1e-5, "s={s}: {x} vs {y}");
            }
            if s == 0 {
                assert_eq!(&out[..8], &st.data[m.out.b.r()]);
            }
        }
    }

    #[test]
    fn gradients_match_finite_differences() {
        let (mut st, m) = make(8, 2);
        let (b, s) = (2, 3);
        let q_in = rand_vec(b * 8, 3);
        let kv = rand_vec(b * s * 8, 4);
        let r = rand_vec(b * 8, 5);
        let run = |p: &[f32], q: &[f32], k: &[f32]| {
            let mut c = MhaCache::default();
            let mut out = vec![0.0; b * 8];
            m.forward(p, q, k, b, s, &mut c, &mut out);
            dot_loss(&out, &r)
        };
        let mut c = MhaCache::default();
        let mut out = vec![0.0; b * 8];
        m.forward(&st.data, &q_in, &kv, b, s, &mut c, &mut out);
        let mut dq = vec![0.0; b * 8];
        let mut dkv = vec![0.0; b * s * 8];
        let (p, g) = st.split();
        m.backward(p, g, &q_in, &kv, b, s, &mut c, &r, &mut dq, &mut dkv);
        let num_p = numeric_grad(&mut st.data.clone(), |p| run(p, &q_in, &kv));
        assert_grad_close("params", &st.grad, &num_p);
        let num_q = numeric_grad(&mut q_in.clone(), |q| run(&st.data, q, &kv));
        assert_grad_close("q_in", &dq, &num_q);
        let num_k = numeric_grad(&mut kv.clone(), |k| run(&st.data, &q_in, k));
        assert_grad_close("kv", &dkv, &num_k);
        // every tensor gets a gradient (the key bias block alone is exactly zero, as in torch)
        for ent in &st.entries {
            assert!(
                st.grad[ent.slot.r()].iter().any(|g| *g != 0.0),
                "{}",
                ent.name
            );
        }
    }

    #[test]
    fn empty_set_backward_only_touches_out_proj() {
        let (mut st, m) = make(8, 2);
        let b = 2;
        let q_in = rand_vec(b * 8, 3);
        let mut c = MhaCache::default();
        let mut out = vec![0.0; b * 8];
        m.forward(&st.data, &q_in, &[], b, 0, &mut c, &mut out);
        let mut dq = vec![0.0; b * 8];
        let (p, g) = st.split();
        m.backward(
            p,
            g,
            &q_in,
            &[],
            b,
            0,
            &mut c,
            &rand_vec(b * 8, 9),
            &mut dq,
            &mut [],
        );
        assert!(dq.iter().all(|x| *x == 0.0));
        assert!(st.grad[m.in_w.r()].iter().all(|x| *x == 0.0));
        assert!(st.grad[m.out.b.r()].iter().any(|x| *x != 0.0));
    }
}
