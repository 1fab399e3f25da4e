//! Whole-network tests: gradients, invariances, and that training, rollout and inference
//! compute the same function.

use crate::{Actor, ArchConfig, Critic, ModelKind, PpoActorConfig, Sequences, ValueLossConfig};
use nn::gradcheck::{assert_grad_close, assert_grad_close_scaled, numeric_grad, rand_vec};
use obs::{Counts, FlatLayout, ObsBatch};
use rand::{Rng, SeedableRng};

pub(crate) fn small_arch(kind: ModelKind) -> ArchConfig {
    let mut a = match kind {
        ModelKind::Smappo => ArchConfig::smappo(),
        ModelKind::Mappo => ArchConfig::mappo(
            FlatLayout {
                max_machines: 3,
                max_storages: 2,
                max_peers: 3,
            },
            4,
        ),
    };
    a.d_model = 8;
    a.heads = 2;
    a.hidden = 8;
    a
}

pub(crate) fn rand_obs(rows: usize, counts: Counts, seed: u64) -> ObsBatch {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut b = ObsBatch::zeros(rows, counts);
    let mut fill = |v: &mut Vec<f32>, dim: usize, flag: Option<usize>| {
        for (i, x) in v.iter_mut().enumerate() {
            *x = if Some(i % dim) == flag {
                rng.gen_range(0..2) as f32
            } else {
                rng.gen_range(-1.0..1.0)
            };
        }
    };
    fill(&mut b.own, 3, Some(2));
    fill(&mut b.machines, 3, Some(2));
    fill(&mut b.storages, 2, None);
    fill(&mut b.peers, 3, Some(2));
    b.validate().unwrap();
    b
}

fn counts(m: usize, s: usize, p: usize) -> Counts {
    Counts {
        machines: m,
        storages: s,
        peers: p,
    }
}

fn loss_of(y: &[f32], r: &[f32]) -> f64 {
    y.iter().zip(r).map(|(a, b)| *a as f64 * *b as f64).sum()
}

#[test]
fn actor_gradients_match_finite_differences() {
    for kind in [ModelKind::Smappo, ModelKind::Mappo] {
        let mut actor = Actor::new(small_arch(kind), 1);
        // non-zero biases / perturbed norms so every path carries gradient
        let pert = rand_vec(actor.params.len(), 2);
        for (x, p) in actor.params.data.iter_mut().zip(&pert) {
            *x += 0.05 * p;
        }
        let (t, b) = (3, 2);
        let obs = rand_obs(t * b, counts(2, 1, 3), 3);
        let h0 = rand_vec(b * 8, 4);
        let masks = [1.0, 1.0, 1.0, 0.0, 1.0, 1.0];
        let r = rand_vec(t * b * 5, 5);
        actor.forward_seq(&obs, t, b, &h0, &masks).unwrap();
        actor.params.zero_grad();
        actor.backward(&r);
        let analytic = actor.params.grad.clone();
        let mut probe = actor.clone();
        let mut data = actor.params.data.clone();
        let num = numeric_grad(&mut data, |p| {
            probe.params.data.copy_from_slice(p);
            let y = probe.forward_seq(&obs, t, b, &h0, &masks).unwrap();
            loss_of(y, &r)
        });
        for e in &actor.params.entries {
            let rg = e.slot.r();
            assert_grad_close(
                &format!("{kind}: {}", e.name),
                &analytic[rg.clone()],
                &num[rg.clone()],
            );
            assert!(
                analytic[rg].iter().any(|g| *g != 0.0),
                "{kind}: {} has no gradient",
                e.name
            );
        }
    }
}

#[test]
fn critic_gradients_match_finite_differences() {
    for kind in [ModelKind::Smappo, ModelKind::Mappo] {
        let mut critic = Critic::new(small_arch(kind), 1);
        let pert = rand_vec(critic.params.len(), 2);
        for (x, p) in critic.params.data.iter_mut().zip(&pert) {
            *x += 0.05 * p;
        }
        // 2 steps, 2 envs of 3 robots
        let (t, b, n) = (2, 6, 3);
        let obs = rand_obs(t * b, counts(2, 1, 2), 3);
        let h0 = rand_vec(b * 8, 4);
        let mut masks = vec![1.0; t * b];
        masks[7] = 0.0;
        let r = rand_vec(t * b, 5);
        critic.forward_seq(&obs, t, b, n, &h0, &masks).unwrap();
        critic.params.zero_grad();
        critic.backward(&r);
        let analytic = critic.params.grad.clone();
        let mut probe = critic.clone();
        let mut data = critic.params.data.clone();
        let num = numeric_grad(&mut data, |p| {
            probe.params.data.copy_from_slice(p);
            let y = probe.forward_seq(&obs, t, b, n, &h0, &masks).unwrap();
            loss_of(y, &r)
        });
        let scale = num.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for e in &critic.params.entries {
            let rg = e.slot.r();
            assert_grad_close_scaled(
                &format!("{kind}: {}", e.name),
                &analytic[rg.clone()],
                &num[rg.clone()],
                scale,
            );
            assert!(
                analytic[rg].iter().any(|g| *g != 0.0),
                "{kind}: {} has no gradient",
                e.name
            );
        }
    }
}

