//! Generalised advantage estimation (Schulman et al.; MAPPO `compute_returns` with GAE).

#[allow(clippy::needless_range_loop)]
/// GAE over a rollout stored step-major: entry `t * b + j` is sequence `j` (one robot) at
/// step `t`. `values` are unnormalised V(s_t); `dones[t*b + j]` says the episode ended
/// with step t (no bootstrap through it); `last_values` (b) are V of the state after the
/// last step. Writes advantages and returns (= advantages + values).
#[allow(clippy::too_many_arguments)]
pub fn gae(
    rewards: &[f32],
    values: &[f32],
    dones: &[bool],
    last_values: &[f32],
    t: usize,
    b: usize,
    gamma: f32,
    lambda: f32,
    adv: &mut [f32],
    ret: &mut [f32],
) {
    assert_eq!(rewards.len(), t * b);
    assert_eq!(values.len(), t * b);
    assert_eq!(dones.len(), t * b);
    assert_eq!(last_values.len(), b);
    assert_eq!(adv.len(), t * b);
    assert_eq!(ret.len(), t * b);
    for j in 0..b {
        let mut acc = 0.0f32;
        for s in (0..t).rev() {
            let i = s * b + j;
            let next_v = if s + 1 < t {
                values[i + b]
            } else {
                last_values[j]
            };
            let mask = if dones[i] { 0.0 } else { 1.0 };
            let delta = rewards[i] + gamma * next_v * mask - values[i];
            acc = delta + gamma * lambda * mask * acc;
            adv[i] = acc;
            ret[i] = acc + values[i];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hand-computed: gamma 0.5, lambda 0.5, one sequence of 3 steps, rewards [1, 0, 2],
    /// values [0.5, 1, 1], bootstrap 4, no done:
    /// delta2 = 2 + 0.5*4 - 1 = 3;       A2 = 3
    /// delta1 = 0 + 0.5*1 - 1 = -0.5;    A1 = -0.5 + 0.25*3 = 0.25
    /// delta0 = 1 + 0.5*1 - 0.5 = 1;     A0 = 1 + 0.25*0.25 = 1.0625
    /// With a done at step 1: delta1 = -1, A1 = -1; A0 = 1 + 0.25*(-1) = 0.75; A2 as above.
    #[test]
    fn hand_computed_example() {
        let (r, v) = ([1.0, 0.0, 2.0], [0.5, 1.0, 1.0]);
        let (mut a, mut ret) = ([0.0; 3], [0.0; 3]);
        gae(
            &r,
            &v,
            &[false; 3],
            &[4.0],
            3,
            1,
            0.5,
            0.5,
            &mut a,
            &mut ret,
        );
        assert_eq!(a, [1.0625, 0.25, 3.0]);
        assert_eq!(ret, [1.5625, 1.25, 4.0]);
        gae(
            &r,
            &v,
            &[false, true, false],
            &[4.0],
            3,
            1,
            0.5,
            0.5,
            &mut a,
            &mut ret,
        );
        assert_eq!(a, [0.75, -1.0, 3.0]);
    }

    /// Two interleaved sequences give the same result as each alone (layout t*b + j).
    #[test]
    fn sequences_are_independent() {
        let r = [1.0, -1.0, 0.0, 2.0, 2.0, 0.5];
        let v = [0.5, 0.1, 1.0, 0.2, 1.0, 0.3];
        let d = [false, false, true, false, false, true];
        let (mut a, mut ret) = ([0.0; 6], [0.0; 6]);
        gae(&r, &v, &d, &[4.0, 9.0], 3, 2, 0.9, 0.8, &mut a, &mut ret);
        for j in 0..2 {
            let rj: Vec<f32> = (0..3).map(|s| r[s * 2 + j]).collect();
            let vj: Vec<f32> = (0..3).map(|s| v[s * 2 + j]).collect();
            let dj: Vec<bool> = (0..3).map(|s| d[s * 2 + j]).collect();
            let lv = [[4.0], [9.0]][j];
            let (mut aj, mut rtj) = ([0.0; 3], [0.0; 3]);
            gae(&rj, &vj, &dj, &lv, 3, 1, 0.9, 0.8, &mut aj, &mut rtj);
            for s in 0..3 {
                assert_eq!(a[s * 2 + j], aj[s]);
            }
        }
        // lambda = 1, gamma = 1, no done: advantage = sum of future rewards + bootstrap - v
        let (mut a1, mut r1) = ([0.0; 2], [0.0; 2]);
        gae(
            &[1.0, 2.0],
            &[0.0, 0.0],
            &[false, false],
            &[3.0],
            2,
            1,
            1.0,
            1.0,
            &mut a1,
            &mut r1,
        );
        assert_eq!(a1, [6.0, 5.0]);
    }
}
