//! Tanh activation (in place); backward uses the output.

use super::simd::dispatch;

dispatch! {
    /// In place, with the branch-free `fastmath::tanh` so the loop vectorises.
    pub fn forward(x: &mut [f32]) {
        x.iter_mut().for_each(|v| *v = super::fastmath::tanh(*v));
    }
}

/// dy *= 1 - y^2, where y is the forward output.
pub fn backward(y: &[f32], dy: &mut [f32]) {
    for (d, &v) in dy.iter_mut().zip(y) {
        *d *= 1.0 - v * v;
    }
}

#[cfg(test)]
mod tests {
    use crate::gradcheck::*;

    #[test]
    fn gradient_matches_finite_differences() {
        let x = rand_vec(10, 1);
        let r = rand_vec(10, 2);
        let mut y = x.clone();
        super::forward(&mut y);
        let mut d = r.clone();
        super::backward(&y, &mut d);
        let num = numeric_grad(&mut x.clone(), |xx| {
            let mut y = xx.to_vec();
            super::forward(&mut y);
            dot_loss(&y, &r)
        });
        assert_grad_close("tanh", &d, &num);
    }
}
