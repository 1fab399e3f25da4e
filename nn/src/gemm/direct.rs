//! A GEMM that never packs A: `matrixmultiply`'s results, without its packing.
//!
//! Why hand-written: `matrixmultiply` copies both operands into panels on every call. On
//! the learner's shapes (outputs 16-256 wide, inner dimensions 16-1,024) each packed element
//! is used only 16-256 times, and a profile of one 6.4_2 update (bundled config) put 27 % of
//! the CPU time in `pack_avx512` against 30 % in the kernel itself. Here every element of A is
//! broadcast straight from memory (any strides), B is read in place when its rows are
//! contiguous and otherwise copied once per call (it is a weight matrix or a thin gradient,
//! at most k x n floats, small next to the m x k x n multiply-adds), and C is written in
//! place. The `gemm` crate packs too, and measured slower here (learner.md).
//!
//! Same bits as `matrixmultiply`: its FMA kernels (AVX-512 and AVX2) compute every element of
//! C as one fused multiply-add chain over the inner index in order, restarted from zero for
//! each 256-long piece of it (`S_KC`), and fold each piece into C with
//! `fma(alpha, acc, beta * C)` (beta 1 after the first piece; beta 0 never reads C). The
//! kernel below does exactly that, so outputs are bit-identical (tests compare with
//! `matrixmultiply` over layouts, tails and pieces). With alpha != 1, `matrixmultiply`'s
//! edge tiles round `alpha * acc` separately from the addition while its inner tiles do
//! not, so such calls are taken here only when that rounding is exact (alpha a power of
//! two) or C is not read (beta 0, one piece).

/// `matrixmultiply`'s inner-dimension piece for f32 (`archparam_defaults::S_KC`).
const KC: usize = 256;

/// Whether this CPU runs the kernel (AVX-512F; checked once).
#[cfg(target_arch = "x86_64")]
fn available() -> bool {
    use std::sync::OnceLock;
    static AVAILABLE: OnceLock<bool> = OnceLock::new();
    *AVAILABLE.get_or_init(|| {
        std::arch::is_x86_feature_detected!("avx512f")
            && std::env::var_os("TENDING_NO_DIRECT_GEMM").is_none()
    })
}

thread_local! {
    /// B copied row-major when its rows are strided, reused across calls. Taken out of the
    /// cell for the duration of a call (not borrowed): a rayon thread waiting inside a
    /// parallel GEMM may run another GEMM that needs it, and then allocates its own.
    static B_ROWS: std::cell::Cell<Vec<f32>> = const { std::cell::Cell::new(Vec::new()) };
}

/// Run `f` with B in a view whose rows are contiguous (`cs == 1`): B itself if they are,
/// else a row-major copy. Done once per `gemm` call, before any split into pieces, so a
/// weight matrix used transposed is copied once, not once per 256-row piece.
pub(super) fn with_contiguous_rows<R>(
    k: usize,
    n: usize,
    b: super::View,
    f: impl FnOnce(super::View) -> R,
) -> R {
    if b.cs == 1 || !uses_kernel() {
        return f(b);
    }
    let mut rows = B_ROWS.take();
    rows.clear();
    rows.resize(k * n, 0.0);
    // Column by column: a transposed weight matrix (rs 1) is then read contiguously.
    for j in 0..n {
        let col = &b.data[j * b.cs..];
        for (p, x) in rows.iter_mut().skip(j).step_by(n).enumerate() {
            *x = col[p * b.rs];
        }
    }
    let out = f(super::rm(&rows, n));
    B_ROWS.set(rows);
    out
}

/// A power of two (the attention's 1/sqrt(16) is one): `alpha acc` is then exact (short
/// of underflow to subnormals), so rounding it before or inside the final addition gives
/// the same bits, and matrixmultiply's edge and inner tiles agree with each other and with
/// this kernel.
fn exact_scale(alpha: f32) -> bool {
    alpha.is_normal() && alpha.to_bits() & 0x007f_ffff == 0
}

/// Whether `try_sgemm` can run on this CPU at all.
fn uses_kernel() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        available()
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// C (m x n, row stride `rsc`) = alpha A B + beta C as `matrixmultiply::sgemm` computes it.
/// Returns false, touching nothing, when the call is not one this kernel takes (the caller
/// then uses `matrixmultiply`). Bounds are checked by the caller (`super::sgemm`).
#[allow(clippy::too_many_arguments)]
pub(super) fn try_sgemm(
    m: usize,
    k: usize,
    n: usize,
    alpha: f32,
    a: super::View,
    b: super::View,
    beta: f32,
    c: &mut [f32],
    rsc: usize,
) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        if m == 0 || n == 0 || k == 0 || !available() {
            return false;
        }
        if !(alpha == 1.0 || exact_scale(alpha) || beta == 0.0 && k <= KC) {
            return false;
        }
        let run = |bp: &[f32], ldb: usize, c: &mut [f32]| {
            // SAFETY: AVX-512F is present (`available`); the caller checked that A, B and C
            // hold every element the m x k x n product touches, and `bp`/`ldb` describe B
            // row-major (in place or copied). C is a unique borrow.
            unsafe {
                avx512::gemm(
                    m,
                    k,
                    n,
                    alpha,
                    a.data.as_ptr(),
                    a.rs,
                    a.cs,
                    bp.as_ptr(),
                    ldb,
                    beta,
                    c.as_mut_ptr(),
                    rsc,
                )
            }
        };
        with_contiguous_rows(k, n, b, |b| run(b.data, b.rs, c));
        true
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = (m, k, n, alpha, a, b, beta, c, rsc);
        false
    }
}

