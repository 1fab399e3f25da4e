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
}
