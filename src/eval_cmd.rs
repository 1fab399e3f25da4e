//! `tending eval`: a checkpoint (or a scripted baseline) over setups and seeds, reported
//! as the paper does: per seed the mean over its episodes, then mean (std) over seeds.

use crate::controller::CheckpointFlags;
use crate::records::{self, EvalResultRecord};
use crate::report::{self, Numbers};
use crate::stats::markdown_table;
use anyhow::{bail, Context, Result};
use clap::Args;
use policy::train::{evaluate, Controller};
use sim::Setup;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct EvalArgs {
    /// Policy checkpoint (.safetensors) to evaluate.
    #[arg(long, conflicts_with = "policy")]
    pub checkpoint: Option<PathBuf>,
    /// Scripted baseline instead of a checkpoint: greedy | greedy-orca | random.
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
    /// Put the checkpoint's actions behind the one-step action shield (obs::shield):
    /// actions whose next position would touch an observed body are masked.
    #[arg(long, requires = "checkpoint")]
    pub shield: bool,
    /// Pass the checkpoint's actions, as velocities, through ORCA as a safety filter
    /// (obs::orca): continuous velocity commands.
    #[arg(long, requires = "checkpoint", conflicts_with = "shield")]
    pub orca_filter: bool,
    /// Run a checkpoint trained behind the ORCA filter without it (by default such a
    /// checkpoint is evaluated behind the filter, as it was trained and as robot_node
    /// runs it).
    #[arg(long, requires = "checkpoint", conflicts_with = "orca_filter")]
    pub no_orca_filter: bool,
    /// Peer clearance of the ORCA filter at full speed, m; at rest the smaller of this and
    /// 0.035 (docs/adr/0017). greedy-orca keeps its own fixed 0.025.
    #[arg(long, default_value_t = obs::orca::FILTER_CLEARANCE)]
    pub filter_clearance: f32,
    /// Scenario config (TOML); default: the simulator's defaults.
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Write results.md and results.csv into this directory.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

pub fn run(a: EvalArgs) -> Result<()> {
    let (ctrl, label) = match (&a.checkpoint, a.policy.as_deref()) {
        (Some(p), None) => {
            let flags = CheckpointFlags {
                sample: a.sample,
                shield: a.shield,
                orca_filter: a.orca_filter,
                no_orca_filter: a.no_orca_filter,
                clearance: a.filter_clearance,
            };
            crate::controller::checkpoint(p, &flags)?
        }
        (None, Some(name)) => (crate::controller::scripted(name)?, name.to_string()),
        (None, None) => bail!("pass --checkpoint <file> or --policy greedy|greedy-orca|random"),
        (Some(_), Some(_)) => bail!("--checkpoint and --policy are exclusive"),
    };
    let mode = match (&ctrl, a.sample) {
        (Controller::Learned { .. }, true) => "sampled actions",
        (Controller::Learned { .. }, false) => "argmax actions",
        (Controller::Shielded { .. }, true) => "sampled shielded actions",
        (Controller::Shielded { .. }, false) => "argmax shielded actions",
        (Controller::Filtered { .. }, true) => "sampled actions through the ORCA filter",
        (Controller::Filtered { .. }, false) => "argmax actions through the ORCA filter",
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
    let mut csv_rows = vec![];
    for &setup in &setups {
        let mut per_seed = vec![];
        for &seed in &seeds {
            let ms = evaluate(&ctrl, &cfg, setup, seed, a.episodes)
                .with_context(|| format!("evaluate {setup} seed {seed}"))?;
            let eps: Vec<Numbers> = ms.iter().map(|m| Numbers::of(m, setup.robots)).collect();
            let r = Numbers::mean(&eps);
            csv_rows.push(EvalResultRecord::new(
                &label,
                &setup.to_string(),
                seed,
                a.episodes,
                &r,
            ));
            per_seed.push(r);
        }
        let mut row = vec![setup.to_string()];
        row.extend(report::cells(&per_seed));
        println!(
            "{:<10} parts {:<14} contacts {:<14} robot-robot {:<14} per robot-step {:<18} MU {}",
            row[0], row[1], row[2], row[3], row[7], row[9]
        );
        rows.push(row);
    }
    let mut header = vec!["Setup"];
    header.extend(report::COLUMNS);
    let md = format!(
        "# tending eval: {label}\n\n{mode}; {} episodes per seed, seeds {}; each seed's value \
         is the mean over its episodes, shown as mean (std) over seeds. Contacts are counted \
         per robot per step by kind (a robot-robot contact counts for both robots).\n\n{}",
        a.episodes,
        a.seeds,
        markdown_table(&header, &rows)
    );
    println!("\n{md}");
    if let Some(out) = &a.out {
        std::fs::create_dir_all(out)?;
        std::fs::write(out.join("results.md"), &md)?;
        std::fs::write(out.join("results.csv"), records::to_text(&csv_rows)?)?;
        eprintln!("wrote {}/results.md and results.csv", out.display());
    }
    Ok(())
}
