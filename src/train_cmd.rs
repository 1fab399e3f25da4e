//! `tending train`: PPO training of SMAPPO or MAPPO with progress, CSV log, curve and
//! checkpoints; Ctrl-C (or SIGTERM) finishes the current update, saves and exits, and
//! `--resume` continues bit-exactly.
//!
//! `--randomize 2..12.2..8_1..4` trains on setups drawn from inclusive ranges of robots,
//! machines and storages instead of fixed setups: one draw per update (all envs of a
//! rollout share it), seeded by (seed, update) so resume stays exact; log.csv's `setup`
//! column holds each update's draw.

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use learn::{parse_curriculum, SetupRange, Stage, TrainConfig, Trainer};
use plots::training::{plot_training, CurvePoint};
use policy::ModelKind;
use records::TrainLogRecord;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::OnceLock;
use std::time::Instant;

#[derive(Args, Debug)]
// `--config` is the training config here: the scenario's `--config` alias (sim::args) goes.
#[command(mut_arg("scenario", |a| a.alias(None)))]
pub struct TrainArgs {
    /// smappo | mappo
    #[arg(long, default_value = "smappo")]
    pub model: String,
    /// Setup N.M_K to train on (ignored with --curriculum). Default 6.4_2.
    #[arg(long, conflicts_with = "randomize")]
    pub setup: Option<String>,
    /// Episodes to train (ignored with --curriculum). Default 2000.
    #[arg(long)]
    pub episodes: Option<u64>,
    /// Randomized setups instead of fixed ones: N.M_K with each count a or a..b
    /// (inclusive; a-b works too), e.g. 2..12.2..8_1..4 = 2-12 robots, 2-8 machines,
    /// 1-4 storage areas. Each count is drawn uniformly and independently ONCE PER UPDATE
    /// (all envs of a rollout share the draw), from a generator seeded by (--seed, update
    /// index), so runs are reproducible and --resume exact; log.csv's `setup` column is
    /// the draw. Refused before training when the range's largest setup does not fit the
    /// room or (MAPPO) exceeds the mappo_max_* padding. With --episodes (default 2000);
    /// with --resume, switches or extends the run.
    #[arg(long, conflicts_with = "curriculum", value_name = "RANGE")]
    pub randomize: Option<String>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Run directory: log.csv, curve.png, policy.safetensors, trainer_state.safetensors.
    #[arg(long)]
    pub out: PathBuf,
    /// Training hyper-parameters (TOML, see policy/src/train/config.rs).
    #[arg(long)]
    pub config: Option<PathBuf>,
    #[command(flatten)]
    pub scenario: sim::args::ScenarioArgs,
    /// Continue the run in --out from its trainer state (config, seed, schedule restored;
    /// --setup/--episodes/--curriculum/--randomize, when given, replace the schedule).
    #[arg(long)]
    pub resume: bool,
    /// setup:episodes list, e.g. 6.4_2:2000,12.8_4:100,18.12_6:100
    #[arg(long)]
    pub curriculum: Option<String>,
    /// Stop after this many updates in this invocation (for tests and benchmarks).
    #[arg(long)]
    pub max_updates: Option<u64>,
    /// Start the actor from this policy checkpoint (same architecture) instead of fresh
    /// weights, e.g. to fine-tune the bundled policy behind the ORCA filter; pair with
    /// `critic_warmup_updates` in --config. The critic starts fresh.
    #[arg(long, conflicts_with = "resume", value_name = "CHECKPOINT")]
    pub init_actor: Option<PathBuf>,
    /// No progress bar (log lines to stderr every update instead).
    #[arg(long)]
    pub quiet: bool,
}

/// `--randomize`: the range, and the episode budget when given.
fn range_from_args(a: &TrainArgs) -> Result<Option<(SetupRange, Option<u64>)>> {
    let Some(r) = &a.randomize else {
        return Ok(None);
    };
    let range: SetupRange = r.parse().map_err(|e| anyhow!("--randomize: {e}"))?;
    if a.episodes == Some(0) {
        bail!("--episodes 0: nothing to train");
    }
    Ok(Some((range, a.episodes)))
}

