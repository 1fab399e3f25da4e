//! Attention against a textbook implementation, finite differences, and itself across
//! encodings, levels and thread counts.

use super::*;
use crate::gradcheck::*;
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
        m.forward(&st.data, &q_in, Kv::Rows(&kv), b, s, &mut c, &mut out);
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
        m.forward(p, q, Kv::Rows(k), b, s, &mut c, &mut out);
        dot_loss(&out, &r)
    };
    let mut c = MhaCache::default();
    let mut out = vec![0.0; b * 8];
    m.forward(&st.data, &q_in, Kv::Rows(&kv), b, s, &mut c, &mut out);
    let mut dq = vec![0.0; b * 8];
    let mut dkv = vec![0.0; b * s * 8];
    let (p, g) = st.split();
    m.backward(
        p,
        g,
        &q_in,
        Kv::Rows(&kv),
        b,
        s,
        &mut c,
        &r,
        &mut dq,
        Some(&mut dkv),
    );
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
    m.forward(&st.data, &q_in, Kv::Rows(&[]), b, 0, &mut c, &mut out);
    let mut dq = vec![0.0; b * 8];
    let (p, g) = st.split();
    m.backward(
        p,
        g,
        &q_in,
        Kv::Rows(&[]),
        b,
        0,
        &mut c,
        &rand_vec(b * 8, 9),
        &mut dq,
        Some(&mut []),
    );
    assert!(dq.iter().all(|x| *x == 0.0));
    assert!(st.grad[m.in_w.r()].iter().all(|x| *x == 0.0));
    assert!(st.grad[m.out.b.r()].iter().any(|x| *x != 0.0));
}

/// The fused entity-encoder path against the old two-step one (Linear + ReLU rows,
/// then attention over them): forward bit-identical, gradients equal up to the
/// summation order of the encoder's weight gradient (row chunks), for batches that
/// span several chunks, at every SIMD level and on 1 and 2 threads.
#[test]
fn encoded_kv_matches_stored_rows_at_every_level_and_thread_count() {
    use crate::relu;
    use crate::simd::tests::at_every_level;
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    let (mut st, m) = make(64, 4);
    let enc = Linear::new(
        LinearConfig {
            d_in: 3,
            d_out: 64,
            init: Init::Orthogonal { gain: 1.4 },
        },
        &mut st,
        "enc",
        &mut rng,
    );
    let rb = rand_vec(64, 8);
    st.data[enc.b.r()].copy_from_slice(&rb.iter().map(|v| 0.1 * v).collect::<Vec<_>>());
    let (b, s) = (3 * ROW_CHUNK + 5, 7);
    let q_in = rand_vec(b * 64, 1);
    let x = rand_vec(b * s * 3, 2);
    let r = rand_vec(b * 64, 3);
    // reference: stored rows
    let mut e = vec![0.0; b * s * 64];
    enc.forward(&st.data, &x, b * s, &mut e);
    relu::forward(&mut e);
    let mut c = MhaCache::default();
    let mut want = vec![0.0; b * 64];
    m.forward(&st.data, &q_in, Kv::Rows(&e), b, s, &mut c, &mut want);
    let mut g_ref = vec![0.0; st.len()];
    let mut dq_ref = vec![0.0; b * 64];
    let mut de = vec![0.0; b * s * 64];
    m.backward(
        &st.data,
        &mut g_ref,
        &q_in,
        Kv::Rows(&e),
        b,
        s,
        &mut c,
        &r,
        &mut dq_ref,
        Some(&mut de),
    );
    relu::backward(&e, &mut de);
    enc.backward(&st.data, &mut g_ref, &x, &de, b * s, None, false);
    let run = || {
        let mut c = MhaCache::default();
        let mut out = vec![0.0; b * 64];
        let kv = Kv::Encoded { x: &x, enc: &enc };
        m.forward(&st.data, &q_in, kv, b, s, &mut c, &mut out);
        let mut g = vec![0.0; st.len()];
        let mut dq = vec![0.0; b * 64];
        m.backward(&st.data, &mut g, &q_in, kv, b, s, &mut c, &r, &mut dq, None);
        (out, g, dq)
    };
    let mut results = at_every_level(run);
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        results.push(pool.install(run));
    }
    for (out, g, dq) in &results {
        assert_eq!(out, &want, "forward is bit-identical");
        assert_eq!(dq, &dq_ref, "query gradient is bit-identical");
        assert_eq!(
            g, &results[0].1,
            "same bits at every level and thread count"
        );
        let scale = g_ref.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        for (i, (x, y)) in g.iter().zip(&g_ref).enumerate() {
            assert!((x - y).abs() <= 1e-5 * scale, "grad[{i}] {x} vs {y}");
        }
    }
}

