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
//!
//! The per-row middle part (scores, softmax, weighted sums and their backward) runs over
//! chunks of rows on rayon's pool, each chunk compiled for the best instruction set found
//! at run time (see `simd`); the projections around it are GEMMs over the whole batch.

use super::gemm::{gemm, gemm_rows_of, rm, tr, View, SMALL_M};
use super::init::Init;
use super::linear::{Linear, LinearConfig};
use super::params::{ParamStore, Slot};
use rand::Rng;
use rayon::prelude::*;
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

/// Where the S keys/values of each row come from.
#[derive(Debug, Clone, Copy)]
pub enum Kv<'a> {
    /// Given rows: (B*S) x E.
    Rows(&'a [f32]),
    /// ReLU(enc(x)) of raw entity features x ((B*S) x d_in, d_in <= 4), computed per row
    /// and never stored: the whole batch's embeddings (B*S*E floats, gigabytes at 100
    /// robots) would be written once and read four times, where a row's S x E block stays
    /// in L1. Backward recomputes them and accumulates `enc`'s gradients.
    Encoded { x: &'a [f32], enc: &'a Linear },
}

/// Activations (forward) and scratch (backward) of one attention instance.
#[derive(Debug, Clone, Default)]
pub struct MhaCache {
    q: Vec<f32>,    // B x E
    a: Vec<f32>,    // B x H x S (softmax weights)
    ebar: Vec<f32>, // B x H x E (sum_j a_j e_j)
    o: Vec<f32>,    // B x E (concatenated heads, before out_proj)
    d_o: Vec<f32>,
    d_u: Vec<f32>,
    d_q: Vec<f32>,
    enc_t: Vec<f32>,    // d_in x E: the entity encoder's weight, transposed
    wv_t: Vec<f32>,     // H x E x dh: each head's Wv, transposed
    wk_t: Vec<f32>,     // H x E x dh: each head's Wk, transposed
    partials: Vec<f32>, // chunks x (d_in + 1) x E: entity-encoder gradient per row chunk
}