#[cfg(target_arch = "x86_64")]
mod avx512 {
    use super::KC;
    use std::arch::x86_64::*;

    /// Columns per block: four 16-lane registers.
    const NB: usize = 64;

    /// Rows per tile for `v` registers of columns: `rows x v` accumulators plus `v` for B
    /// stay within the 32 vector registers.
    /// Narrow tiles take more rows: each row is one more independent FMA chain, and the
    /// FMA latency needs about 8 in flight per register of columns.
    const fn tile_rows(v: usize) -> usize {
        match v {
            1 => 16,
            2 => 12,
            _ => 6,
        }
    }

    /// See `try_sgemm`. B is row-major with row stride `ldb`.
    #[allow(clippy::too_many_arguments)]
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn gemm(
        m: usize,
        k: usize,
        n: usize,
        alpha: f32,
        a: *const f32,
        ars: usize,
        acs: usize,
        b: *const f32,
        ldb: usize,
        beta: f32,
        c: *mut f32,
        rsc: usize,
    ) {
        let mut k0 = 0;
        while k0 < k {
            let kc = KC.min(k - k0);
            // Pieces after the first add onto C, as matrixmultiply's do.
            let beta = if k0 == 0 { beta } else { 1.0 };
            let mut j0 = 0;
            while j0 < n {
                let nb = NB.min(n - j0);
                let v = nb.div_ceil(16);
                let tail = nb - 16 * (v - 1);
                let mask: __mmask16 = if tail == 16 {
                    0xFFFF
                } else {
                    (1u16 << tail) - 1
                };
                let rows = tile_rows(v);
                let mut i0 = 0;
                while i0 < m {
                    let r = rows.min(m - i0);
                    // SAFETY (all pointer offsets): inside the caller's checked extents.
                    let t = Tile {
                        kc,
                        a: unsafe { a.add(i0 * ars + k0 * acs) },
                        ars,
                        acs,
                        b: unsafe { b.add(k0 * ldb + j0) },
                        ldb,
                        c: unsafe { c.add(i0 * rsc + j0) },
                        rsc,
                        mask,
                        alpha,
                        beta,
                    };
                    unsafe { dispatch(&t, r, v) };
                    i0 += r;
                }
                j0 += nb;
            }
            k0 += kc;
        }
    }

    /// One tile's operands: `r` rows of C from `c`, `v` registers of columns (the last one
    /// masked), the inner piece `kc` long.
    struct Tile {
        kc: usize,
        a: *const f32,
        ars: usize,
        acs: usize,
        b: *const f32,
        ldb: usize,
        c: *mut f32,
        rsc: usize,
        mask: __mmask16,
        alpha: f32,
        beta: f32,
    }

    #[target_feature(enable = "avx512f")]
    unsafe fn dispatch(t: &Tile, r: usize, v: usize) {
        macro_rules! rows {
            ($v:literal; $($r:literal)*) => {
                match r {
                    $($r => unsafe { tile::<$r, $v>(t) },)*
                    _ => unreachable!("tile of {r} rows"),
                }
            };
        }
        match v {
            1 => rows!(1; 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16),
            2 => rows!(2; 1 2 3 4 5 6 7 8 9 10 11 12),
            3 => rows!(3; 1 2 3 4 5 6),
            4 => rows!(4; 1 2 3 4 5 6),
            _ => unreachable!("{v} column registers"),
        }
    }