fn schedule_from_args(a: &TrainArgs) -> Result<Option<Vec<Stage>>> {
    if a.randomize.is_some() {
        return Ok(None);
    }
    if let Some(c) = &a.curriculum {
        return Ok(Some(parse_curriculum(c)?));
    }
    if a.setup.is_none() && a.episodes.is_none() {
        return Ok(None);
    }
    let setup = a.setup.clone().unwrap_or_else(|| "6.4_2".into());
    let episodes = a.episodes.unwrap_or(2000);
    Ok(Some(parse_curriculum(&format!("{setup}:{episodes}"))?))
}

/// The rows of an existing log up to (and including) `update`; the wall time reached.
/// No log yet is an empty one.
fn read_log(path: &Path, update: u64) -> Result<(Vec<TrainLogRecord>, f64)> {
    if !path.exists() {
        return Ok((vec![], 0.0));
    }
    let keep: Vec<TrainLogRecord> = records::read::<TrainLogRecord>(path)?
        .into_iter()
        .map(|l| l.record)
        .filter(|r| r.update <= update)
        .collect();
    let wall = keep.last().map_or(0.0, |r| r.wall_secs);
    Ok((keep, wall))
}

/// Curve points and stage-change episodes of a log.
pub fn curve_from_log(rows: &[TrainLogRecord]) -> (Vec<CurvePoint>, Vec<f64>) {
    let mut pts: Vec<CurvePoint> = vec![];
    let mut stages = vec![];
    for (i, r) in rows.iter().enumerate() {
        if i > 0 && r.stage != rows[i - 1].stage {
            // the stage began one update before this point's episode count
            stages.push(pts.last().map_or(0.0, |p| p.episodes));
        }
        pts.push(CurvePoint {
            episodes: r.episodes as f64,
            reward: r.team_reward,
            mu: r.mu,
        });
    }
    (pts, stages)
}

fn write_atomic(path: &Path, text: &str) -> Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, text)?;
    std::fs::rename(&tmp, path)?;
    Ok(())
}

fn save_all(t: &Trainer, out: &Path, log: &[TrainLogRecord]) -> Result<()> {
    t.save_policy(&out.join("policy.safetensors"))?;
    t.save_state(&out.join("trainer_state.safetensors"))?;
    let (pts, stages) = curve_from_log(log);
    plot_training(&pts, &stages, &out.join("curve.png"))?;
    Ok(())
}

/// Set by Ctrl-C / SIGTERM: finish the current update, save, exit. The handler is
/// installed once per process (a second `ctrlc::set_handler` fails), so `run` can be
/// called more than once (tests); each call clears the flag.
static STOP: AtomicBool = AtomicBool::new(false);

fn stop_flag() -> Result<&'static AtomicBool> {
    static INSTALLED: OnceLock<Result<(), String>> = OnceLock::new();
    INSTALLED
        .get_or_init(|| {
            let first = AtomicBool::new(true);
            ctrlc::set_handler(move || {
                if first.swap(false, Ordering::SeqCst) {
                    eprintln!("\nstopping after the current update (Ctrl-C again to abort)...");
                    STOP.store(true, Ordering::SeqCst);
                } else {
                    std::process::exit(130);
                }
            })
            .map_err(|e| e.to_string())
        })
        .clone()
        .map_err(|e| anyhow!("install Ctrl-C handler: {e}"))?;
    STOP.store(false, Ordering::SeqCst);
    Ok(&STOP)
}

