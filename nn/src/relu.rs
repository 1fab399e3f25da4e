//! ReLU activation (in place); backward uses the output.

pub fn forward(x: &mut [f32]) {
    x.iter_mut().for_each(|v| *v = v.max(0.0));
}

/// dy = 0 where the output was not positive.
pub fn backward(y: &[f32], dy: &mut [f32]) {
    for (d, &v) in dy.iter_mut().zip(y) {
        if v <= 0.0 {
            *d = 0.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::gradcheck::*;

    #[test]
    fn gradient_matches_finite_differences() {
        // keep values away from the kink at 0
        let x: Vec<f32> = rand_vec(10, 1)
            .into_iter()
            .map(|v| if v.abs() < 0.1 { v + 0.3 } else { v })
            .collect();
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
        assert_grad_close("relu", &d, &num);
        assert!(d.contains(&0.0) && d.iter().any(|v| *v != 0.0));
    }
}