#[test]
fn dot_avx2_has_the_scalar_bits() {
    for n in [0, 3, 8, 16, 64, 67] {
        let (a, b) = (rand_vec(n, 1), rand_vec(n, 2));
        let want = crate::dot(&a, &b);
        assert_eq!(want.to_bits(), dot(&a, &b).to_bits());
    }
}

/// `fwd_row` and `bwd_row` written head by head with a stored accumulator, as they were
/// before the width-64 kernels kept their sums in registers: the oracles for the bits.
fn fwd_row_head_by_head(
    u: &[f32],
    kr: &[f32],
    a: &mut [f32],
    eb: &mut [f32],
    h: usize,
    e: usize,
    s: usize,
) {
    for hh in 0..h {
        let ur = &u[hh * e..(hh + 1) * e];
        let ar = &mut a[hh * s..(hh + 1) * s];
        let mut mx = f32::NEG_INFINITY;
        for j in 0..s {
            ar[j] = super::dot(ur, &kr[j * e..(j + 1) * e]);
            mx = mx.max(ar[j]);
        }
        for v in ar.iter_mut() {
            *v = crate::fastmath::exp(*v - mx);
        }
        let mut sum = 0.0;
        for v in ar.iter() {
            sum += *v;
        }
        let inv = 1.0 / sum;
        let er = &mut eb[hh * e..(hh + 1) * e];
        er.iter_mut().for_each(|x| *x = 0.0);
        for j in 0..s {
            ar[j] *= inv;
            for (y, k) in er.iter_mut().zip(&kr[j * e..(j + 1) * e]) {
                *y += ar[j] * k;
            }
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn bwd_row_head_by_head(
    a: &[f32],
    de_all: &[f32],
    u: &[f32],
    kr: &[f32],
    du_all: &mut [f32],
    dkr: &mut [f32],
    h: usize,
    e: usize,
    s: usize,
) {
    let mut ds = vec![0.0f32; s];
    dkr[..s * e].iter_mut().for_each(|x| *x = 0.0);
    for hh in 0..h {
        let ar = &a[hh * s..(hh + 1) * s];
        let de = &de_all[hh * e..(hh + 1) * e];
        let ur = &u[hh * e..(hh + 1) * e];
        let mut mean = 0.0;
        for j in 0..s {
            ds[j] = super::dot(de, &kr[j * e..(j + 1) * e]);
            mean += ar[j] * ds[j];
        }
        let du = &mut du_all[hh * e..(hh + 1) * e];
        du.iter_mut().for_each(|x| *x = 0.0);
        for j in 0..s {
            let dsj = ar[j] * (ds[j] - mean);
            for (d, k) in du.iter_mut().zip(&kr[j * e..(j + 1) * e]) {
                *d += dsj * k;
            }
            let dkj = &mut dkr[j * e..(j + 1) * e];
            for i in 0..e {
                dkj[i] += ar[j] * de[i] + dsj * ur[i];
            }
        }
    }
}

/// The row kernels at the register-accumulated width (64) and at a general one (24) give
/// the oracles' bits at every SIMD level.
#[test]
fn row_kernels_have_the_head_by_head_bits_at_every_level() {
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    for (h, e, s) in [(4, 64, 99), (2, 24, 7)] {
        let kr = rand_vec(s * e, 4);
        let u = rand_vec(h * e, 8);
        let (mut a0, mut eb0) = (vec![0.0; h * s], vec![0.0; h * e]);
        fwd_row_head_by_head(&u, &kr, &mut a0, &mut eb0, h, e, s);
        let de = rand_vec(h * e, 2);
        let (mut du0, mut dk0) = (vec![0.0; h * e], vec![0.0; s * e]);
        bwd_row_head_by_head(&a0, &de, &u, &kr, &mut du0, &mut dk0, h, e, s);
        let runs = crate::simd::tests::at_every_level(|| {
            let (mut a, mut eb) = (vec![1.0; h * s], vec![1.0; h * e]);
            super::fwd_row(&u, &kr, &mut a, &mut eb, h, e, s);
            let (mut du, mut dk, mut ds) = (vec![1.0; h * e], vec![1.0; s * e], vec![0.0; h * s]);
            super::bwd_row(&a, &de, &u, &kr, &mut du, &mut dk, &mut ds, h, e, s);
            (a, eb, du, dk)
        });
        for (a, eb, du, dk) in runs {
            assert_eq!(bits(&a), bits(&a0), "a, e {e}");
            assert_eq!(bits(&eb), bits(&eb0), "eb, e {e}");
            assert_eq!(bits(&du), bits(&du0), "du, e {e}");
            assert_eq!(bits(&dk), bits(&dk0), "dk, e {e}");
        }
    }
}
