//! `tending eval`: a checkpoint (or a scripted baseline) over setups and seeds, reported
//! as the paper does: per seed the mean over its episodes, then mean (std) over seeds.

use crate::method::CheckpointFlags;
use anyhow::{bail, Context, Result};
use clap::Args;
use learn::evaluate;
use records::stats::markdown_table;
use records::{report, EvalResultRecord, Numbers};
use sim::Setup;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct EvalArgs {
    /// Policy checkpoint (.safetensors) to evaluate.
    #[arg(long, conflicts_with = "policy")]
    pub checkpoint: Option<PathBuf>,
    /// Scripted method instead of a checkpoint: greedy | greedy-orca | matching-orca |
    /// random (matching-ORCA behind the ORCA filter, with the --margins file's).
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
    /// Safety margins (TOML, plan::margins): the ORCA filter's, for a checkpoint behind
    /// it and for matching-orca, and greedy-ORCA's own; e.g. configs/margins/*.toml.
    /// Default: configs/margins/deployed.toml's, what robot_node deploys. Margins other
    /// than those are named in the results' labels.
    #[arg(long)]
    pub margins: Option<PathBuf>,
    #[command(flatten)]
    pub scenario: sim::args::ScenarioArgs,
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

pub fn run(a: EvalArgs) -> Result<()> {
    let margins = crate::method::margins(&a.margins)?;
    let (ctrl, label) = match (&a.checkpoint, a.policy.as_deref()) {
        (Some(p), None) => {
            let flags = CheckpointFlags {
                sample: a.sample,
                shield: a.shield,
                orca_filter: (a.orca_filter || a.no_orca_filter).then_some(a.orca_filter),
                margins: margins.filter,
            };
            crate::method::checkpoint(p, &flags)?
        }
        (None, Some(name)) => crate::method::scripted(name, &margins)?,
        (None, None) => bail!(
            "pass --checkpoint <file> or --policy {}",
            crate::method::SCRIPTS
        ),
        (Some(_), Some(_)) => bail!("--checkpoint and --policy are exclusive"),
    };
    let mode = crate::method::mode(&ctrl);
    let cfg = a.scenario.load()?;
    // A floor or observation other than the paper's is part of the method's name, so rows
    // of a sweep stay apart in records and plots (the paper's rows keep their labels).
    let scope = scope_label(&cfg);
    let label = if scope.is_empty() {
        label
    } else {
        format!("{label} [{scope}]")
    };
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

/// "grown floor, nearest 8/8/8" for what differs from the paper's floor and observation;
/// empty for the paper's.
pub fn scope_label(cfg: &sim::ScenarioConfig) -> String {
    let mut parts = vec![];
    if cfg.world.floor == sim::Floor::Grown {
        parts.push("grown floor".to_string());
    }
    if cfg.observation.is_bounded() {
        parts.push(cfg.observation.label());
    }
    parts.join(", ")
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

    /// A margins file in a fresh directory; its path.
    fn margins_file(dir: &std::path::Path, name: &str, text: &str) -> String {
        std::fs::create_dir_all(dir).unwrap();
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p.to_str().unwrap().to_string()
    }

    const BUNDLED: &str = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/policy/pretrained/smappo_6.4_2.safetensors"
    );

    /// Margins other than the deployed ones are part of a method's name in the results
    /// (sweeps join rows by it), for greedy-ORCA, a checkpoint behind the filter and
    /// matching-ORCA; the deployed ones leave the name as it was.
    #[test]
    fn margins_from_a_file_are_named_in_results() {
        let dir = std::env::temp_dir().join(format!("tending-eval-m-{}", std::process::id()));
        let out = dir.join("out");
        let out = out.to_str().unwrap();
        let first_row = || {
            let csv = std::fs::read_to_string(dir.join("out/results.csv")).unwrap();
            csv.lines().nth(1).unwrap().to_string()
        };
        let cases = [
            (
                "--policy greedy-orca",
                "[greedy_orca]\nclearance = 0.03\n",
                "greedy-orca 30 mm,2.2_2,0,1,",
            ),
            (
                "--policy greedy-orca",
                "[greedy_orca]\nobstacle_horizon = 0.15\nclearance = 0.03\n",
                "greedy-orca obstacles 0.15 s 30 mm,2.2_2,",
            ),
            (
                "--policy matching-orca",
                "[filter]\nobstacle_horizon = 0.3\nclearance = 0.035\n",
                "matching-orca obstacles 0.3 s 30/35 mm,2.2_2,",
            ),
            (
                "--checkpoint BUNDLED",
                "[filter]\nrest_clearance = 0.025\n",
                "smappo targets+orca 25/40 mm (smappo_6.4_2.safetensors)",
            ),
            (
                "--checkpoint BUNDLED",
                "[filter]\nobstacle_horizon = 0.3\n",
                "smappo targets+orca obstacles 0.3 s (smappo_6.4_2",
            ),
            // greedy-ORCA's margins do not rename a checkpoint, nor the filter's greedy-ORCA
            (
                "--checkpoint BUNDLED",
                "[greedy_orca]\nclearance = 0.03\n",
                "smappo targets+orca (smappo_6.4_2",
            ),
            (
                "--policy greedy-orca",
                "[filter]\nclearance = 0.05\n",
                "greedy-orca,2.2_2,",
            ),
        ];
        for (method, toml, label) in cases {
            let m = margins_file(&dir, "m.toml", toml);
            let method = method.replace("BUNDLED", BUNDLED);
            let mut a: Vec<&str> = method.split(' ').collect();
            a.extend(["--margins", &m, "--out", out]);
            run(args(&a)).unwrap();
            assert!(
                first_row().starts_with(label),
                "{method} {toml}: {}",
                first_row()
            );
        }
        let deployed = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/margins/deployed.toml");
        run(args(&[
            "--checkpoint",
            BUNDLED,
            "--margins",
            deployed,
            "--out",
            out,
        ]))
        .unwrap();
        assert!(first_row().starts_with("smappo targets+orca (smappo_6.4_2"));
        run(args(&["--policy", "matching-orca", "--out", out])).unwrap();
        assert!(first_row().starts_with("matching-orca,2.2_2,0,1,"));
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A bad margins file is refused naming the flag, the file and the key.
    #[test]
    fn bad_margins_are_refused_by_name() {
        let dir = std::env::temp_dir().join(format!("tending-eval-bad-{}", std::process::id()));
        for (toml, key) in [
            (
                "[filter]\nobstacle_horizon = 0.0\n",
                "filter.obstacle_horizon",
            ),
            (
                "[filter]\nrest_clearance = -0.01\n",
                "filter.rest_clearance",
            ),
            ("[greedy_orca]\nclearance = nan\n", "greedy_orca.clearance"),
            ("[filter]\nhorizon = 0.2\n", "horizon"),
        ] {
            let m = margins_file(&dir, "bad.toml", toml);
            let e = run(args(&["--checkpoint", BUNDLED, "--margins", &m]))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("--margins") && e.contains("bad.toml") && e.contains(key),
                "{toml}: {e}"
            );
        }
        let e = run(args(&[
            "--policy",
            "greedy",
            "--margins",
            "/nonexistent/m.toml",
        ]))
        .unwrap_err()
        .to_string();
        assert!(e.contains("/nonexistent/m.toml"), "{e}");
        let e = run(args(&["--policy", "matched"])).unwrap_err().to_string();
        assert!(e.contains("matching-orca"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