#[test]
fn smappo_actor_is_permutation_invariant_and_takes_any_counts() {
    let mut actor = Actor::new(small_arch(ModelKind::Smappo), 7);
    let obs = rand_obs(1, counts(4, 3, 3), 8);
    let h0 = rand_vec(8, 9);
    let base = actor.forward_seq(&obs, 1, 1, &h0, &[1.0]).unwrap().to_vec();
    let mut perm = obs.clone();
    // reverse machines, rotate storages, swap two peers
    for (v, dim, n) in [
        (&mut perm.machines, 3, 4),
        (&mut perm.storages, 2, 3),
        (&mut perm.peers, 3, 3),
    ] {
        let rows: Vec<Vec<f32>> = v.chunks(dim).map(|c| c.to_vec()).collect();
        let order: Vec<usize> = match dim {
            2 => vec![1, 2, 0],
            _ if n == 4 => vec![3, 2, 1, 0],
            _ => vec![0, 2, 1],
        };
        *v = order.iter().flat_map(|&i| rows[i].clone()).collect();
    }
    assert_ne!(perm, obs);
    let out = actor.forward_seq(&perm, 1, 1, &h0, &[1.0]).unwrap();
    for (a, b) in base.iter().zip(out) {
        assert!((a - b).abs() < 1e-5, "{a} vs {b}");
    }
    // the same network takes other counts, including empty groups (a lone robot)
    for c in [
        counts(1, 1, 0),
        counts(0, 0, 0),
        counts(9, 4, 13),
        counts(0, 2, 5),
    ] {
        let o = rand_obs(3, c, 10);
        let y = actor
            .forward_seq(&o, 1, 3, &rand_vec(24, 1), &[1.0; 3])
            .unwrap();
        assert_eq!(y.len(), 15);
        assert!(y.iter().all(|v| v.is_finite()));
    }
    // and a change of a machine's features does change the output
    let mut moved = obs.clone();
    moved.machines[0] += 0.5;
    let out = actor.forward_seq(&moved, 1, 1, &h0, &[1.0]).unwrap();
    assert!(base.iter().zip(out).any(|(a, b)| (a - b).abs() > 1e-7));
}

#[test]
fn batch_forward_equals_per_row_forward_and_sequence_equals_steps() {
    for kind in [ModelKind::Smappo, ModelKind::Mappo] {
        let mut actor = Actor::new(small_arch(kind), 11);
        let (t, b) = (4, 3);
        let obs = rand_obs(t * b, counts(3, 2, 2), 12);
        let h0 = rand_vec(b * 8, 13);
        let mut masks = vec![1.0; t * b];
        masks[4] = 0.0; // env row 1 restarts at step 1
        masks[9] = 0.0; // env row 0 restarts at step 3
        let seq = actor.forward_seq(&obs, t, b, &h0, &masks).unwrap().to_vec();
        let last = actor.last_hidden().to_vec();
        // stepwise, one row at a time (the rollout / inference path)
        for r in 0..b {
            let mut h = h0[r * 8..(r + 1) * 8].to_vec();
            for s in 0..t {
                let row = obs.row(s * b + r);
                let y = actor
                    .forward_step(&row, &mut h, &[masks[s * b + r]])
                    .unwrap();
                for k in 0..5 {
                    let want = seq[(s * b + r) * 5 + k];
                    assert!(
                        (y[k] - want).abs() < 1e-5,
                        "{kind} t{s} r{r}: {} vs {want}",
                        y[k]
                    );
                }
            }
            for k in 0..8 {
                assert!((h[k] - last[r * 8 + k]).abs() < 1e-5);
            }
        }
    }
}

