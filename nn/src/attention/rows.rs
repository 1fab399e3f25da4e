//! The per-row kernels of [`super::MultiHeadAttention`]: dot products and weighted sums
//! in a fixed summation order (bit-identical across instruction sets and thread counts),
//! one row's backward pass, and the chunked rayon loop that runs them. Apart from the
//! layer so that its file reads as the algorithm (projections, then rows).

use crate::simd::dispatch;
use rayon::prelude::*;
use std::cell::RefCell;

/// Rows per parallel work item. Fixed (never derived from the thread count), and each
/// chunk's parameter-gradient partial is summed in chunk order, so results are
/// bit-identical for any number of threads.
pub(super) const ROW_CHUNK: usize = 32;

thread_local! {
    /// Per-thread row scratch: keys/values, their gradient, and score gradients.
    pub(super) static SCRATCH: RefCell<Vec<f32>> = const { RefCell::new(Vec::new()) };
}

pub(super) fn sized(v: &mut Vec<f32>, n: usize) -> &mut [f32] {
    v.resize(n, 0.0);
    &mut v[..n]
}

/// Dot product in the summation order of [`crate::dot`] (8 lanes, fixed combine). The
/// compiler turns the 8-accumulator loop into shuffles of 4-wide halves, so where the CPU
/// has AVX2 the 8 lanes are one explicit 256-bit register: the same additions and
/// multiplications in the same order (no FMA), hence the same bits.
#[inline(always)]
pub(super) fn dot(a: &[f32], b: &[f32]) -> f32 {
    #[cfg(target_arch = "x86_64")]
    {
        if crate::simd::level() >= crate::simd::Level::Avx2 {
            // SAFETY: the level is Avx2 or higher only when the CPU has AVX2.
            return unsafe { dot_avx2(a, b) };
        }
    }
    crate::dot(a, b)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn dot_avx2(a: &[f32], b: &[f32]) -> f32 {
    use std::arch::x86_64::*;
    let n = a.len().min(b.len());
    let chunks = n / 8;
    let mut acc = _mm256_setzero_ps();
    for c in 0..chunks {
        // SAFETY: 8 * c + 8 <= n <= both lengths.
        let (x, y) = unsafe {
            (
                _mm256_loadu_ps(a.as_ptr().add(8 * c)),
                _mm256_loadu_ps(b.as_ptr().add(8 * c)),
            )
        };
        acc = _mm256_add_ps(acc, _mm256_mul_ps(x, y));
    }
    let mut l = [0.0f32; 8];
    // SAFETY: l has 8 floats.
    unsafe { _mm256_storeu_ps(l.as_mut_ptr(), acc) };
    let mut s = (l[0] + l[4]) + (l[1] + l[5]) + ((l[2] + l[6]) + (l[3] + l[7]));
    for i in chunks * 8..n {
        s += a[i] * b[i];
    }
    s
}

#[inline(always)]
pub(super) fn axpy(y: &mut [f32], alpha: f32, x: &[f32]) {
    for (a, b) in y.iter_mut().zip(x) {
        *a += alpha * b;
    }
}

dispatch! {
    /// One row's keys/values from raw features: out[j] = relu(bias + sum_i x[j, i] wt[i]),
    /// summed in the order of `Linear::forward`'s small-input path (bit-identical to
    /// Linear + ReLU).
    pub(super) fn encode_row(x: &[f32], k: usize, wt: &[f32], bias: &[f32], e: usize, s: usize, out: &mut [f32]) {
        for j in 0..s {
            let xj = &x[j * k..(j + 1) * k];
            let o = &mut out[j * e..(j + 1) * e];
            o.iter_mut().for_each(|v| *v = 0.0);
            for (i, &xi) in xj.iter().enumerate() {
                axpy(o, xi, &wt[i * e..(i + 1) * e]);
            }
            for (v, b) in o.iter_mut().zip(bias) {
                *v = (b + *v).max(0.0);
            }
        }
    }
}

dispatch! {
    /// Softmax weights `a` (H x S) and weighted sums `eb` (H x E) of one row.
    pub(super) fn fwd_row(u: &[f32], kr: &[f32], a: &mut [f32], eb: &mut [f32], h: usize, e: usize, s: usize) {
        for hh in 0..h {
            let ur = &u[hh * e..(hh + 1) * e];
            let ar = &mut a[hh * s..(hh + 1) * s];
            let mut mx = f32::NEG_INFINITY;
            for j in 0..s {
                ar[j] = dot(ur, &kr[j * e..(j + 1) * e]);
                mx = mx.max(ar[j]);
            }
            // exp in its own loop so it vectorises; the sum keeps its order
            for v in ar.iter_mut() {
                *v = crate::fastmath::exp(*v - mx);
            }
            let mut sum = 0.0;
            for v in ar.iter() {
                sum += *v;
            }
            let inv = 1.0 / sum;
            for v in ar.iter_mut() {
                *v *= inv;
            }
            weighted_sum(&mut eb[hh * e..(hh + 1) * e], ar, kr, e);
        }
    }
}

/// er = sum_j w[j] kr[j] (keys of length e), summed in key order from zero. At the
/// bundled width (64) the sum is kept in a fixed-size accumulator, i.e. in registers,
/// instead of being stored and reloaded once per key (that store was the hottest
/// instruction of the forward row kernel); the same additions in the same order.
#[inline(always)]
pub(super) fn weighted_sum(er: &mut [f32], w: &[f32], kr: &[f32], e: usize) {
    if e == FAST_E {
        let mut acc = [0.0f32; FAST_E];
        for (&wj, kj) in w.iter().zip(kr.chunks_exact(FAST_E)) {
            for l in 0..FAST_E {
                acc[l] += wj * kj[l];
            }
        }
        er[..FAST_E].copy_from_slice(&acc);
        return;
    }
    er[..e].iter_mut().for_each(|x| *x = 0.0);
    for (&wj, kj) in w.iter().zip(kr.chunks_exact(e)) {
        axpy(er, wj, kj);
    }
}

/// Embedding width with register-accumulated row kernels (the bundled networks' d_model);
/// other widths take the general loops, with the same bits.
pub(super) const FAST_E: usize = 64;

dispatch! {
    /// Backward of [`fwd_row`]: writes du (H x E) and dkr (S x E); `ds` is H x S scratch.
    pub(super) fn bwd_row(
        a: &[f32],
        de_all: &[f32],
        u: &[f32],
        kr: &[f32],
        du_all: &mut [f32],
        dkr: &mut [f32],
        ds: &mut [f32],
        h: usize,
        e: usize,
        s: usize,
    ) {
        if e == FAST_E {
            return bwd_row_fixed(a, de_all, u, kr, du_all, dkr, ds, h, s);
        }
        dkr[..s * e].iter_mut().for_each(|x| *x = 0.0);
        for hh in 0..h {
            let ar = &a[hh * s..(hh + 1) * s];
            let de = &de_all[hh * e..(hh + 1) * e];
            let ur = &u[hh * e..(hh + 1) * e];
            let mean = score_grads(de, kr, ar, &mut ds[..s], e);
            let du = &mut du_all[hh * e..(hh + 1) * e];
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
}

/// One head's score gradients dA_j = de . k_j into `ds` (one per key of `kr`, width `e`),
/// returning their softmax-weighted mean sum_j a_j dA_j (summed in key order). Shared by
/// both [`bwd_row`] paths so they form these the same way.
#[inline(always)]
pub(super) fn score_grads(de: &[f32], kr: &[f32], a: &[f32], ds: &mut [f32], e: usize) -> f32 {
    let mut mean = 0.0;
    for (j, d) in ds.iter_mut().enumerate() {
        *d = dot(de, &kr[j * e..(j + 1) * e]);
        mean += a[j] * *d;
    }
    mean
}

/// [`bwd_row`] at width [`FAST_E`]: du and each key's gradient accumulated in registers,
/// the key gradient over the heads in one pass per key (`ds` needs H x S). Every element
/// gets the same additions in the same order as the general loop: dkr[j] from zero, head
/// 0's term first; du from zero in key order.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn bwd_row_fixed(
    a: &[f32],
    de_all: &[f32],
    u: &[f32],
    kr: &[f32],
    du_all: &mut [f32],
    dkr: &mut [f32],
    ds: &mut [f32],
    h: usize,
    s: usize,
) {
    const E: usize = FAST_E;
    for hh in 0..h {
        let ar = &a[hh * s..(hh + 1) * s];
        let de = &de_all[hh * E..(hh + 1) * E];
        let dsh = &mut ds[hh * s..(hh + 1) * s];
        let mean = score_grads(de, kr, ar, dsh, E);
        let mut acc = [0.0f32; E];
        for j in 0..s {
            dsh[j] = ar[j] * (dsh[j] - mean);
            let kj = &kr[j * E..(j + 1) * E];
            for l in 0..E {
                acc[l] += dsh[j] * kj[l];
            }
        }
        du_all[hh * E..(hh + 1) * E].copy_from_slice(&acc);
    }
    for j in 0..s {
        let mut acc = [0.0f32; E];
        for hh in 0..h {
            let (aj, dsj) = (a[hh * s + j], ds[hh * s + j]);
            let de = &de_all[hh * E..(hh + 1) * E];
            let ur = &u[hh * E..(hh + 1) * E];
            for l in 0..E {
                acc[l] += aj * de[l] + dsj * ur[l];
            }
        }
        dkr[j * E..(j + 1) * E].copy_from_slice(&acc);
    }
}

dispatch! {
    /// Entity encoder gradient of one row: dkr is masked by the ReLU (kr = its output) and
    /// accumulated as acc[i] += x[j, i] * dkr[j] (i < k), acc[k] += dkr[j].
    pub(super) fn enc_grad_row(x: &[f32], k: usize, kr: &[f32], dkr: &mut [f32], acc: &mut [f32], e: usize, s: usize) {
        for j in 0..s {
            let ej = &kr[j * e..(j + 1) * e];
            let dj = &mut dkr[j * e..(j + 1) * e];
            for (d, &v) in dj.iter_mut().zip(ej) {
                if v <= 0.0 {
                    *d = 0.0;
                }
            }
            let xj = &x[j * k..(j + 1) * k];
            for (i, &xi) in xj.iter().enumerate() {
                axpy(&mut acc[i * e..(i + 1) * e], xi, dj);
            }
            for (g, d) in acc[k * e..(k + 1) * e].iter_mut().zip(dj.iter()) {
                *g += d;
            }
        }
    }
}

/// Run `f(chunk_index, a_chunk, b_chunk, c_chunk)` over matching chunks of [`ROW_CHUNK`]
/// rows of `a` (`la` per row), `b` (`lb` per chunk row, or `lb` per chunk when
/// `per_chunk`) and `c` (`lc` per row), on rayon's pool when there is more than one chunk:
/// single-row inference never touches the thread pool (nor allocates).
#[allow(clippy::too_many_arguments)]
pub(super) fn for_row_chunks(
    rows: usize,
    a: &mut [f32],
    la: usize,
    b: &mut [f32],
    lb: usize,
    per_chunk: bool,
    c: &mut [f32],
    lc: usize,
    f: impl Fn(usize, &mut [f32], &mut [f32], &mut [f32]) + Sync,
) {
    let cb = if per_chunk { lb } else { ROW_CHUNK * lb };
    if rows <= ROW_CHUNK {
        f(0, a, b, &mut c[..rows * lc]);
    } else {
        a.par_chunks_mut(ROW_CHUNK * la)
            .zip(b.par_chunks_mut(cb))
            .zip(c[..rows * lc].par_chunks_mut(ROW_CHUNK * lc))
            .enumerate()
            .for_each(|(i, ((x, y), z))| f(i, x, y, z));
    }
}

/// The per-head blocks of a [H*dh, E] weight (rows = heads' outputs), each transposed to
/// E x dh row-major, head after head, into `buf`: the chunk GEMMs then read B's rows in
/// place instead of copying the transposed head once per chunk.
pub(super) fn head_major_t(w: &[f32], h: usize, dh: usize, e: usize, buf: &mut Vec<f32>) {
    let t = sized(buf, h * e * dh);
    for hh in 0..h {
        let (wh, th) = (
            &w[hh * dh * e..(hh + 1) * dh * e],
            &mut t[hh * e * dh..(hh + 1) * e * dh],
        );
        for (j, row) in wh.chunks_exact(e).enumerate() {
            for (i, x) in row.iter().enumerate() {
                th[i * dh + j] = *x;
            }
        }
    }
}
