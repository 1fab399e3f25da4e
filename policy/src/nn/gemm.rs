//! Row-major GEMM helpers over `matrixmultiply::sgemm`.
//!
//! All matrices are row-major; a "transposed" operand is expressed by swapping strides, so
//! no copy is ever made.

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
    // Bounds: the last element touched must be inside each slice.
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
    assert!((m - 1) * rsc + (n - 1) < c.len(), "gemm: C too small");
    if m <= SMALL_M || k <= SMALL_K {
        small(m, k, n, alpha, a, b, beta, c, rsc);
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
const SMALL_M: usize = 4;

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
        use crate::nn::gradcheck::rand_vec;
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
}
