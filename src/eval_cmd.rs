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
    /// Scripted method instead of a checkpoint: greedy | greedy-orca | matching-orca |
    /// random (matching-ORCA behind the ORCA filter, with the --filter-* margins).
    #[arg(long)]
    pub policy: Option<String>,
    #[command(flatten)]
    pub runs: Runs,
    /// Sample actions from the policy instead of taking the most probable one.
    #[arg(long)]
    pub sample: bool,
    /// Put the checkpoint's actions behind the one-step action shield (plan::shield):
    /// actions whose next position would touch an observed body are masked.
    #[arg(long, requires = "checkpoint")]
    pub shield: bool,
    /// Pass the checkpoint's actions, as velocities, through ORCA as a safety filter
    /// (plan::orca): continuous velocity commands.
    #[arg(long, requires = "checkpoint", conflicts_with = "shield")]
    pub orca_filter: bool,
    /// Run a checkpoint trained behind the ORCA filter without it (by default such a
    /// checkpoint is evaluated behind the filter, as it was trained and as robot_node
    /// runs it).
    #[arg(long, requires = "checkpoint", conflicts_with = "orca_filter")]
    pub no_orca_filter: bool,
    /// Peer clearance of the ORCA filter at full speed, m; at rest the smaller of this and
    /// --filter-rest-clearance (docs/adr/0019); for a checkpoint behind the filter and for
    /// matching-orca. greedy-orca keeps its own fixed 0.025 (--script-clearance).
    #[arg(long, default_value_t = plan::orca::FILTER_CLEARANCE)]
    pub filter_clearance: f32,
    /// Peer clearance of the ORCA filter at rest, m (at most --filter-clearance). With
    /// --filter-clearance, a point of the safety margin's sweep (docs/RESULTS.md 7.7).
    #[arg(long, default_value_t = plan::orca::FILTER_REST_CLEARANCE)]
    pub filter_rest_clearance: f32,
    /// The ORCA filter's horizon for boxes and walls, s (docs/adr/0030).
    #[arg(long, default_value_t = plan::orca::FILTER_OBSTACLE_HORIZON)]
    pub filter_obstacle_horizon: f32,
    /// greedy-ORCA's own peer clearance, m (with --policy greedy-orca).
    #[arg(long, default_value_t = plan::orca::GREEDY_ORCA_CLEARANCE)]
    pub script_clearance: f32,
    /// greedy-ORCA's horizon for boxes and walls, s (with --policy greedy-orca).
    #[arg(long, default_value_t = plan::orca::OBSTACLE_HORIZON)]
    pub script_obstacle_horizon: f32,
    /// Scenario config (TOML); default: the simulator's defaults.
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Write results.md and results.csv into this directory.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Which episodes are evaluated: `tending eval` runs them, `tending bound` bounds them
/// (the same layouts for the same flags).
#[derive(Args, Debug)]
pub struct Runs {
    /// Comma-separated setups N.M_K.
    #[arg(long, default_value = "6.4_2")]
    pub setups: String,
    /// Episodes per seed.
    #[arg(long, default_value_t = 50)]
    pub episodes: u64,
    /// Comma-separated evaluation seeds.
    #[arg(long, default_value = "0,1,2")]
    pub seeds: String,
}

impl Runs {
    /// The setups and seeds, refused by name when malformed or empty.
    pub fn parse(&self) -> Result<(Vec<Setup>, Vec<u64>)> {
        let setups: Vec<Setup> = self
            .setups
            .split(',')
            .map(|s| s.trim().parse::<Setup>())
            .collect::<Result<_, _>>()?;
        let seeds: Vec<u64> = self
            .seeds
            .split(',')
            .map(|s| s.trim().parse::<u64>().context("--seeds"))
            .collect::<Result<_>>()?;
        if self.episodes == 0 || seeds.is_empty() {
            bail!("need at least one episode and one seed");
        }
        Ok((setups, seeds))
    }
}

/// greedy-ORCA's name with margins other than its defaults: "greedy-orca 30 mm" (a point
/// of the clearance sweep, which `tending plot pareto --sweep` joins by the "mm" ending),
/// "greedy-orca obstacles 0.15 s", or both.
fn script_label(clearance: f32, obstacle_horizon: f32) -> String {
    let mut s = String::from("greedy-orca");
    if obstacle_horizon != plan::orca::OBSTACLE_HORIZON {
        s += &format!(" obstacles {obstacle_horizon} s");
    }
    if clearance != plan::orca::GREEDY_ORCA_CLEARANCE {
        s += &format!(" {} mm", crate::controller::mm(clearance));
    }
    s
}

