//! `tending bench-sim`: simulator throughput in agent-steps per second.
//!
//! One agent-step = one robot's share of an environment step *including* every robot's
//! observation and reward, as VMAS's `env.step` returns them. Random actions are drawn
//! before timing so the policy costs nothing.

use anyhow::Result;
use clap::Args;
use rand::{Rng, SeedableRng};
use sim::{Env, ScenarioConfig, Setup, VecEnv};
use std::path::PathBuf;
use std::time::{Duration, Instant};

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Seconds of stepping per measurement.
    #[arg(long, default_value_t = 2.0)]
    pub seconds: f64,
    /// Markdown report to write.
    #[arg(long, default_value = "docs/bench/sim.md")]
    pub out: PathBuf,
}

fn actions_pool(n: usize) -> Vec<Vec<u8>> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    (0..64)
        .map(|_| (0..n).map(|_| rng.gen_range(0..5u8)).collect())
        .collect()
}

/// agent-steps/s for `n_envs` envs of `setup` (observations included).
fn measure_vec(setup: Setup, n_envs: usize, secs: f64) -> Result<f64> {
    let mut v = VecEnv::new(ScenarioConfig::default(), setup, n_envs, 1)?;
    let n = v.robots_per_env() * n_envs;
    let pool = actions_pool(n);
    let mut obs = obs::ObsBatch::default();
    // warm-up
    for a in pool.iter().take(5) {
        v.step_actions_observe(a, &mut obs)?;
    }
    let t0 = Instant::now();
    let mut steps = 0usize;
    while t0.elapsed() < Duration::from_secs_f64(secs) {
        for _ in 0..10 {
            v.step_actions_observe(&pool[steps % pool.len()], &mut obs)?;
            steps += 1;
        }
    }
    Ok((steps * n) as f64 / t0.elapsed().as_secs_f64())
}

/// (ns per agent-step for the step alone, for observation alone) in one env of `setup`.
fn measure_split(setup: Setup, secs: f64) -> Result<(f64, f64)> {
    let mut env = Env::new(ScenarioConfig::default(), setup, 1)?;
    let n = env.n_robots();
    let pool = actions_pool(n);
    let mut obs = obs::ObsBatch::default();
    let (mut t_step, mut t_obs, mut steps) = (Duration::ZERO, Duration::ZERO, 0usize);
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs_f64(secs) {
        if env.is_done() {
            env.reset(steps as u64)?;
        }
        let a = Instant::now();
        env.step_actions(&pool[steps % pool.len()])?;
        let b = Instant::now();
        env.observe(&mut obs);
        t_obs += b.elapsed();
        t_step += b - a;
        steps += 1;
    }
    let per = (steps * n) as f64;
    Ok((
        t_step.as_nanos() as f64 / per,
        t_obs.as_nanos() as f64 / per,
    ))
}

pub fn run(a: BenchArgs) -> Result<()> {
    // batched steps run on sim::fork's threads (the caller and micropool's), not rayon's
    let threads = sim::fork::threads();
    let mut md = String::new();
    md += "# Simulator throughput (`tending bench-sim`)\n\n";
    md += &format!(
        "Machine: {} threads for batched steps (sim::fork), {} cores. Batched: `VecEnv::step_actions_observe`. Random actions; every step includes all robots' observations and rewards. {:.1} s per cell.\n\n",
        threads,
        std::thread::available_parallelism().map(|n| n.get()).unwrap_or(0),
        a.seconds
    );
    md += "| setup | envs | agent-steps/s |\n|---|---|---|\n";
    for setup in ["6.4_2", "14.10_4", "100.16_2"] {
        for n_envs in [1usize, 32] {
            let s: Setup = setup.parse()?;
            let r = measure_vec(s, n_envs, a.seconds)?;
            eprintln!("{setup:>9} x {n_envs:>2} envs: {:>12.0} agent-steps/s", r);
            md += &format!("| {setup} | {n_envs} | {:.0} |\n", r);
        }
    }
    md += "\n## Cost per agent-step as N grows (one env, 16 machines, 2 storages, one thread)\n\n";
    md += "Physics and rewards use a uniform-grid broad phase; the observation is all-to-all by the paper's design (every robot sees every other robot), so its cost per agent grows with N.\n\n";
    md += "| N | step ns/agent | observation ns/agent | total ns/agent |\n|---|---|---|---|\n";
    for n in [10usize, 30, 100, 300, 1000] {
        let s = Setup::new(n, 16, 2);
        let (st, ob) = measure_split(s, a.seconds.min(2.0))?;
        eprintln!("N={n:>5}: step {st:>8.1} ns/agent, obs {ob:>8.1} ns/agent");
        md += &format!("| {n} | {st:.1} | {ob:.1} | {:.1} |\n", st + ob);
    }
    if let Some(p) = a.out.parent() {
        std::fs::create_dir_all(p)?;
    }
    std::fs::write(&a.out, &md)?;
    println!("{md}");
    eprintln!("wrote {}", a.out.display());
    Ok(())
}
