//! Test helpers: central finite differences against analytic gradients.

/// Central differences of `f` w.r.t. every element of `x` (eps 1e-3).
pub fn numeric_grad(x: &mut [f32], mut f: impl FnMut(&[f32]) -> f64) -> Vec<f64> {
    let eps = 1e-3f32;
    (0..x.len())
        .map(|i| {
            let orig = x[i];
            x[i] = orig + eps;
            let lp = f(x);
            x[i] = orig - eps;
            let lm = f(x);
            x[i] = orig;
            (lp - lm) / (2.0 * eps as f64)
        })
        .collect()
}

/// Assert analytic ~ numeric: relative tolerance 2e-2 plus an absolute floor of 2e-3 of the
/// tensor's largest gradient (f32 forward passes make tiny entries noisy).
pub fn assert_grad_close(label: &str, analytic: &[f32], numeric: &[f64]) {
    let scale = numeric.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    assert_grad_close_scaled(label, analytic, numeric, scale);
}

/// As [`assert_grad_close`] with the absolute floor taken from `scale` (e.g. the largest
/// gradient of the whole network, since f32 noise in a finite difference scales with the
/// loss, not with the tensor).
pub fn assert_grad_close_scaled(label: &str, analytic: &[f32], numeric: &[f64], scale: f64) {
    assert_eq!(analytic.len(), numeric.len(), "{label}: length");
    for (i, (&a, &n)) in analytic.iter().zip(numeric).enumerate() {
        let a = a as f64;
        let tol = 2e-2 * a.abs().max(n.abs()) + 2e-3 * scale.max(1e-2);
        assert!(
            (a - n).abs() <= tol,
            "{label}[{i}]: analytic {a} vs numeric {n} (tol {tol})"
        );
    }
}

/// Deterministic pseudo-random values in [-1, 1).
pub fn rand_vec(n: usize, seed: u64) -> Vec<f32> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    (0..n).map(|_| rng.gen_range(-1.0..1.0)).collect()
}

/// sum(y * r) in f64: a loss whose gradient w.r.t. y is `r`.
pub fn dot_loss(y: &[f32], r: &[f32]) -> f64 {
    y.iter().zip(r).map(|(&a, &b)| a as f64 * b as f64).sum()
}
