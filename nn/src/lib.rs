//! Layers with hand-written forward and backward passes over `matrixmultiply::sgemm`.
//!
//! Conventions: every tensor is a row-major `f32` slice; parameters and gradients live in a
//! [`ParamStore`] and layers hold [`Slot`]s into it; `forward(p, ...)` reads parameters
//! from `p`, `backward(p, g, ...)` ACCUMULATES parameter gradients into `g`. Activations
//! needed by backward are kept by the caller (networks own caches that are resized, not
//! reallocated, after the first call).

pub mod adam;
pub mod attention;
pub mod categorical;
pub mod fastmath;
pub mod gemm;
#[cfg(any(test, feature = "gradcheck"))]
pub mod gradcheck;
pub mod gru;
pub mod init;
pub mod layernorm;
pub mod linear;
pub mod params;
pub mod relu;
pub mod simd;
pub mod tanh;

pub use adam::{clip_grad_norm, Adam, AdamConfig};
pub use attention::{Kv, MhaCache, MhaConfig, MultiHeadAttention};
pub use gru::{Gru, GruCache, GruConfig};
pub use init::Init;
pub use layernorm::{LayerNorm, LayerNormConfig};
pub use linear::{Linear, LinearConfig};
pub use params::{ParamEntry, ParamStore, Slot};

/// Resize a buffer to exactly `n` elements (no reallocation once capacity suffices) and
/// return it as a slice. Contents are unspecified: callers overwrite them.
#[inline]
pub fn sized(v: &mut Vec<f32>, n: usize) -> &mut [f32] {
    v.resize(n, 0.0);
    &mut v[..n]
}

/// Dot product with 8 independent accumulators (lets the compiler vectorise the sum,
/// which it may not reorder on its own).
#[inline]
pub fn dot(a: &[f32], b: &[f32]) -> f32 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0f32; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for i in 0..8 {
            acc[i] += x[i] * y[i];
        }
    }
    let mut s = (acc[0] + acc[4]) + (acc[1] + acc[5]) + ((acc[2] + acc[6]) + (acc[3] + acc[7]));
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}
