//! `tending eval`: a checkpoint (or a scripted baseline) over setups and seeds, reported
//! as the paper does: per seed the mean over its episodes, then mean (std) over seeds.

use crate::stats::{fmt_ms, markdown_table};
use anyhow::{bail, Context, Result};
use clap::Args;
use policy::train::{evaluate, Controller};
use policy::Policy;
use sim::{Metrics, Setup};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct EvalArgs {
    /// Policy checkpoint (.safetensors) to evaluate.
    #[arg(long, conflicts_with = "policy")]
    pub checkpoint: Option<PathBuf>,
    /// Scripted baseline instead of a checkpoint: greedy | random.
    #[arg(long)]
    pub policy: Option<String>,
    /// Comma-separated setups N.M_K.
    #[arg(long, default_value = "6.4_2")]
    pub setups: String,
    /// Episodes per seed.
    #[arg(long, default_value_t = 50)]
    pub episodes: u64,
    /// Comma-separated evaluation seeds.
    #[arg(long, default_value = "0,1,2")]
    pub seeds: String,
    /// Sample actions from the policy instead of taking the most probable one.
    #[arg(long)]
    pub sample: bool,
    /// Scenario config (TOML); default: the simulator's defaults.
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Write results.md and results.csv into this directory.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Per-seed means of one setup.
struct SeedResult {
    seed: u64,
    parts: f64,
    collisions: f64,
    mu: f64,
    reward: f64,
}

fn mean(ms: &[Metrics], f: impl Fn(&Metrics) -> f64) -> f64 {
    ms.iter().map(f).sum::<f64>() / ms.len().max(1) as f64
}

pub fn run(a: EvalArgs) -> Result<()> {
    let (ctrl, label) = match (&a.checkpoint, a.policy.as_deref()) {
        (Some(p), None) => {
            let pol = Policy::load(p).with_context(|| format!("load {}", p.display()))?;
            let label = format!(
                "{} ({})",
                pol.kind(),
                p.file_name()
                    .and_then(|f| f.to_str())
                    .unwrap_or("checkpoint")
            );
            (
                Controller::Learned {
                    actor: Box::new(pol.actor().clone()),
                    sample: a.sample,
                },
                label,
            )
        }
        (None, Some("greedy")) => (Controller::Greedy, "greedy".to_string()),
        (None, Some("random")) => (Controller::Random, "random".to_string()),
        (None, Some(o)) => bail!("unknown --policy `{o}`: expected greedy or random"),
        (None, None) => bail!("pass --checkpoint <file> or --policy greedy|random"),
        (Some(_), Some(_)) => bail!("--checkpoint and --policy are exclusive"),
    };
    let mode = match (&ctrl, a.sample) {
        (Controller::Learned { .. }, true) => "sampled actions",
        (Controller::Learned { .. }, false) => "argmax actions",
        _ => "scripted",
    };
    let cfg = crate::sim_cmd::load_config(&a.scenario)?;
    let setups: Vec<Setup> = a
        .setups
        .split(',')
        .map(|s| s.trim().parse::<Setup>())
        .collect::<Result<_, _>>()?;
    let seeds: Vec<u64> = a
        .seeds
        .split(',')
        .map(|s| s.trim().parse::<u64>().context("--seeds"))
        .collect::<Result<_>>()?;
    if a.episodes == 0 || seeds.is_empty() {
        bail!("need at least one episode and one seed");
    }

    let mut rows = vec![];
    let mut csv =
        String::from("policy,setup,seed,episodes,parts_delivered,collisions,mu,team_reward\n");
    for &setup in &setups {
        let mut per_seed = vec![];
        for &seed in &seeds {
            let ms = evaluate(&ctrl, &cfg, setup, seed, a.episodes)
                .with_context(|| format!("evaluate {setup} seed {seed}"))?;
            let r = SeedResult {
                seed,
                parts: mean(&ms, |m| m.parts_delivered as f64),
                collisions: mean(&ms, |m| m.collisions as f64),
                mu: mean(&ms, |m| m.utilization()),
                reward: mean(&ms, |m| m.total_reward),
            };
            csv += &format!(
                "{label},{setup},{},{},{:.4},{:.4},{:.5},{:.4}\n",
                r.seed, a.episodes, r.parts, r.collisions, r.mu, r.reward
            );
            per_seed.push(r);
        }
        let col = |f: &dyn Fn(&SeedResult) -> f64| per_seed.iter().map(f).collect::<Vec<_>>();
        let row = vec![
            setup.to_string(),
            fmt_ms(&col(&|r| r.parts), 1),
            fmt_ms(&col(&|r| r.collisions), 1),
            fmt_ms(&col(&|r| r.mu), 2),
            fmt_ms(&col(&|r| r.reward), 1),
        ];
        println!(
            "{:<10} parts {:<14} collisions {:<14} MU {:<12} reward {}",
            row[0], row[1], row[2], row[3], row[4]
        );
        rows.push(row);
    }
    let header = [
        "Setup",
        "Parts delivered",
        "Collisions",
        "MU",
        "Team reward",
    ];
    let md = format!(
        "# tending eval: {label}\n\n{mode}; {} episodes per seed, seeds {}; each seed's value \
         is the mean over its episodes, shown as mean (std) over seeds.\n\n{}",
        a.episodes,
        a.seeds,
        markdown_table(&header, &rows)
    );
    println!("\n{md}");
    if let Some(out) = &a.out {
        std::fs::create_dir_all(out)?;
        std::fs::write(out.join("results.md"), &md)?;
        std::fs::write(out.join("results.csv"), &csv)?;
        eprintln!("wrote {}/results.md and results.csv", out.display());
    }
    Ok(())
}
