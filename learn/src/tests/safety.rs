//! Training behind a safety layer: the shield, the ORCA filter, PPO-Lagrangian.

use super::*;

/// `shield = true` trains behind the action shield: updates run with finite statistics,
/// and the masked distribution differs from the unshielded one on the same rollout seed.
#[test]
fn shielded_training_runs() {
    let sc = short_episodes();
    let mk = |shield| {
        let cfg = tiny(TrainConfig {
            shield,
            ..TrainConfig::default()
        });
        Trainer::new(
            ModelKind::Smappo,
            cfg,
            sc.clone(),
            parse_curriculum("4.2_2:8").unwrap(),
            7,
        )
        .unwrap()
    };
    let (mut on, mut off) = (mk(true), mk(false));
    let (a, b) = (on.step().unwrap(), off.step().unwrap());
    assert!(a.policy_loss.is_finite() && a.entropy.is_finite() && a.value_loss.is_finite());
    assert_ne!(a.entropy, b.entropy);
    assert!(TrainConfig::from_toml("shield = true\n").unwrap().shield);
}

/// `orca_filter = true` steps the simulator with the ORCA-filtered velocities: a fresh
/// (near-uniform) policy in a crowded room touches far less than without the filter.
#[test]
fn orca_filtered_rollouts_touch_less() {
    let mut on = crowded(TrainConfig {
        orca_filter: true,
        ..TrainConfig::default()
    });
    let mut off = crowded(TrainConfig::default());
    let (mut r_on, mut r_off) = (0.0, 0.0);
    for _ in 0..2 {
        r_on += on.step().unwrap().contact_rate;
        r_off += off.step().unwrap().contact_rate;
    }
    assert!(
        r_off > 0.02,
        "unfiltered random-ish robots should touch: {r_off}"
    );
    assert!(r_on < 0.25 * r_off, "filtered {r_on} vs unfiltered {r_off}");
    assert!(
        TrainConfig::from_toml("orca_filter = true\n")
            .unwrap()
            .orca_filter
    );
}

/// PPO-Lagrangian: the multiplier rises while the contact rate is above the budget, stays
/// at 0 when the budget is loose, and survives save/resume; bad budgets are refused.
#[test]
fn lagrange_multiplier_follows_the_budget() {
    let mut tight = crowded(TrainConfig {
        collision_budget: Some(0.0),
        lagrange_lr: 1.0,
        ..TrainConfig::default()
    });
    let s1 = tight.step().unwrap();
    assert_eq!(s1.lambda, 0.0, "first rollout uses the initial multiplier");
    assert!(s1.contact_rate > 0.0);
    assert!(
        (tight.lambda as f64 - s1.contact_rate).abs() < 1e-6,
        "{}",
        tight.lambda
    );
    let s2 = tight.step().unwrap();
    assert!((tight.lambda - s2.lambda - s2.contact_rate as f32).abs() < 1e-6);
    assert!(tight.lambda > s2.lambda, "rises while above budget");
    let p = tmp("lagrange.safetensors");
    tight.save_state(&p).unwrap();
    assert_eq!(Trainer::resume(&p, None).unwrap().lambda, tight.lambda);

    let mut loose = crowded(TrainConfig {
        collision_budget: Some(10.0),
        ..TrainConfig::default()
    });
    loose.step().unwrap();
    assert_eq!(loose.lambda, 0.0);
    for bad in [
        "collision_budget = -0.1\n",
        "lagrange_lr = -1.0\n",
        "lagrange_init = nan\n",
    ] {
        let e = TrainConfig::from_toml(bad).unwrap_err();
        assert!(e.contains(bad.split(' ').next().unwrap()), "{bad}: {e}");
    }
}
