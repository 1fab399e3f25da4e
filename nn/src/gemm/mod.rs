//! Row-major GEMM helpers over `matrixmultiply::sgemm` (or, with the same bits, the
//! non-packing kernel in `direct` where the CPU has it).
//!
//! All matrices are row-major; a "transposed" operand is expressed by swapping strides, so
//! no copy is ever made.

mod direct;

/// A strided view of a matrix: element (i, j) is at `i * rs + j * cs`.
#[derive(Clone, Copy)]
pub struct View<'a> {
    pub data: &'a [f32],
    pub rs: usize,
    pub cs: usize,
}

/// Row-major contiguous matrix with `cols` columns.
#[inline]
pub fn rm(data: &[f32], cols: usize) -> View<'_> {
    View {
        data,
        rs: cols,
        cs: 1,
    }
}

/// Transposed view of a row-major matrix with `cols` columns.
#[inline]
pub fn tr(data: &[f32], cols: usize) -> View<'_> {
    View {
        data,
        rs: 1,
        cs: cols,
    }
}

/// C (m x n, row stride `rsc`) = alpha * A (m x k) * B (k x n) + beta * C.
/// With beta == 0, C is not read.
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn gemm(
    m: usize,
    k: usize,
    n: usize,
    alpha: f32,
    a: View,
    b: View,
    beta: f32,
    c: &mut [f32],
    rsc: usize,
) {
    if m == 0 || n == 0 {
        return;
    }
    check_bounds(m, k, n, a, b, c.len(), rsc);
    if m <= SMALL_M || k <= SMALL_K {
        small(m, k, n, alpha, a, b, beta, c, rsc);
        return;
    }
    direct::with_contiguous_rows(k, n, b, |b| {
        if m * k * n >= PAR_MIN_MACS {
            if m >= 2 * ROW_CHUNK {
                return par_rows(m, k, n, alpha, a, b, beta, c, rsc);
            }
            if k >= 2 * K_CHUNK {
                return par_inner(m, k, n, alpha, a, b, beta, c, rsc);
            }
        }
        sgemm(m, k, n, alpha, a, b, beta, c, rsc);
    })
}

/// Bounds of an m x k x n product (m, n > 0): the last element touched must be inside
/// each slice.
fn check_bounds(m: usize, k: usize, n: usize, a: View, b: View, c_len: usize, rsc: usize) {
    if k > 0 {
        assert!(
            (m - 1) * a.rs + (k - 1) * a.cs < a.data.len(),
            "gemm: A too small"
        );
        assert!(
            (k - 1) * b.rs + (n - 1) * b.cs < b.data.len(),
            "gemm: B too small"
        );
    }
    assert!((m - 1) * rsc + (n - 1) < c_len, "gemm: C too small");
}

/// Rows of a product of `total_m` rows, computed on the calling thread with exactly the
/// bits [`gemm`] gives those rows when it computes the whole product (the small-product
/// loop when the whole is small, one `sgemm` call's bits otherwise, which no row split
/// changes). Lets a layer compute a product chunk by chunk, next to the code that uses each
/// chunk while it is in cache, without changing results.
#[allow(clippy::too_many_arguments)]
pub fn gemm_rows_of(
    total_m: usize,
    m: usize,
    k: usize,
    n: usize,
    alpha: f32,
    a: View,
    b: View,
    beta: f32,
    c: &mut [f32],
    rsc: usize,
) {
    if m == 0 || n == 0 {
        return;
    }
    if total_m <= SMALL_M || k <= SMALL_K {
        check_bounds(m, k, n, a, b, c.len(), rsc);
        small(m, k, n, alpha, a, b, beta, c, rsc);
        return;
    }
    direct::with_contiguous_rows(k, n, b, |b| sgemm(m, k, n, alpha, a, b, beta, c, rsc));
}

/// Below this many multiply-adds a GEMM runs on the calling thread (a rayon hand-off
/// costs some microseconds).
const PAR_MIN_MACS: usize = 1 << 20;
/// Rows per parallel piece of a tall GEMM. Each element of C is computed exactly as by one
/// call, so the result does not depend on the split (test).
const ROW_CHUNK: usize = 256;
/// Inner-dimension piece of a GEMM with few rows and a long inner dimension (weight
/// gradients summed over the batch): partial products are added in piece order, so the
/// result is the same for any thread count (and differs from one call only by summation
/// order).
const K_CHUNK: usize = 1024;

thread_local! {
    static PARTIALS: std::cell::RefCell<Vec<f32>> = const { std::cell::RefCell::new(Vec::new()) };
}

