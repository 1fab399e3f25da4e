//! Weight initialisation: orthogonal (MAPPO's default) and scaled uniform.

use rand::Rng;
use serde::{Deserialize, Serialize};

/// How a weight matrix is initialised. Biases always start at zero.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Init {
    /// Orthogonal rows/columns times `gain` (torch.nn.init.orthogonal_).
    Orthogonal { gain: f32 },
    /// U(-scale / sqrt(fan_in), scale / sqrt(fan_in)).
    Uniform { scale: f32 },
}

/// Standard normal sample (Box-Muller).
pub fn normal(rng: &mut impl Rng) -> f64 {
    let u1: f64 = rng.gen::<f64>().max(1e-300);
    let u2: f64 = rng.gen();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// Fill a row-major `rows x cols` matrix.
pub fn fill(init: Init, w: &mut [f32], rows: usize, cols: usize, rng: &mut impl Rng) {
    assert_eq!(w.len(), rows * cols);
    match init {
        Init::Uniform { scale } => {
            let a = scale / (cols.max(1) as f32).sqrt();
            for x in w.iter_mut() {
                *x = rng.gen_range(-a..=a);
            }
        }
        Init::Orthogonal { gain } => orthogonal(w, rows, cols, gain, rng),
    }
}

/// Orthogonal matrix: if rows >= cols the columns are orthonormal, else the rows are.
fn orthogonal(w: &mut [f32], rows: usize, cols: usize, gain: f32, rng: &mut impl Rng) {
    if rows == 0 || cols == 0 {
        return;
    }
    let (big, small) = (rows.max(cols), rows.min(cols));
    // `small` vectors of length `big`, orthonormalised by modified Gram-Schmidt.
    let mut v: Vec<Vec<f64>> = (0..small)
        .map(|_| (0..big).map(|_| normal(rng)).collect())
        .collect();
    for i in 0..small {
        for j in 0..i {
            let (done, rest) = v.split_at_mut(i);
            let (vi, vj) = (&mut rest[0], &done[j]);
            let d: f64 = vi.iter().zip(vj.iter()).map(|(a, b)| a * b).sum();
            for (a, b) in vi.iter_mut().zip(vj.iter()) {
                *a -= d * b;
            }
        }
        let n: f64 = v[i].iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-12);
        v[i].iter_mut().for_each(|x| *x /= n);
    }
    for r in 0..rows {
        for c in 0..cols {
            let x = if rows >= cols { v[c][r] } else { v[r][c] };
            w[r * cols + c] = (x as f32) * gain;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn orthogonal_is_orthogonal_both_ways() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(1);
        for (r, c) in [(4, 7), (7, 4), (5, 5)] {
            let mut w = vec![0.0; r * c];
            fill(Init::Orthogonal { gain: 2.0 }, &mut w, r, c, &mut rng);
            // W W^T = 4 I (rows) when r <= c, W^T W = 4 I when r >= c
            let (n, dot): (usize, Box<dyn Fn(usize, usize) -> f32>) = if r <= c {
                (
                    r,
                    Box::new(|i, j| (0..c).map(|k| w[i * c + k] * w[j * c + k]).sum()),
                )
            } else {
                (
                    c,
                    Box::new(|i, j| (0..r).map(|k| w[k * c + i] * w[k * c + j]).sum()),
                )
            };
            for i in 0..n {
                for j in 0..n {
                    let want = if i == j { 4.0 } else { 0.0 };
                    assert!((dot(i, j) - want).abs() < 1e-4, "{r}x{c} ({i},{j})");
                }
            }
        }
    }

    #[test]
    fn uniform_respects_bound() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(2);
        let mut w = vec![0.0; 64 * 16];
        fill(Init::Uniform { scale: 1.0 }, &mut w, 64, 16, &mut rng);
        assert!(w.iter().all(|x| x.abs() <= 0.25 + 1e-6));
        assert!(w.iter().any(|x| x.abs() > 0.2));
    }
}