mod rows;
use rows::*;

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

    /// Transposed entity-encoder weight (d_in x E) into `enc_t`; returns d_in (0 for rows).
    fn prepare_kv(&self, p: &[f32], kv: Kv, enc_t: &mut Vec<f32>) -> usize {
        match kv {
            Kv::Rows(_) => 0,
            Kv::Encoded { enc, .. } => {
                let (k, e) = (enc.cfg.d_in, self.cfg.dim);
                assert!(k <= 4 && enc.cfg.d_out == e, "entity encoder {k} -> E");
                let w = &p[enc.w.r()];
                let wt = sized(enc_t, k * e);
                for o in 0..e {
                    for i in 0..k {
                        wt[i * e + o] = w[o * k + i];
                    }
                }
                k
            }
        }
    }

    /// out[b] = MHA(query = q_in[b], keys = values = the S entities of row b).
    /// q_in: B x E, out: B x E.
    #[allow(clippy::too_many_arguments)]
    pub fn forward(
        &self,
        p: &[f32],
        q_in: &[f32],
        kv: Kv,
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
        let k = self.prepare_kv(p, kv, &mut c.enc_t);
        // Q = q_in Wq^T + bq
        let q = sized(&mut c.q, b * e);
        for row in q.chunks_exact_mut(e) {
            row.copy_from_slice(&bias[..e]);
        }
        gemm(b, e, e, 1.0, rm(q_in, e), tr(&w[..e * e], e), 1.0, q, e);
        // Per chunk of rows, while the chunk is in cache: U[:, hh, :] = scale * Q_h Wk_h
        // (per-thread scratch: backward recomputes it, cheaper than writing and reading
        // back a B x H x E array), then the softmax(U . e_j) and ebar = sum_j a_j e_j of
        // each row, then O[:, head hh] = ebar_h Wv_h^T + bv_h. U and ebar are B x H x E
        // (four times the activations), so whole-batch products streamed them through
        // memory. `gemm_rows_of` keeps each element's bits as one whole-batch GEMM.
        // Wv's heads transposed once for the chunk GEMMs; a few rows (one robot's decision)
        // take the small-product loop, which reads Wv in place: no copy on that path.
        let copy_wv = b > SMALL_M;
        if copy_wv {
            head_major_t(&w[2 * e * e..3 * e * e], h, dh, e, &mut c.wv_t);
        }
        let wv_t = &c.wv_t;
        let (a, ebar) = (sized(&mut c.a, b * h * s), sized(&mut c.ebar, b * h * e));
        let (q, wt) = (&*q, &c.enc_t);
        let bv = &bias[2 * e..3 * e];
        let chunk = |ci: usize, ac: &mut [f32], ec: &mut [f32], oc: &mut [f32]| {
            let (r0, rows) = (ci * ROW_CHUNK, oc.len() / e);
            SCRATCH.with_borrow_mut(|scr| {
                let need = s * e + rows * h * e;
                if scr.len() < need {
                    scr.resize(need, 0.0);
                }
                let (kbuf, uc) = scr.split_at_mut(s * e);
                let uc = &mut uc[..rows * h * e];
                self.u_rows(w, q, b, r0, rows, uc);
                for (i, (ar, er)) in ac.chunks_mut(h * s).zip(ec.chunks_mut(h * e)).enumerate() {
                    let r = r0 + i;
                    let kr: &[f32] = match kv {
                        Kv::Rows(x) => &x[r * s * e..(r + 1) * s * e],
                        Kv::Encoded { x, enc } => {
                            let xr = &x[r * s * k..(r + 1) * s * k];
                            encode_row(xr, k, wt, &p[enc.b.r()], e, s, kbuf);
                            kbuf
                        }
                    };
                    fwd_row(&uc[i * h * e..(i + 1) * h * e], kr, ar, er, h, e, s);
                }
            });
            for row in oc.chunks_exact_mut(e) {
                row.copy_from_slice(bv);
            }
            for hh in 0..h {
                let ev = View {
                    data: &ec[hh * e..],
                    rs: h * e,
                    cs: 1,
                };
                let wvh = if copy_wv {
                    rm(&wv_t[hh * e * dh..(hh + 1) * e * dh], dh)
                } else {
                    tr(&w[(2 * e + hh * dh) * e..(2 * e + (hh + 1) * dh) * e], e)
                };
                gemm_rows_of(b, rows, e, dh, 1.0, ev, wvh, 1.0, &mut oc[hh * dh..], e);
            }
        };
        if b <= ROW_CHUNK {
            chunk(0, a, ebar, o);
        } else {
            a.par_chunks_mut(ROW_CHUNK * h * s)
                .zip(ebar.par_chunks_mut(ROW_CHUNK * h * e))
                .zip(o.par_chunks_mut(ROW_CHUNK * e))
                .enumerate()
                .for_each(|(ci, ((ac, ec), oc))| chunk(ci, ac, ec, oc));
        }
        self.out.forward(p, o, b, out);
    }

    /// U of rows r0..r0+rows of a b-row batch into `u` (rows x H x E): U[:, hh, :] =
    /// scale * Q_h Wk_h, with the bits of the whole-batch product (`gemm_rows_of`). Forward
    /// computes it per chunk and backward recomputes it, instead of storing it.
    fn u_rows(&self, w: &[f32], q: &[f32], b: usize, r0: usize, rows: usize, u: &mut [f32]) {
        let (e, h, dh) = (self.cfg.dim, self.cfg.heads, self.dh());
        let scale = 1.0 / (dh as f32).sqrt();
        for hh in 0..h {
            let wk = &w[(e + hh * dh) * e..(e + (hh + 1) * dh) * e];
            let qv = View {
                data: &q[r0 * e + hh * dh..],
                rs: e,
                cs: 1,
            };
            let uh = &mut u[hh * e..];
            gemm_rows_of(b, rows, dh, e, scale, qv, rm(wk, e), 0.0, uh, h * e);
        }
    }

    /// Backward of [`forward`](Self::forward) (same inputs, cache from it).
    /// Accumulates parameter grads (including the entity encoder's for [`Kv::Encoded`]),
    /// ADDS into `dq_in` (B x E) and, for [`Kv::Rows`], WRITES `dkv` ((B*s) x E).
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        &self,
        p: &[f32],
        g: &mut [f32],
        q_in: &[f32],
        kv: Kv,
        b: usize,
        s: usize,
        c: &mut MhaCache,
        dout: &[f32],
        dq_in: &mut [f32],
        dkv: Option<&mut [f32]>,
    ) {
        let e = self.cfg.dim;
        let d_o = sized(&mut c.d_o, b * e);
        self.out.backward(p, g, &c.o, dout, b, Some(d_o), false);
        if s == 0 {
            return;
        }
        let k = self.prepare_kv(p, kv, &mut c.enc_t);
        self.backward_value(g, b, c);
        self.backward_scores(p, g, kv, k, b, s, c, dkv);
        self.backward_query(p, g, q_in, b, c, dq_in);
    }

    /// Backward of O = ebar_h Wv_h^T + bv_h: grads of Wv and bv (d_ebar is formed per row
    /// chunk in [`backward_scores`](Self::backward_scores)).
    fn backward_value(&self, g: &mut [f32], b: usize, c: &MhaCache) {
        let (e, h, dh) = (self.cfg.dim, self.cfg.heads, self.dh());
        let d_o = &c.d_o[..b * e];
        let ebar = &c.ebar;
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
                gemm(dh, b, e, 1.0, dov_t, ev, 1.0, &mut gw[wv_r], e);
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
    }

    /// Backward of the softmax and scores, row by row: writes `c.d_u`, and for
    /// [`Kv::Rows`] `dkv`, for [`Kv::Encoded`] accumulates the entity encoder's grads.
    #[allow(clippy::too_many_arguments)]
    fn backward_scores(
        &self,
        p: &[f32],
        g: &mut [f32],
        kv: Kv,
        k: usize,
        b: usize,
        s: usize,
        c: &mut MhaCache,
        dkv: Option<&mut [f32]>,
    ) {
        let (e, h, dh) = (self.cfg.dim, self.cfg.heads, self.dh());
        let scale = 1.0 / (dh as f32).sqrt();
        let w = &p[self.in_w.r()];
        // as Wv in `forward`: copied for chunk GEMMs, read in place by the small-product loop
        let copy_wk = b > SMALL_M;
        if copy_wk {
            head_major_t(&w[e * e..2 * e * e], h, dh, e, &mut c.wk_t);
        }
        let wk_t = &c.wk_t;
        let (q, a, d_o) = (&c.q, &c.a, &c.d_o);
        let d_u = sized(&mut c.d_u, b * h * e);
        let d_q = sized(&mut c.d_q, b * e);
        let n_chunks = b.div_ceil(ROW_CHUNK);
        let wt = &c.enc_t;
        // Per chunk of rows, while it is in cache: U recomputed as in `forward` (same bits)
        // and d_ebar_h = d_O_h Wv_h (both scratch, never stored for the batch), the
        // softmax / score path row by row into d_u, then
        // d_Q_h = scale d_U_h Wk_h^T. Each chunk writes its d_u and d_q rows and either its
        // dkv rows or its encoder-gradient partial.
        let part_len = (k + 1) * e;
        let run = |ci: usize, du_c: &mut [f32], dk_c: &mut [f32], dq_c: &mut [f32]| {
            let (r0, rows) = (ci * ROW_CHUNK, dq_c.len() / e);
            SCRATCH.with_borrow_mut(|scr| {
                let need = 2 * s * e + h * s + 2 * rows * h * e;
                if scr.len() < need {
                    scr.resize(need, 0.0);
                }
                let (kbuf, rest) = scr.split_at_mut(s * e);
                let (dkbuf, rest) = rest.split_at_mut(s * e);
                let (ds, rest) = rest.split_at_mut(h * s);
                let (d_ebar, rest) = rest.split_at_mut(rows * h * e);
                let u = &mut rest[..rows * h * e];
                self.u_rows(w, q, b, r0, rows, u);
                let u = &*u;
                for hh in 0..h {
                    let wv = &w[(2 * e + hh * dh) * e..(2 * e + (hh + 1) * dh) * e];
                    let dov = View {
                        data: &d_o[r0 * e + hh * dh..],
                        rs: e,
                        cs: 1,
                    };
                    let de = &mut d_ebar[hh * e..];
                    gemm_rows_of(b, rows, dh, e, 1.0, dov, rm(wv, e), 0.0, de, h * e);
                }
                if let Kv::Encoded { .. } = kv {
                    dk_c.iter_mut().for_each(|x| *x = 0.0);
                }
                for (i, du) in du_c.chunks_mut(h * e).enumerate() {
                    let r = r0 + i;
                    let (ar, de, ur) = (
                        &a[r * h * s..(r + 1) * h * s],
                        &d_ebar[i * h * e..(i + 1) * h * e],
                        &u[i * h * e..(i + 1) * h * e],
                    );
                    match kv {
                        Kv::Rows(x) => {
                            let kr = &x[r * s * e..(r + 1) * s * e];
                            let dkr = &mut dk_c[i * s * e..(i + 1) * s * e];
                            bwd_row(ar, de, ur, kr, du, dkr, ds, h, e, s);
                        }
                        Kv::Encoded { x, enc } => {
                            let xr = &x[r * s * k..(r + 1) * s * k];
                            encode_row(xr, k, wt, &p[enc.b.r()], e, s, kbuf);
                            bwd_row(ar, de, ur, kbuf, du, dkbuf, ds, h, e, s);
                            enc_grad_row(xr, k, kbuf, dkbuf, dk_c, e, s);
                        }
                    }
                }
            });
            for hh in 0..h {
                let duv = View {
                    data: &du_c[hh * e..],
                    rs: h * e,
                    cs: 1,
                };
                let wkh = if copy_wk {
                    rm(&wk_t[hh * e * dh..(hh + 1) * e * dh], dh)
                } else {
                    tr(&w[(e + hh * dh) * e..(e + (hh + 1) * dh) * e], e)
                };
                gemm_rows_of(
                    b,
                    rows,
                    e,
                    dh,
                    scale,
                    duv,
                    wkh,
                    0.0,
                    &mut dq_c[hh * dh..],
                    e,
                );
            }
        };
        match kv {
            Kv::Rows(_) => {
                let dkv = dkv.expect("Kv::Rows needs dkv");
                let dkv = &mut dkv[..b * s * e];
                for_row_chunks(b, d_u, h * e, dkv, s * e, false, d_q, e, run);
            }
            Kv::Encoded { enc, .. } => {
                let parts = sized(&mut c.partials, n_chunks * part_len);
                for_row_chunks(b, d_u, h * e, parts, part_len, true, d_q, e, run);
                // chunk partials in chunk order: the same sum for any thread count
                let (gw, gb) = (enc.w.r(), enc.b.r());
                for pc in c.partials.chunks_exact(part_len) {
                    for o in 0..e {
                        for i in 0..k {
                            g[gw.start + o * k + i] += pc[i * e + o];
                        }
                        g[gb.start + o] += pc[k * e + o];
                    }
                }
            }
        }
    }

    /// Backward of U = scale * Q_h Wk_h and Q = q_in Wq^T + bq: grads of Wk, Wq and bq,
    /// ADDS into `dq_in`.
    fn backward_query(
        &self,
        p: &[f32],
        g: &mut [f32],
        q_in: &[f32],
        b: usize,
        c: &mut MhaCache,
        dq_in: &mut [f32],
    ) {
        let (e, h, dh) = (self.cfg.dim, self.cfg.heads, self.dh());
        let scale = 1.0 / (dh as f32).sqrt();
        let w = &p[self.in_w.r()];
        // U = scale * Q_h Wk_h
        // d_q was formed per row chunk in `backward_scores`
        let (d_u, q, d_q) = (&c.d_u, &c.q, &c.d_q[..b * e]);
        {
            let gw = &mut g[self.in_w.r()];
            for hh in 0..h {
                let wk_r = (e + hh * dh) * e..(e + (hh + 1) * dh) * e;
                let duv = View {
                    data: &d_u[hh * e..],
                    rs: h * e,
                    cs: 1,
                };
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
mod tests;