#[allow(clippy::too_many_arguments)]
fn par_rows(
    m: usize,
    k: usize,
    n: usize,
    alpha: f32,
    a: View,
    b: View,
    beta: f32,
    c: &mut [f32],
    rsc: usize,
) {
    use rayon::prelude::*;
    let c = &mut c[..(m - 1) * rsc + n];
    c.par_chunks_mut(ROW_CHUNK * rsc)
        .enumerate()
        .for_each(|(i, cc)| {
            let r0 = i * ROW_CHUNK;
            let rows = ROW_CHUNK.min(m - r0);
            let av = View {
                data: &a.data[r0 * a.rs..],
                rs: a.rs,
                cs: a.cs,
            };
            sgemm(rows, k, n, alpha, av, b, beta, cc, rsc);
        });
}

#[allow(clippy::too_many_arguments)]
fn par_inner(
    m: usize,
    k: usize,
    n: usize,
    alpha: f32,
    a: View,
    b: View,
    beta: f32,
    c: &mut [f32],
    rsc: usize,
) {
    use rayon::prelude::*;
    let pieces = k.div_ceil(K_CHUNK);
    PARTIALS.with_borrow_mut(|parts| {
        parts.resize(pieces * m * n, 0.0);
        parts.par_chunks_mut(m * n).enumerate().for_each(|(i, pc)| {
            let k0 = i * K_CHUNK;
            let kk = K_CHUNK.min(k - k0);
            let av = View {
                data: &a.data[k0 * a.cs..],
                rs: a.rs,
                cs: a.cs,
            };
            let bv = View {
                data: &b.data[k0 * b.rs..],
                rs: b.rs,
                cs: b.cs,
            };
            sgemm(m, kk, n, alpha, av, bv, 0.0, pc, n);
        });
        for i in 0..m {
            let crow = &mut c[i * rsc..i * rsc + n];
            if beta == 0.0 {
                crow.iter_mut().for_each(|x| *x = 0.0);
            } else if beta != 1.0 {
                crow.iter_mut().for_each(|x| *x *= beta);
            }
            for pc in parts.chunks_exact(m * n) {
                for (x, y) in crow.iter_mut().zip(&pc[i * n..(i + 1) * n]) {
                    *x += y;
                }
            }
        }
    });
}

/// One `matrixmultiply` call (bounds already checked by the caller).
#[allow(clippy::too_many_arguments)]
fn sgemm(
    m: usize,
    k: usize,
    n: usize,
    alpha: f32,
    a: View,
    b: View,
    beta: f32,
    c: &mut [f32],
    rsc: usize,
) {
    if k > 0 {
        assert!((m - 1) * a.rs + (k - 1) * a.cs < a.data.len());
        assert!((k - 1) * b.rs + (n - 1) * b.cs < b.data.len());
    }
    assert!((m - 1) * rsc + (n - 1) < c.len());
    if direct::try_sgemm(m, k, n, alpha, a, b, beta, c, rsc) {
        return;
    }
    // SAFETY: the asserts above keep every access inside the slices; A/B are only read and C
    // is a unique borrow.
    unsafe {
        matrixmultiply::sgemm(
            m,
            k,
            n,
            alpha,
            a.data.as_ptr(),
            a.rs as isize,
            a.cs as isize,
            b.data.as_ptr(),
            b.rs as isize,
            b.cs as isize,
            beta,
            c.as_mut_ptr(),
            rsc as isize,
            1,
        );
    }
}

/// Below this many rows, a direct loop beats packing the B operand (single-robot
/// inference multiplies one row by 64x64 weights).
pub const SMALL_M: usize = 4;

/// With an inner dimension this small (the 2-3 feature entity encoders), packing costs more
/// than it saves, and `matrixmultiply` would allocate its packing buffers on every call,
/// breaking allocation-free inference.
const SMALL_K: usize = 4;

