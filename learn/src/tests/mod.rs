//! Trainer behaviour, by subject; the small-run fixtures (tiny configs, short episodes)
//! they share are here.

mod actions;
mod basics;
mod randomized;
mod safety;

use super::trainer::estimate_train_bytes;
use super::*;
use policy::config::ModelKind;
use rand::{Rng, SeedableRng};
use sim::{Env, ScenarioConfig, Setup};

fn tmp(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("policy-train-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

/// 40-step episodes: every fixture's scenario.
fn short_episodes() -> ScenarioConfig {
    let mut sc = ScenarioConfig::default();
    sc.world.episode_steps = 40;
    sc
}

/// `cfg` with 2 envs, 2 epochs, 2 mini-batches: every fixture's run size.
fn tiny(cfg: TrainConfig) -> TrainConfig {
    TrainConfig {
        n_envs: 2,
        ppo_epoch: 2,
        num_mini_batch: 2,
        ..cfg
    }
}

fn small(kind: ModelKind) -> Trainer {
    let sched = parse_curriculum("2.2_2:4,3.2_2:4").unwrap();
    Trainer::new(
        kind,
        tiny(TrainConfig::default()),
        short_episodes(),
        sched,
        7,
    )
    .unwrap()
}

fn crowded(cfg: TrainConfig) -> Trainer {
    let sched = parse_curriculum("16.4_2:40").unwrap();
    Trainer::new(ModelKind::Smappo, tiny(cfg), short_episodes(), sched, 3).unwrap()
}

/// A resumed trainer `c` holds the weights, optimiser moments and value normaliser of `a`,
/// the run it must continue bit for bit.
fn assert_same_learner(c: &Trainer, a: &Trainer, kind: ModelKind) {
    assert_eq!(c.actor.params.data, a.actor.params.data, "{kind} actor");
    assert_eq!(c.critic.params.data, a.critic.params.data, "{kind} critic");
    assert_eq!(c.actor.opt.m, a.actor.opt.m);
    assert_eq!(c.critic.opt.v, a.critic.opt.v);
    assert_eq!(c.vnorm, a.vnorm);
}