pub fn run(a: TrainArgs) -> Result<()> {
    let range = range_from_args(&a)?;
    let schedule = schedule_from_args(&a)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("create {}", a.out.display()))?;
    let state_path = a.out.join("trainer_state.safetensors");
    let log_path = a.out.join("log.csv");
    let mut t = if a.resume {
        if !state_path.exists() {
            bail!("--resume: no {} to resume from", state_path.display());
        }
        let mut t = Trainer::resume(&state_path, None).context("resume")?;
        if let Some((r, eps)) = range {
            let total = eps.unwrap_or_else(|| t.total_episodes());
            t.set_randomize(r, total).context("--randomize")?;
        } else if let Some(s) = schedule.filter(|_| a.curriculum.is_some() || a.setup.is_some()) {
            t.set_schedule(s)?;
        } else if let Some(total) = a.episodes {
            // --episodes alone: a new total, the last stage absorbs the difference
            t.set_total_episodes(total).context("--episodes")?;
        }
        t
    } else {
        if state_path.exists() {
            bail!(
                "{} already holds a run: pass --resume to continue it or choose another --out",
                a.out.display()
            );
        }
        let kind = match a.model.as_str() {
            "smappo" => ModelKind::Smappo,
            "mappo" => ModelKind::Mappo,
            m => bail!("unknown --model `{m}`: expected smappo or mappo"),
        };
        let cfg = match &a.config {
            Some(p) => TrainConfig::load(p)?,
            None => TrainConfig::default(),
        };
        let scenario = a.scenario.load()?;
        let mut t = if let Some((r, eps)) = range {
            Trainer::new_randomized(kind, cfg, scenario, r, eps.unwrap_or(2000), a.seed)
                .context("--randomize")?
        } else {
            let schedule = schedule.unwrap_or(parse_curriculum("6.4_2:2000")?);
            Trainer::new(kind, cfg, scenario, schedule, a.seed)?
        };
        if let Some(p) = &a.init_actor {
            let pol = policy::Policy::load_expecting(p, kind)
                .with_context(|| format!("--init-actor {}", p.display()))?;
            t.init_actor(pol.actor())
                .with_context(|| format!("--init-actor {}", p.display()))?;
            t.init_actor_from = Some(p.display().to_string());
        }
        t
    };
    let (mut log, mut wall) = if a.resume {
        read_log(&log_path, t.update)?
    } else {
        (vec![], 0.0)
    };

    let stop = stop_flag()?;

    let total = t.total_episodes();
    let pb = if a.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(total)
    };
    pb.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} ep (eta {eta}) {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    pb.set_position(t.episodes.min(total));
    eprintln!(
        "training {} on {} (seed {}, {} envs, {} epochs), {} -> {}",
        t.kind,
        t.schedule_string(),
        t.seed,
        t.cfg.n_envs,
        t.cfg.ppo_epoch,
        t.episodes,
        total
    );
    let mut since_save = 0usize;
    let mut done_here = 0u64;
    while !t.finished() && !stop.load(Ordering::SeqCst) {
        if a.max_updates.is_some_and(|m| done_here >= m) {
            break;
        }
        let t0 = Instant::now();
        let steps_before = t.agent_steps;
        let s = t.step()?;
        let dt = t0.elapsed().as_secs_f64();
        wall += dt;
        let sps = (t.agent_steps - steps_before) as f64 / dt.max(1e-9);
        log.push(TrainLogRecord::new(&s, wall, sps));
        write_atomic(&log_path, &records::to_text(&log)?)?;
        let msg = format!(
            "{} R {:.1} parts {:.1} coll {:.1} MU {:.2} lambda {:.2} | {:.0} agent-steps/s",
            s.setup, s.team_reward, s.parts_delivered, s.collisions, s.mu, s.lambda, sps
        );
        pb.set_position(t.episodes.min(total));
        pb.set_message(msg.clone());
        if a.quiet {
            eprintln!("update {} ep {} {}", s.update, s.episodes, msg);
        }
        done_here += 1;
        since_save += 1;
        if since_save >= t.cfg.save_every {
            save_all(&t, &a.out, &log)?;
            since_save = 0;
        }
    }
    save_all(&t, &a.out, &log)?;
    pb.finish_and_clear();
    let _ = std::io::stderr().flush();
    eprintln!(
        "{} after {} updates, {} episodes, {:.0} s of training; checkpoints in {}",
        if t.finished() { "finished" } else { "stopped" },
        t.update,
        t.episodes,
        wall,
        a.out.display()
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
        a: TrainArgs,
    }

    fn args(extra: &[&str]) -> Result<TrainArgs, clap::Error> {
        Cli::try_parse_from(["train"].iter().chain(extra)).map(|c| c.a)
    }

    /// A run directory with a 40-step scenario and a 2-env, 1-epoch training config.
    fn run_dir(name: &str) -> (PathBuf, Vec<String>) {
        let d = std::env::temp_dir().join(format!("tending-train-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        let mut sc = sim::ScenarioConfig::default();
        sc.world.episode_steps = 40;
        std::fs::write(d.join("scenario.toml"), sc.to_toml()).unwrap();
        std::fs::write(d.join("train.toml"), "n_envs = 2\nppo_epoch = 1\n").unwrap();
        let common = vec![
            "--scenario".into(),
            d.join("scenario.toml").display().to_string(),
            "--config".into(),
            d.join("train.toml").display().to_string(),
            "--quiet".into(),
        ];
        (d, common)
    }

    fn train(out: &Path, common: &[String], extra: &[&str]) -> Result<()> {
        let mut v: Vec<&str> = vec!["--out", out.to_str().unwrap()];
        v.extend(common.iter().map(String::as_str));
        v.extend(extra);
        run(args(&v)?)
    }

    /// log.csv rows without the timing columns.
    fn log_rows(out: &Path) -> Vec<TrainLogRecord> {
        let (rows, _) = read_log(&out.join("log.csv"), u64::MAX).unwrap();
        rows.into_iter()
            .map(|r| TrainLogRecord {
                rollout_secs: 0.0,
                train_secs: 0.0,
                wall_secs: 0.0,
                agent_steps_per_sec: 0.0,
                ..r
            })
            .collect()
    }

    #[test]
    fn randomize_flag_conflicts_and_help() {
        assert!(args(&["--out", "x", "--randomize", "2..3.2_2", "--setup", "6.4_2"]).is_err());
        assert!(args(&[
            "--out",
            "x",
            "--randomize",
            "2..3.2_2",
            "--curriculum",
            "6.4_2:4"
        ])
        .is_err());
        let a = args(&["--out", "x", "--randomize", "2..3.2_2", "--episodes", "8"]).unwrap();
        assert_eq!(a.randomize.as_deref(), Some("2..3.2_2"));
        use clap::CommandFactory;
        let help = Cli::command().render_long_help().to_string();
        assert!(help.contains("--randomize <RANGE>"), "{help}");
        assert!(help.contains("ONCE PER UPDATE"), "{help}");
    }

    /// Bad ranges fail before anything is trained, naming the input.
    #[test]
    fn randomize_bad_input_is_a_clear_error() {
        let (d, common) = run_dir("bad");
        for (r, why) in [
            ("12..2.2_2", "robots range 12..2 is empty"),
            ("2..3.2", "count fields"),
            ("2..100000.2_2", "does not fit"),
        ] {
            let out = d.join("run");
            let e = train(&out, &common, &["--randomize", r]).unwrap_err();
            let e = format!("{e:#}");
            assert!(
                e.contains("--randomize") && e.contains(r) && e.contains(why),
                "{e}"
            );
            assert!(!out.join("trainer_state.safetensors").exists());
        }
        let e = train(
            &d.join("m"),
            &common,
            &["--model", "mappo", "--randomize", "2.2_1..20"],
        )
        .unwrap_err();
        assert!(format!("{e:#}").contains("mappo_max_storages"), "{e:#}");
        let _ = std::fs::remove_dir_all(&d);
    }

    /// End to end: `tending train --randomize` for 2 updates, then `--resume` for 1,
    /// gives the log of 3 updates straight (timings aside); every logged setup lies in
    /// the range; the checkpoints load.
    #[test]
    fn randomize_train_and_resume_end_to_end() {
        let (d, common) = run_dir("e2e");
        let range = "2..3.1..2_1..2";
        let r: SetupRange = range.parse().unwrap();
        let (x, y) = (d.join("straight"), d.join("resumed"));
        let base = ["--randomize", range, "--episodes", "8", "--seed", "5"];
        train(&x, &common, &[&base[..], &["--max-updates", "3"]].concat()).unwrap();
        train(&y, &common, &[&base[..], &["--max-updates", "2"]].concat()).unwrap();
        assert_eq!(log_rows(&y).len(), 2);
        train(&y, &common, &["--resume", "--max-updates", "1"]).unwrap();
        let (rx, ry) = (log_rows(&x), log_rows(&y));
        assert_eq!(rx.len(), 3);
        assert_eq!(rx, ry);
        for row in &rx {
            assert_eq!(row.stage, 0, "one stage");
            assert!(r.contains(row.setup.parse().unwrap()), "{}", row.setup);
        }
        let t = Trainer::resume(&y.join("trainer_state.safetensors"), None).unwrap();
        assert_eq!(t.schedule_string(), format!("{range}:8"));
        assert_eq!(t.update, 3);
        policy::Policy::load(y.join("policy.safetensors")).unwrap();
        // a second run into the same directory needs --resume
        let e = train(&x, &common, &base).unwrap_err();
        assert!(e.to_string().contains("--resume"), "{e}");
        let _ = std::fs::remove_dir_all(&d);
    }
}