#[allow(clippy::too_many_arguments)]
fn small(
    m: usize,
    k: usize,
    n: usize,
    alpha: f32,
    a: View,
    b: View,
    beta: f32,
    c: &mut [f32],
    rsc: usize,
) {
    for i in 0..m {
        let crow = &mut c[i * rsc..i * rsc + n];
        if beta == 0.0 {
            crow.iter_mut().for_each(|x| *x = 0.0);
        } else if beta != 1.0 {
            crow.iter_mut().for_each(|x| *x *= beta);
        }
        if b.rs == 1 && a.cs == 1 && k > 0 {
            // B is a transposed row-major matrix: each column is contiguous
            let arow = &a.data[i * a.rs..i * a.rs + k];
            for (j, cj) in crow.iter_mut().enumerate() {
                *cj += alpha * super::dot(arow, &b.data[j * b.cs..j * b.cs + k]);
            }
        } else if b.cs == 1 {
            for p in 0..k {
                let av = alpha * a.data[i * a.rs + p * a.cs];
                let brow = &b.data[p * b.rs..p * b.rs + n];
                for (x, y) in crow.iter_mut().zip(brow) {
                    *x += av * y;
                }
            }
        } else {
            for (j, cj) in crow.iter_mut().enumerate() {
                let mut s = 0.0;
                for p in 0..k {
                    s += a.data[i * a.rs + p * a.cs] * b.data[p * b.rs + j * b.cs];
                }
                *cj += alpha * s;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_naive_with_transposes() {
        // A 2x3, B 3x2 -> C 2x2
        let a = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        let bt = [1.0, 0.0, -1.0, 2.0, 1.0, 0.5]; // B^T stored 2x3
        let mut c = [1.0f32; 4];
        gemm(2, 3, 2, 1.0, rm(&a, 3), tr(&bt, 3), 0.0, &mut c, 2);
        assert_eq!(c, [1.0 - 3.0, 2.0 + 2.0 + 1.5, 4.0 - 6.0, 8.0 + 5.0 + 3.0]);
        // accumulate
        gemm(2, 3, 2, 1.0, rm(&a, 3), tr(&bt, 3), 1.0, &mut c, 2);
        assert_eq!(c[0], -4.0);
    }

    #[test]
    fn small_path_matches_sgemm_for_every_layout() {
        use crate::gradcheck::rand_vec;
        let (k, n) = (7, 5);
        let a = rand_vec(20 * k, 1);
        let b = rand_vec(k * n, 2);
        for (av, bv) in [
            (rm(&a, k), rm(&b, n)),
            (rm(&a, k), tr(&b, k)),
            (tr(&a, 20), rm(&b, n)),
            (tr(&a, 20), tr(&b, k)),
        ] {
            // m = 9 goes through sgemm in `gemm`; compare with the direct loop
            for m in [9, 12] {
                let mut c1 = rand_vec(m * n, 3);
                let mut c2 = c1.clone();
                gemm(m, k, n, 0.5, av, bv, 1.0, &mut c1, n);
                small(m, k, n, 0.5, av, bv, 1.0, &mut c2, n);
                for (x, y) in c1.iter().zip(&c2) {
                    assert!((x - y).abs() < 1e-5);
                }
            }
        }
    }

    /// Tall GEMMs split into row pieces give exactly one call's bits; long inner
    /// dimensions split into pieces give the same bits on 1 and 2 threads and agree with
    /// one call up to summation order.
    #[test]
    fn parallel_splits_match_one_call() {
        use crate::gradcheck::rand_vec;
        let pool = |t| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .unwrap()
        };
        // rows: C (700 x 70, row stride 80) = A (700 x 64) * B^T
        let (m, k, n, rsc) = (700, 64, 70, 80);
        let a = rand_vec(m * k, 1);
        let b = rand_vec(n * k, 2);
        let c0 = rand_vec(m * rsc, 3);
        let mut one = c0.clone();
        sgemm(m, k, n, 0.5, rm(&a, k), tr(&b, k), 1.0, &mut one, rsc);
        for t in [1, 2] {
            let mut c = c0.clone();
            pool(t).install(|| gemm(m, k, n, 0.5, rm(&a, k), tr(&b, k), 1.0, &mut c, rsc));
            assert_eq!(c, one);
        }
        // inner: C (16 x 64) += dY^T (16 x 5000) X (5000 x 64)
        let (m, k, n) = (16, 5000, 64);
        let dy = rand_vec(k * m, 4);
        let x = rand_vec(k * n, 5);
        let c0 = rand_vec(m * n, 6);
        let mut one = c0.clone();
        sgemm(m, k, n, 1.0, tr(&dy, m), rm(&x, n), 1.0, &mut one, n);
        let runs: Vec<Vec<f32>> = [1, 2]
            .into_iter()
            .map(|t| {
                let mut c = c0.clone();
                pool(t).install(|| gemm(m, k, n, 1.0, tr(&dy, m), rm(&x, n), 1.0, &mut c, n));
                c
            })
            .collect();
        assert_eq!(runs[0], runs[1]);
        for (x, y) in runs[0].iter().zip(&one) {
            assert!((x - y).abs() < 1e-3, "{x} vs {y}");
        }
    }
}