#[test]
fn critic_batch_equals_per_env_and_is_agent_order_equivariant() {
    let mut critic = Critic::new(small_arch(ModelKind::Smappo), 3);
    let (b, n) = (6, 3);
    let obs = rand_obs(b, counts(2, 2, 2), 4);
    let h0 = vec![0.0; b * 8];
    let all = critic
        .forward_seq(&obs, 1, b, n, &h0, &[1.0; 6])
        .unwrap()
        .to_vec();
    // env 1 alone
    let mut env1 = ObsBatch::default();
    for r in 3..6 {
        env1.extend_from(&obs.row(r)).unwrap();
    }
    let one = critic
        .forward_seq(&env1, 1, 3, n, &h0[..24], &[1.0; 3])
        .unwrap()
        .to_vec();
    for i in 0..3 {
        assert!((one[i] - all[3 + i]).abs() < 1e-5);
    }
    // swapping two robots of env 1 swaps their values
    let mut sw = ObsBatch::default();
    for r in [4, 3, 5] {
        sw.extend_from(&obs.row(r)).unwrap();
    }
    let s = critic
        .forward_seq(&sw, 1, 3, n, &h0[..24], &[1.0; 3])
        .unwrap();
    assert!((s[0] - one[1]).abs() < 1e-5 && (s[1] - one[0]).abs() < 1e-5);
    // different robot counts per env work
    let o = rand_obs(5, counts(1, 1, 4), 5);
    assert!(critic
        .forward_seq(&o, 1, 5, 5, &[0.0; 40], &[1.0; 5])
        .is_ok());
    assert!(critic
        .forward_seq(&o, 1, 5, 2, &[0.0; 40], &[1.0; 5])
        .is_err());
}

#[test]
fn mappo_refuses_counts_beyond_its_layout() {
    let mut actor = Actor::new(small_arch(ModelKind::Mappo), 1);
    let ok = rand_obs(1, counts(3, 2, 3), 1);
    assert!(actor.forward_seq(&ok, 1, 1, &[0.0; 8], &[1.0]).is_ok());
    let big = rand_obs(1, counts(4, 2, 3), 1);
    let err = actor
        .forward_seq(&big, 1, 1, &[0.0; 8], &[1.0])
        .unwrap_err();
    assert!(err.to_string().contains("machines"), "{err}");
    let mut critic = Critic::new(small_arch(ModelKind::Mappo), 1);
    let five = rand_obs(5, counts(1, 1, 3), 2);
    assert!(critic
        .forward_seq(&five, 1, 5, 5, &[0.0; 40], &[1.0; 5])
        .is_err());
}

#[test]
fn ppo_training_drives_losses_down() {
    // Supervised sanity: advantages favour action (row % 5); PPO with a fresh "old" policy
    // each iteration must raise the log-prob of those actions. The critic regresses a target.
    for kind in [ModelKind::Smappo, ModelKind::Mappo] {
        let mut actor = Actor::new(small_arch(kind), 21);
        actor.opt.cfg.lr = 3e-3;
        let (t, b) = (2, 10);
        let obs = rand_obs(t * b, counts(2, 1, 1), 22);
        let h0 = vec![0.0; b * 8];
        let masks = vec![1.0; t * b];
        let actions: Vec<u8> = (0..t * b).map(|r| (r % 5) as u8).collect();
        let adv = vec![1.0; t * b];
        let seq = Sequences::new(&obs, t, b, &h0, &masks);
        let logp_of = |a: &mut Actor| -> Vec<f32> {
            let y = a.forward_seq(&obs, t, b, &h0, &masks).unwrap().to_vec();
            (0..t * b)
                .map(|r| {
                    let mut lp = [0.0; 5];
                    nn::categorical::log_softmax(&y[r * 5..(r + 1) * 5], &mut lp);
                    lp[actions[r] as usize]
                })
                .collect()
        };
        let start: f32 = logp_of(&mut actor).iter().sum();
        for _ in 0..60 {
            let old = logp_of(&mut actor);
            for _ in 0..4 {
                actor
                    .ppo_grads(seq, &actions, &old, &adv, PpoActorConfig::default())
                    .unwrap();
                actor.step(10.0);
            }
        }
        let end: f32 = logp_of(&mut actor).iter().sum();
        assert!(end > start + 10.0, "{kind}: log-prob sum {start} -> {end}");

        let mut critic = Critic::new(small_arch(kind), 23);
        critic.opt.cfg.lr = 3e-3;
        let n = 2;
        let target: Vec<f32> = (0..t * b).map(|r| obs.own[r * 3]).collect();
        let cfg = ValueLossConfig {
            clip: 10.0,
            ..Default::default()
        };
        let mut first = None;
        let mut last = 0.0;
        for _ in 0..300 {
            let old = critic
                .forward_seq(&obs, t, b, n, &h0, &masks)
                .unwrap()
                .to_vec();
            let st = critic.value_grads(seq, n, &old, &target, cfg).unwrap();
            critic.step(10.0);
            first.get_or_insert(st.value_loss);
            last = st.value_loss;
        }
        assert!(
            last < 0.2 * first.unwrap(),
            "{kind}: value loss {first:?} -> {last}"
        );
    }
}

