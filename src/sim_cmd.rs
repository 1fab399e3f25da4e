//! `tending sim`: episodes of a scripted baseline or a checkpoint, a metrics table, an
//! optional animation of the first episode. Episodes run through `tending eval`'s episode
//! runner ([`learn::run_episode_watched`]), so for the same setup, seed and
//! controller both commands report the same numbers.

use crate::method::CheckpointFlags;
use anyhow::{bail, Context, Result};
use clap::Args;
use learn::{evaluate, run_episode_watched, Method};
use plots::episode::Frame;
use records::stats::markdown_table;
use records::{report, Numbers};
use sim::{Env, Metrics, ScenarioConfig, Setup};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct SimArgs {
    /// Setup N.M_K (robots.machines_storages), e.g. 14.10_4.
    #[arg(long, default_value = "6.4_2")]
    pub setup: String,
    /// Scripted method: greedy | greedy-orca | matching-orca | random.
    #[arg(long, default_value = "greedy", conflicts_with = "checkpoint")]
    pub policy: String,
    /// A policy checkpoint (.safetensors) instead of a scripted baseline, run as
    /// `tending eval` runs it: argmax actions, behind the ORCA filter when it was trained
    /// behind it.
    #[arg(long)]
    pub checkpoint: Option<PathBuf>,
    /// Sample the checkpoint's actions instead of taking the most probable one.
    #[arg(long, requires = "checkpoint")]
    pub sample: bool,
    /// Put the checkpoint's actions behind the one-step action shield (plan::shield).
    #[arg(long, requires = "checkpoint")]
    pub shield: bool,
    /// Pass the checkpoint's actions through ORCA as a safety filter (plan::orca).
    #[arg(long, requires = "checkpoint", conflicts_with = "shield")]
    pub orca_filter: bool,
    #[arg(long, default_value_t = 20)]
    pub episodes: u64,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[command(flatten)]
    pub scenario: sim::args::ScenarioArgs,
    /// Safety margins (TOML, plan::margins, e.g. configs/margins/*.toml); default: the
    /// deployed ones.
    #[arg(long)]
    pub margins: Option<PathBuf>,
    /// Draw the first episode: .gif (animation) or .svg (final frame) or a directory of
    /// PNG frames (ends with /).
    #[arg(long)]
    pub render: Option<PathBuf>,
}

/// The controller the arguments name, and its label for the table.
fn controller(a: &SimArgs) -> Result<(Method, String)> {
    let margins = crate::method::margins(&a.margins)?;
    let Some(path) = &a.checkpoint else {
        return crate::method::scripted(&a.policy, &margins);
    };
    let flags = CheckpointFlags {
        sample: a.sample,
        shield: a.shield,
        orca_filter: a.orca_filter.then_some(true),
        margins: margins.filter,
    };
    crate::method::checkpoint(path, &flags)
}

/// The table row of one policy on one setup: mean (std) over episodes.
pub fn metrics_row(label: &str, setup: Setup, ms: &[Metrics]) -> Vec<String> {
    let eps: Vec<Numbers> = ms.iter().map(|m| Numbers::of(m, setup.robots)).collect();
    let mut row = vec![label.to_string(), setup.to_string(), ms.len().to_string()];
    row.extend(report::cells(&eps));
    row
}

/// The episodes `a` asks for (the first one drawn with `--render`), and the label.
fn episodes(a: &SimArgs, cfg: &ScenarioConfig) -> Result<(String, Vec<Metrics>)> {
    let setup: Setup = a.setup.parse()?;
    if a.episodes == 0 {
        bail!("--episodes must be at least 1");
    }
    // Fail fast on a setup that cannot fit, before spawning work.
    Env::new(cfg.clone(), setup, a.seed).with_context(|| format!("setup {setup}"))?;
    let (ctrl, label) = controller(a)?;
    if let Some(path) = &a.render {
        let mut frames = Vec::new();
        run_episode_watched(&ctrl, cfg, setup, a.seed, 0, |env| {
            frames.push(Frame::capture(env))
        })?;
        plots::episode::write(path, cfg, &frames)?;
        eprintln!("rendered {} frames to {}", frames.len(), path.display());
    }
    let ms = evaluate(&ctrl, cfg, setup, a.seed, a.episodes)
        .with_context(|| format!("{label} on {setup}"))?;
    Ok((label, ms))
}

