//! Trainer behaviour, by subject; the small-run fixtures (tiny configs, short episodes)
//! they share are here.

mod actions;
mod basics;
mod randomized;
mod safety;

use super::trainer::estimate_train_bytes;
use super::*;
use crate::config::ModelKind;
use rand::{Rng, SeedableRng};
use sim::{Env, ScenarioConfig, Setup};

fn tmp(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("policy-train-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

fn small(kind: ModelKind) -> Trainer {
    let mut sc = ScenarioConfig::default();
    sc.world.episode_steps = 40;
    let cfg = TrainConfig {
        n_envs: 2,
        ppo_epoch: 2,
        num_mini_batch: 2,
        ..TrainConfig::default()
    };
    let sched = parse_curriculum("2.2_2:4,3.2_2:4").unwrap();
    Trainer::new(kind, cfg, sc, sched, 7).unwrap()
}

fn crowded(cfg: TrainConfig) -> Trainer {
    let mut sc = ScenarioConfig::default();
    sc.world.episode_steps = 40;
    let cfg = TrainConfig {
        n_envs: 2,
        ppo_epoch: 2,
        num_mini_batch: 2,
        ..cfg
    };
    Trainer::new(
        ModelKind::Smappo,
        cfg,
        sc,
        parse_curriculum("16.4_2:40").unwrap(),
        3,
    )
    .unwrap()
}