pub fn run(a: EvalArgs) -> Result<()> {
    for (name, v) in [
        ("--filter-clearance", a.filter_clearance),
        ("--filter-rest-clearance", a.filter_rest_clearance),
        ("--script-clearance", a.script_clearance),
    ] {
        if !(v.is_finite() && v > 0.0) {
            bail!("{name} {v}: must be a positive number of metres");
        }
    }
    for (name, v) in [
        ("--filter-obstacle-horizon", a.filter_obstacle_horizon),
        ("--script-obstacle-horizon", a.script_obstacle_horizon),
    ] {
        if !(v.is_finite() && v > 0.0) {
            bail!("{name} {v}: must be a positive number of seconds");
        }
    }
    let script_default = a.script_clearance == plan::orca::GREEDY_ORCA_CLEARANCE
        && a.script_obstacle_horizon == plan::orca::OBSTACLE_HORIZON;
    if !script_default && a.policy.as_deref() != Some("greedy-orca") {
        bail!(
            "--script-clearance and --script-obstacle-horizon are greedy-ORCA's: pass them \
             with --policy greedy-orca"
        );
    }
    let margins = plan::FilterMargins {
        clearance: a.filter_clearance,
        rest_clearance: a.filter_rest_clearance,
        obstacle_horizon: a.filter_obstacle_horizon,
    };
    let (ctrl, label) = match (&a.checkpoint, a.policy.as_deref()) {
        (Some(p), None) => {
            let flags = CheckpointFlags {
                sample: a.sample,
                shield: a.shield,
                orca_filter: (a.orca_filter || a.no_orca_filter).then_some(a.orca_filter),
                margins,
            };
            crate::controller::checkpoint(p, &flags)?
        }
        (None, Some("greedy-orca")) if !script_default => (
            Controller::GreedyOrca {
                clearance: a.script_clearance,
                obstacle_horizon: a.script_obstacle_horizon,
            },
            script_label(a.script_clearance, a.script_obstacle_horizon),
        ),
        (None, Some(name)) => crate::controller::scripted(name, margins)?,
        (None, None) => bail!(
            "pass --checkpoint <file> or --policy {}",
            crate::controller::SCRIPTS
        ),
        (Some(_), Some(_)) => bail!("--checkpoint and --policy are exclusive"),
    };
    let mode = crate::controller::mode(&ctrl);
    let cfg = crate::sim_cmd::load_config(&a.scenario)?;
    let (setups, seeds) = a.runs.parse()?;
    let episodes = a.runs.episodes;

    let mut rows = vec![];
    let mut csv_rows = vec![];
    for &setup in &setups {
        let mut per_seed = vec![];
        for &seed in &seeds {
            let ms = evaluate(&ctrl, &cfg, setup, seed, episodes)
                .with_context(|| format!("evaluate {setup} seed {seed}"))?;
            let eps: Vec<Numbers> = ms.iter().map(|m| Numbers::of(m, setup.robots)).collect();
            let r = Numbers::mean(&eps);
            csv_rows.push(EvalResultRecord::new(
                &label,
                &setup.to_string(),
                seed,
                episodes,
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
        episodes,
        a.runs.seeds,
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

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        a: EvalArgs,
    }

    fn args(extra: &[&str]) -> EvalArgs {
        let base = [
            "eval",
            "--setups",
            "2.2_2",
            "--episodes",
            "1",
            "--seeds",
            "0",
        ];
        Cli::try_parse_from(base.iter().chain(extra)).unwrap().a
    }

    /// A swept clearance is part of the method's name in the results, and a clearance a
    /// controller does not use, or that is not a distance, is refused by name.
    #[test]
    fn clearances_are_named_in_results_and_checked() {
        let dir = std::env::temp_dir().join(format!("tending-eval-{}", std::process::id()));
        let out = dir.to_str().unwrap();
        run(args(&[
            "--policy",
            "greedy-orca",
            "--script-clearance",
            "0.03",
            "--out",
            out,
        ]))
        .unwrap();
        let csv = std::fs::read_to_string(dir.join("results.csv")).unwrap();
        assert!(csv
            .lines()
            .nth(1)
            .unwrap()
            .starts_with("greedy-orca 30 mm,2.2_2,0,1,"));
        let bundled = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/policy/pretrained/smappo_6.4_2.safetensors"
        );
        let e = run(args(&[
            "--checkpoint",
            bundled,
            "--script-clearance",
            "0.03",
        ]));
        assert!(e.unwrap_err().to_string().contains("--script-clearance"));
        let e = run(args(&[
            "--checkpoint",
            bundled,
            "--filter-rest-clearance=-0.01",
        ]));
        assert!(e
            .unwrap_err()
            .to_string()
            .contains("--filter-rest-clearance"));
        run(args(&[
            "--checkpoint",
            bundled,
            "--filter-rest-clearance",
            "0.025",
            "--out",
            out,
        ]))
        .unwrap();
        let csv = std::fs::read_to_string(dir.join("results.csv")).unwrap();
        assert!(csv.contains("smappo targets+orca 25/40 mm (smappo_6.4_2.safetensors)"));
        std::fs::remove_dir_all(&dir).ok();
    }

    /// An obstacle horizon other than a controller's default is part of its name
    /// (docs/adr/0030), and one that is not a positive time, or is greedy-ORCA's without
    /// greedy-ORCA, is refused by name.
    #[test]
    fn obstacle_horizons_are_named_in_results_and_checked() {
        let dir = std::env::temp_dir().join(format!("tending-eval-obst-{}", std::process::id()));
        let out = dir.to_str().unwrap();
        let first_row = || {
            let csv = std::fs::read_to_string(dir.join("results.csv")).unwrap();
            csv.lines().nth(1).unwrap().to_string()
        };
        let script = ["--policy", "greedy-orca", "--out", out];
        run(args(
            &[&script[..], &["--script-obstacle-horizon", "0.15"]].concat(),
        ))
        .unwrap();
        assert!(first_row().starts_with("greedy-orca obstacles 0.15 s,2.2_2,"));
        let both = [
            "--script-obstacle-horizon",
            "0.15",
            "--script-clearance",
            "0.03",
        ];
        run(args(&[&script[..], &both[..]].concat())).unwrap();
        assert!(first_row().starts_with("greedy-orca obstacles 0.15 s 30 mm,2.2_2,"));
        let bundled = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/policy/pretrained/smappo_6.4_2.safetensors"
        );
        let ck = ["--checkpoint", bundled, "--out", out];
        run(args(
            &[&ck[..], &["--filter-obstacle-horizon", "0.3"]].concat(),
        ))
        .unwrap();
        assert!(first_row().starts_with("smappo targets+orca obstacles 0.3 s (smappo_6.4_2"));
        // the default horizon leaves the name as it was
        run(args(&ck)).unwrap();
        assert!(first_row().starts_with("smappo targets+orca (smappo_6.4_2"));
        for bad in [
            "--filter-obstacle-horizon=0",
            "--filter-obstacle-horizon=NaN",
            "--script-obstacle-horizon=-0.1",
        ] {
            let e = run(args(&["--checkpoint", bundled, bad])).unwrap_err();
            let name = bad.split('=').next().unwrap();
            assert!(e.to_string().contains(name), "{bad}: {e}");
        }
        let e = run(args(&[
            "--checkpoint",
            bundled,
            "--script-obstacle-horizon",
            "0.15",
        ]));
        assert!(e
            .unwrap_err()
            .to_string()
            .contains("--script-obstacle-horizon"));
        std::fs::remove_dir_all(&dir).ok();
    }

    /// matching-ORCA is a scripted method: named "matching-orca", behind the ORCA filter
    /// whose margins, when not the deployed ones, are part of its name as a checkpoint's.
    #[test]
    fn matching_orca_is_a_script_named_with_its_margins() {
        let dir = std::env::temp_dir().join(format!("tending-eval-mo-{}", std::process::id()));
        let out = dir.to_str().unwrap();
        let first_row = || {
            let csv = std::fs::read_to_string(dir.join("results.csv")).unwrap();
            csv.lines().nth(1).unwrap().to_string()
        };
        let script = ["--policy", "matching-orca", "--out", out];
        run(args(&script)).unwrap();
        assert!(first_row().starts_with("matching-orca,2.2_2,0,1,"));
        let swept = [
            "--filter-obstacle-horizon",
            "0.3",
            "--filter-clearance",
            "0.035",
        ];
        run(args(&[&script[..], &swept[..]].concat())).unwrap();
        assert!(first_row().starts_with("matching-orca obstacles 0.3 s 30/35 mm,2.2_2,"));
        let e = run(args(&[
            "--policy",
            "matching-orca",
            "--script-clearance",
            "0.03",
        ]));
        assert!(e.unwrap_err().to_string().contains("--script-clearance"));
        let e = run(args(&["--policy", "matched"])).unwrap_err().to_string();
        assert!(e.contains("matching-orca"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
