//! `tending sim`: episodes with a scripted policy, a metrics table, an optional animation.

use crate::report::{self, Numbers};
use crate::stats::markdown_table;
use anyhow::{bail, Context, Result};
use clap::Args;
use rand::SeedableRng;
use rayon::prelude::*;
use sim::baselines::{greedy_action, random_action, GreedyOrcaFleet, GreedyParams};
use sim::{episode_seed, Env, Metrics, ScenarioConfig, Setup};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct SimArgs {
    /// Setup N.M_K (robots.machines_storages), e.g. 14.10_4.
    #[arg(long, default_value = "6.4_2")]
    pub setup: String,
    /// greedy | greedy-orca | random
    #[arg(long, default_value = "greedy")]
    pub policy: String,
    #[arg(long, default_value_t = 20)]
    pub episodes: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Scenario config (TOML); defaults are documented in sim/src/config.rs.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Draw the first episode: .gif (animation) or .svg (final frame) or a directory of
    /// PNG frames (ends with /).
    #[arg(long)]
    pub render: Option<PathBuf>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Scripted {
    Greedy,
    /// Greedy allocation + ORCA avoidance, continuous velocity commands.
    GreedyOrca,
    Random,
}

impl std::str::FromStr for Scripted {
    type Err = anyhow::Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "greedy" => Ok(Self::Greedy),
            "greedy-orca" => Ok(Self::GreedyOrca),
            "random" => Ok(Self::Random),
            other => bail!("unknown --policy `{other}`: expected greedy, greedy-orca or random"),
        }
    }
}

pub fn load_config(path: &Option<PathBuf>) -> Result<ScenarioConfig> {
    Ok(match path {
        Some(p) => ScenarioConfig::load(p)?,
        None => ScenarioConfig::default(),
    })
}

/// Run one episode with a scripted policy; `on_step` sees the env after every step.
pub fn run_episode(
    cfg: &ScenarioConfig,
    setup: Setup,
    policy: Scripted,
    seed: u64,
    mut on_step: impl FnMut(&Env),
) -> Result<Metrics> {
    let mut env = Env::new(cfg.clone(), setup, seed)?;
    let params = GreedyParams {
        sizes: *env.sizes(),
        k_speed: cfg.task.k_speed,
        dt: cfg.world.dt,
    };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0xA5A5);
    let mut obs = obs::ObsBatch::default();
    let mut actions = Vec::new();
    let mut orca = GreedyOrcaFleet::new(&env)?;
    let mut vels = Vec::new();
    on_step(&env);
    while !env.is_done() {
        actions.clear();
        match policy {
            Scripted::Random => {
                actions.extend((0..env.n_robots()).map(|_| random_action(&mut rng)));
            }
            Scripted::Greedy => {
                env.observe(&mut obs);
                actions.extend((0..obs.rows).map(|r| {
                    greedy_action(
                        obs.own_row(r),
                        obs.machines_row(r),
                        obs.storages_row(r),
                        obs.peers_row(r),
                        &params,
                    )
                }));
            }
            Scripted::GreedyOrca => {
                env.observe(&mut obs);
                orca.act(&obs, &mut vels)?;
                env.step_velocities(&vels)?;
                on_step(&env);
                continue;
            }
        }
        env.step_actions(&actions)?;
        on_step(&env);
    }
    Ok(*env.metrics())
}

/// The table row of one policy on one setup: mean (std) over episodes.
pub fn metrics_row(label: &str, setup: Setup, ms: &[Metrics]) -> Vec<String> {
    let eps: Vec<Numbers> = ms.iter().map(|m| Numbers::of(m, setup.robots)).collect();
    let mut row = vec![label.to_string(), setup.to_string(), ms.len().to_string()];
    row.extend(report::cells(&eps));
    row
}

pub fn run(a: SimArgs) -> Result<()> {
    let cfg = load_config(&a.config)?;
    let setup: Setup = a.setup.parse()?;
    let policy: Scripted = a.policy.parse()?;
    if a.episodes == 0 {
        bail!("--episodes must be at least 1");
    }
    // Fail fast on a setup that cannot fit, before spawning work.
    Env::new(cfg.clone(), setup, a.seed).with_context(|| format!("setup {setup}"))?;
    if let Some(path) = &a.render {
        let mut frames = Vec::new();
        run_episode(&cfg, setup, policy, episode_seed(a.seed, 0, 0), |env| {
            frames.push(crate::render::Frame::capture(env))
        })?;
        crate::render::write(path, &cfg, &frames)?;
        eprintln!("rendered {} frames to {}", frames.len(), path.display());
    }
    let t0 = std::time::Instant::now();
    let ms: Vec<Metrics> = (0..a.episodes)
        .into_par_iter()
        .map(|ep| {
            run_episode(
                &cfg,
                setup,
                policy,
                episode_seed(a.seed, 0, ep as u64),
                |_| {},
            )
        })
        .collect::<Result<_>>()?;
    let mut header = vec!["policy", "setup", "episodes"];
    header.extend(report::COLUMNS);
    let table = markdown_table(&header, &[metrics_row(&a.policy, setup, &ms)]);
    println!("{table}");
    eprintln!(
        "{} episodes in {:.2} s (seed {}, k_speed {} m/s, {} steps)",
        a.episodes,
        t0.elapsed().as_secs_f64(),
        a.seed,
        cfg.task.k_speed,
        cfg.world.episode_steps
    );
    Ok(())
}
