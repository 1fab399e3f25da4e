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
    /// Seconds per measurement.
    #[arg(long, default_value_t = 1.0)]
    pub seconds: f64,
    /// Rounds of (1 env, 32 envs) measured in turn per setup; ratios are medians of each
    /// round's ratio (this shared VM's speed drifts by 1.5x within minutes, so a ratio of
    /// two measurements taken far apart says little).
    #[arg(long, default_value_t = 5)]
    pub rounds: usize,
    /// Generated Markdown (its own file: the analysis in docs/bench/sim.md is written by
    /// hand and links here).
    #[arg(long, default_value = "docs/bench/sim_throughput.md")]
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

fn median(mut x: Vec<f64>) -> f64 {
    x.sort_by(f64::total_cmp);
    x[x.len() / 2]
}

pub fn run(a: BenchArgs) -> Result<()> {
    // batched steps run on sim::fork's threads (the caller and micropool's), not rayon's
    let threads = sim::fork::threads();
    let mut md = String::new();
    md += "# Simulator throughput (`tending bench-sim`)\n\n";
    md += &format!(
        "Machine: {} threads for batched steps (sim::fork), {} cores. Batched: `VecEnv::step_actions_observe`. Random actions; every step includes all robots' observations and rewards. {:.1} s per measurement.\n\n",
        threads,
        std::thread::available_parallelism().map(|n| n.get()).unwrap_or(0),
        a.seconds
    );
    md += &format!(
        "{} rounds per setup, each measuring 1 env then 32 envs; medians over rounds, and the median of the rounds' ratios.\n\n",
        a.rounds.max(1)
    );
    md += "| setup | 1 env (agent-steps/s) | 32 envs (agent-steps/s) | 32 / 1 per round | 32 / 1 (median) |\n|---|---|---|---|---|\n";
    for setup in ["6.4_2", "14.10_4", "100.16_2"] {
        let s: Setup = setup.parse()?;
        let (mut one, mut many, mut ratio) = (vec![], vec![], vec![]);
        for _ in 0..a.rounds.max(1) {
            let (r1, r32) = (
                measure_vec(s, 1, a.seconds)?,
                measure_vec(s, 32, a.seconds)?,
            );
            eprintln!(
                "{setup:>9}: 1 env {r1:>12.0} | 32 envs {r32:>12.0} agent-steps/s | {:.2}x",
                r32 / r1
            );
            one.push(r1);
            many.push(r32);
            ratio.push(r32 / r1);
        }
        let rounds: Vec<String> = ratio.iter().map(|r| format!("{r:.2}")).collect();
        md += &format!(
            "| {setup} | {:.0} | {:.0} | {} | **{:.2}x** |\n",
            median(one),
            median(many),
            rounds.join(" "),
            median(ratio)
        );
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