#[test]
fn ppo_gradient_matches_finite_differences_of_the_loss() {
    let mut actor = Actor::new(small_arch(ModelKind::Smappo), 31);
    let (t, b) = (2, 2);
    let obs = rand_obs(t * b, counts(1, 1, 1), 32);
    let h0 = rand_vec(b * 8, 33);
    let masks = vec![1.0; t * b];
    let actions = [0u8, 3, 4, 1];
    let adv = [1.0, -0.5, 2.0, 0.3];
    // old log-probs chosen so that some ratios are clipped and some not
    let y = actor.forward_seq(&obs, t, b, &h0, &masks).unwrap().to_vec();
    let old: Vec<f32> = (0..4)
        .map(|r| {
            let mut lp = [0.0; 5];
            nn::categorical::log_softmax(&y[r * 5..(r + 1) * 5], &mut lp);
            lp[actions[r] as usize] + [0.0, 0.5, -0.5, 0.05][r]
        })
        .collect();
    let cfg = PpoActorConfig::default();
    let seq = Sequences::new(&obs, t, b, &h0, &masks);
    actor.params.zero_grad();
    let st = actor.ppo_grads(seq, &actions, &old, &adv, cfg).unwrap();
    assert!(st.clip_frac > 0.0 && st.clip_frac < 1.0);
    let analytic = actor.params.grad.clone();
    let mut probe = actor.clone();
    let num = numeric_grad(&mut actor.params.data.clone(), |p| {
        probe.params.data.copy_from_slice(p);
        probe.params.zero_grad();
        probe
            .ppo_grads(seq, &actions, &old, &adv, cfg)
            .unwrap()
            .loss as f64
    });
    assert_grad_close("ppo loss", &analytic, &num);
}

/// The shield's logit bias in the PPO update: a zero bias changes nothing (bit for bit); a
/// masked action gets probability 0, so the loss stays finite and equals the loss of
/// logits with that action removed.
#[test]
fn ppo_logit_bias_masks_actions_and_zero_bias_is_neutral() {
    let mut actor = Actor::new(small_arch(ModelKind::Smappo), 41);
    let (t, b) = (2, 2);
    let obs = rand_obs(t * b, counts(1, 1, 1), 42);
    let h0 = rand_vec(b * 8, 43);
    let masks = vec![1.0; t * b];
    let actions = [0u8, 3, 4, 1];
    let adv = [1.0, -0.5, 2.0, 0.3];
    let old = [-1.6f32; 4];
    let cfg = PpoActorConfig::default();
    let seq = Sequences::new(&obs, t, b, &h0, &masks);
    let run = |a: &mut Actor, bias: &[f32]| {
        a.params.zero_grad();
        let st = a
            .ppo_grads_biased(seq, &actions, &old, &adv, bias, cfg)
            .unwrap();
        (st, a.params.grad.clone())
    };
    let (s0, g0) = run(&mut actor, &[]);
    let (s1, g1) = run(&mut actor, &[0.0; 20]);
    assert_eq!(s0.loss.to_bits(), s1.loss.to_bits());
    assert_eq!(g0, g1);
    // Mask action 2 in every row (never the taken one): entropy drops, all stays finite.
    let mut bias = [0.0f32; 20];
    for r in 0..4 {
        bias[r * 5 + 2] = plan::shield::MASKED_LOGIT;
    }
    let (s2, g2) = run(&mut actor, &bias);
    assert!(s2.loss.is_finite() && g2.iter().all(|g| g.is_finite()));
    assert!(s2.entropy < s0.entropy, "{} !< {}", s2.entropy, s0.entropy);
    assert_ne!(g2, g0);
    // A wrong bias length is refused.
    assert!(actor
        .ppo_grads_biased(seq, &actions, &old, &adv, &[0.0; 3], cfg)
        .is_err());
}
