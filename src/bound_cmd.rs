//! `tending bound`: the most parts any controller could deliver on the layouts that
//! `tending eval` runs (same setups, seeds and episodes), from `sim::parts_bound`. Issue
//! 10's targets compare with it: where 1.1x the best script is above the bound, no policy
//! can meet that target.

use anyhow::{Context, Result};
use clap::Args;
use learn::eval::eval_env_seed;
use records::PartsBoundRecord;
use sim::{parts_bound, Env};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct BoundArgs {
    #[command(flatten)]
    pub runs: crate::eval_cmd::Runs,
    #[command(flatten)]
    pub scenario: sim::args::ScenarioArgs,
    /// Write the per-seed means as CSV here.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

pub fn run(a: BoundArgs) -> Result<()> {
    let cfg = a.scenario.load()?;
    let (setups, seeds) = a.runs.parse()?;
    let episodes = a.runs.episodes;
    let per_machine = cfg.world.episode_steps.div_ceil(cfg.task.prep_steps.max(1));
    let mut rows = vec![];
    println!("setup      bound (mean over seeds; machines / robots)   P_max");
    for &setup in &setups {
        let p_max = (setup.machines as u32 * per_machine) as f64;
        let mut all = [0.0f64; 3];
        for &seed in &seeds {
            let mut sum = [0u64; 3];
            for ep in 0..episodes {
                let env = Env::new(cfg.clone(), setup, eval_env_seed(seed, ep))
                    .with_context(|| format!("{setup} seed {seed} episode {ep}"))?;
                let b = parts_bound(&env).expect("a fresh episode");
                sum[0] += b.value() as u64;
                sum[1] += b.machines as u64;
                sum[2] += b.robots as u64;
            }
            let mean = sum.map(|s| s as f64 / episodes as f64);
            rows.push(PartsBoundRecord {
                setup: setup.to_string(),
                seed,
                episodes,
                parts_bound: mean[0],
                machine_bound: mean[1],
                robot_bound: mean[2],
                p_max,
            });
            for k in 0..3 {
                all[k] += mean[k] / seeds.len() as f64;
            }
        }
        println!(
            "{:<10} {:<7.1} ({:.1} / {:.1}){:>27.0}",
            setup.to_string(),
            all[0],
            all[1],
            all[2],
            p_max
        );
    }
    if let Some(out) = &a.out {
        std::fs::write(out, records::to_text(&rows)?)
            .with_context(|| format!("write {}", out.display()))?;
        eprintln!("wrote {}", out.display());
    }
    Ok(())
}