    /// `R x 16V` block of C: accumulators in registers, one fused multiply-add chain per
    /// element over the piece, then `C = fma(alpha, acc, beta C)` (beta 0: `alpha acc`, C not
    /// read).
    #[inline]
    #[target_feature(enable = "avx512f")]
    unsafe fn tile<const R: usize, const V: usize>(t: &Tile) {
        let mut acc = [[_mm512_setzero_ps(); V]; R];
        let lane_mask = |w: usize| if w + 1 == V { t.mask } else { 0xFFFF };
        for p in 0..t.kc {
            // SAFETY: row p of B's block and A's column p of these rows are in bounds; the
            // masked-off lanes of the last register are neither read nor faulted on.
            let brow = unsafe { t.b.add(p * t.ldb) };
            let mut bv = [_mm512_setzero_ps(); V];
            for (w, x) in bv.iter_mut().enumerate() {
                *x = unsafe { _mm512_maskz_loadu_ps(lane_mask(w), brow.add(16 * w)) };
            }
            for (i, row) in acc.iter_mut().enumerate() {
                let av = _mm512_set1_ps(unsafe { *t.a.add(i * t.ars + p * t.acs) });
                for (x, y) in row.iter_mut().zip(&bv) {
                    *x = _mm512_fmadd_ps(av, *y, *x);
                }
            }
        }
        let alphav = _mm512_set1_ps(t.alpha);
        let betav = _mm512_set1_ps(t.beta);
        for (i, row) in acc.iter().enumerate() {
            for (w, x) in row.iter().enumerate() {
                let mask = lane_mask(w);
                // SAFETY: inside row i of C's block; masked lanes untouched.
                let cp = unsafe { t.c.add(i * t.rsc + 16 * w) };
                let out = if t.beta == 0.0 {
                    _mm512_mul_ps(alphav, *x)
                } else {
                    let cv = _mm512_mul_ps(unsafe { _mm512_maskz_loadu_ps(mask, cp) }, betav);
                    _mm512_fmadd_ps(alphav, *x, cv)
                };
                unsafe { _mm512_mask_storeu_ps(cp, mask, out) };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{rm, tr, View};
    use crate::gradcheck::rand_vec;

    /// `matrixmultiply` itself, for the reference bits.
    #[allow(clippy::too_many_arguments)]
    fn reference(
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
            )
        }
    }

    /// Every layout, row and column tails, inner dimensions across the 256 pieces, beta 0
    /// (C holding NaN, which must not be read), 1 and 0.5, alpha 1, 0.25 and (one piece, beta 0)
    /// 0.3: the same bits as
    /// `matrixmultiply`.
    #[test]
    fn same_bits_as_matrixmultiply() {
        if !super::uses_kernel() {
            // Without AVX-512F (or with TENDING_NO_DIRECT_GEMM) every call must fall back to
            // matrixmultiply, which is then the only GEMM and trivially has its own bits.
            let a = rand_vec(64, 1);
            let mut c = vec![0.0; 64];
            assert!(!super::try_sgemm(
                8,
                8,
                8,
                1.0,
                rm(&a, 8),
                rm(&a, 8),
                0.0,
                &mut c,
                8
            ));
            return;
        }
        let mut checked = 0;
        for &(m, k, n) in &[
            (1, 1, 1),
            (7, 16, 16),
            (13, 64, 64),
            (37, 300, 70),
            (9, 600, 5),
            (64, 1024, 64),
            (20, 17, 192),
            (6, 64, 130),
        ] {
            let a = rand_vec(m * k, 1);
            let b = rand_vec(k * n, 2);
            let rsc = n + 3;
            for (ai, av) in [rm(&a, k), tr(&a, m)].into_iter().enumerate() {
                for (bi, bv) in [rm(&b, n), tr(&b, k)].into_iter().enumerate() {
                    for &(alpha, beta) in &[
                        (1.0, 0.0),
                        (1.0, 1.0),
                        (1.0, 0.5),
                        (0.25, 0.0),
                        (0.25, 1.0),
                        (0.3, 0.0),
                    ] {
                        if alpha == 0.3 && k > super::KC {
                            continue; // declined (next test)
                        }
                        let mut c0 = rand_vec(m * rsc, 3);
                        if beta == 0.0 {
                            c0.iter_mut().step_by(2).for_each(|x| *x = f32::NAN);
                        }
                        let mut want = c0.clone();
                        reference(m, k, n, alpha, av, bv, beta, &mut want, rsc);
                        let mut got = c0.clone();
                        assert!(super::try_sgemm(
                            m, k, n, alpha, av, bv, beta, &mut got, rsc
                        ));
                        let same = want
                            .iter()
                            .zip(&got)
                            .all(|(x, y)| x.to_bits() == y.to_bits());
                        assert!(
                            same,
                            "m {m} k {k} n {n} layout A{ai} B{bi} alpha {alpha} beta {beta}"
                        );
                        checked += 1;
                    }
                }
            }
        }
        assert_eq!(checked, 8 * 4 * 6 - 3 * 4);
    }

    /// alpha neither 1 nor a power of two, on a C that is read or over several pieces, stays
    /// with `matrixmultiply`.
    #[test]
    fn declines_what_it_cannot_match() {
        let a = rand_vec(8 * 300, 1);
        let b = rand_vec(300 * 8, 2);
        let mut c = vec![0.0; 64];
        assert!(!super::try_sgemm(
            8,
            8,
            8,
            0.3,
            rm(&a, 8),
            rm(&b, 8),
            1.0,
            &mut c,
            8
        ));
        assert!(!super::try_sgemm(
            8,
            300,
            8,
            0.3,
            rm(&a, 300),
            rm(&b, 8),
            0.0,
            &mut c,
            8
        ));
        assert!(!super::try_sgemm(
            8,
            0,
            8,
            1.0,
            rm(&a, 8),
            rm(&b, 8),
            0.0,
            &mut c,
            8
        ));
    }
}
