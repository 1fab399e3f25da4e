//! Categorical distribution over logits: log-softmax, log-prob of the taken action, entropy,
//! and the gradient of `w_logp * logp(a) + w_ent * H` w.r.t. the logits.

/// log-softmax of one row into `out`.
pub fn log_softmax(logits: &[f32], out: &mut [f32]) {
    let mx = logits.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
    let lse = mx + logits.iter().map(|x| (x - mx).exp()).sum::<f32>().ln();
    for (o, x) in out.iter_mut().zip(logits) {
        *o = x - lse;
    }
}

/// Entropy -sum p log p of one row of log-probabilities.
pub fn entropy(logp: &[f32]) -> f32 {
    -logp.iter().map(|l| l.exp() * l).sum::<f32>()
}

/// For one row: given log-probs `logp` (from [`log_softmax`]), the taken action and
/// weights, writes dlogits = w_logp * d logp(a) / dlogits + w_ent * dH / dlogits.
pub fn backward_row(logp: &[f32], action: usize, w_logp: f32, w_ent: f32, dlogits: &mut [f32]) {
    let h = entropy(logp);
    for (k, (d, &l)) in dlogits.iter_mut().zip(logp).enumerate() {
        let p = l.exp();
        let onehot = if k == action { 1.0 } else { 0.0 };
        *d = w_logp * (onehot - p) + w_ent * (-p * (l + h));
    }
}

/// Index of the largest logit (first on ties).
pub fn argmax(logits: &[f32]) -> usize {
    let mut best = 0;
    for (i, &v) in logits.iter().enumerate() {
        if v > logits[best] {
            best = i;
        }
    }
    best
}

/// Sample an index from softmax(logits) given a uniform `u` in [0, 1).
pub fn sample(logits: &[f32], u: f32) -> usize {
    let mx = logits.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
    let z: f32 = logits.iter().map(|x| (x - mx).exp()).sum();
    let mut acc = 0.0;
    for (i, x) in logits.iter().enumerate() {
        acc += (x - mx).exp() / z;
        if u < acc {
            return i;
        }
    }
    logits.len() - 1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gradcheck::*;

    #[test]
    fn logsoftmax_normalises_and_entropy_of_uniform() {
        let mut lp = [0.0; 5];
        log_softmax(&[1.0, 2.0, 3.0, 4.0, 1000.0], &mut lp);
        assert!((lp.iter().map(|l| l.exp()).sum::<f32>() - 1.0).abs() < 1e-5);
        assert!(lp.iter().all(|l| l.is_finite()));
        log_softmax(&[0.5; 5], &mut lp);
        assert!((entropy(&lp) - 5f32.ln()).abs() < 1e-5);
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let logits = rand_vec(5, 1);
        let (wl, we) = (0.7, -0.3);
        let f = |x: &[f32]| {
            let mut lp = [0.0; 5];
            log_softmax(x, &mut lp);
            wl as f64 * lp[2] as f64 + we as f64 * entropy(&lp) as f64
        };
        let mut lp = [0.0; 5];
        log_softmax(&logits, &mut lp);
        let mut d = [0.0; 5];
        backward_row(&lp, 2, wl, we, &mut d);
        let num = numeric_grad(&mut logits.clone(), f);
        assert_grad_close("dlogits", &d, &num);
    }

    #[test]
    fn sampling_follows_probabilities() {
        let logits = [0.0, (3.0f32).ln(), f32::NEG_INFINITY, 0.0, 0.0];
        // p = [1/6, 3/6, 0, 1/6, 1/6]
        let n = 6000;
        let mut counts = [0usize; 5];
        for i in 0..n {
            counts[sample(&logits, (i as f32 + 0.5) / n as f32)] += 1;
        }
        assert_eq!(counts[2], 0);
        assert!((counts[1] as f32 / n as f32 - 0.5).abs() < 0.01);
        assert_eq!(argmax(&logits), 1);
    }
}