pub fn run(a: SimArgs) -> Result<()> {
    let cfg = a.scenario.load()?;
    let t0 = std::time::Instant::now();
    let (label, ms) = episodes(&a, &cfg)?;
    let setup: Setup = a.setup.parse()?;
    let mut header = vec!["policy", "setup", "episodes"];
    header.extend(report::COLUMNS);
    println!(
        "{}",
        markdown_table(&header, &[metrics_row(&label, setup, &ms)])
    );
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

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        a: SimArgs,
    }

    fn args(extra: &[&str]) -> SimArgs {
        Cli::try_parse_from(["sim"].iter().chain(extra)).unwrap().a
    }

    /// `tending sim` and `tending eval` report the same metrics for the same setup, seed
    /// and controller (scripted or learned), and the rendered episode is episode 0.
    #[test]
    fn sim_and_eval_agree_and_render_the_first_episode() {
        let mut cfg = ScenarioConfig::default();
        cfg.world.episode_steps = 60;
        let setup: Setup = "4.2_2".parse().unwrap();
        let pretrained = concat!(env!("CARGO_MANIFEST_DIR"), "/policy/pretrained/");
        let moves = format!("{pretrained}smappo_moves_6.4_2.safetensors");
        let bundled = format!("{pretrained}smappo_6.4_2.safetensors");
        let actor = |p: &str| Box::new(policy::Policy::load(p).unwrap().actor().clone());
        let dir = std::env::temp_dir().join(format!("tending-sim-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let gif = dir.join("ep.gif");
        for (flags, ctrl) in [
            (vec!["--policy", "random"], Method::Random),
            (vec!["--policy", "greedy"], Method::Greedy),
            (vec!["--policy", "greedy-orca"], Method::greedy_orca()),
            (vec!["--policy", "matching-orca"], Method::matching_orca()),
            (
                vec!["--checkpoint", &moves],
                Method::learned(actor(&moves), false),
            ),
            // trained behind the ORCA filter: run behind it, as eval and robot_node do
            (
                vec!["--checkpoint", &bundled],
                Method::filtered(actor(&bundled), false),
            ),
        ] {
            let mut v = vec!["--setup", "4.2_2", "--seed", "7", "--episodes", "3"];
            v.extend(flags);
            let (_, sim) = episodes(&args(&v), &cfg).unwrap();
            let eval = evaluate(&ctrl, &cfg, setup, 7, 3).unwrap();
            assert_eq!(sim, eval, "{v:?}");
            let mut frames = 0;
            let first = run_episode_watched(&ctrl, &cfg, setup, 7, 0, |_| frames += 1).unwrap();
            assert_eq!(first, eval[0], "{v:?}");
            assert_eq!(frames, 61, "the start and every step");
        }
        let a = args(&[
            "--checkpoint",
            &bundled,
            "--render",
            gif.to_str().unwrap(),
            "--episodes",
            "1",
        ]);
        episodes(&a, &cfg).unwrap();
        assert!(std::fs::metadata(&gif).unwrap().len() > 1000);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn bad_arguments_are_clear_errors() {
        let cfg = ScenarioConfig::default();
        let e = episodes(&args(&["--policy", "greedy-lol"]), &cfg).unwrap_err();
        assert!(
            e.to_string()
                .contains("--policy: unknown controller `greedy-lol`"),
            "{e}"
        );
        let e = episodes(&args(&["--checkpoint", "/nonexistent.safetensors"]), &cfg).unwrap_err();
        assert!(
            format!("{e:#}").contains("/nonexistent.safetensors"),
            "{e:#}"
        );
        assert!(Cli::try_parse_from(["sim", "--sample"]).is_err());
        assert!(Cli::try_parse_from(["sim", "--policy", "random", "--checkpoint", "x"]).is_err());
    }
}
