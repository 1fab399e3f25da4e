//! `tending train`: PPO training of SMAPPO or MAPPO with progress, CSV log, curve and
//! checkpoints; Ctrl-C (or SIGTERM) finishes the current update, saves and exits, and
//! `--resume` continues bit-exactly.

use crate::plot::{plot_training, CurvePoint};
use anyhow::{bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use policy::train::{parse_curriculum, Stage, TrainConfig, Trainer, UpdateStats};
use policy::ModelKind;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct TrainArgs {
    /// smappo | mappo
    #[arg(long, default_value = "smappo")]
    pub model: String,
    /// Setup N.M_K to train on (ignored with --curriculum). Default 6.4_2.
    #[arg(long)]
    pub setup: Option<String>,
    /// Episodes to train (ignored with --curriculum). Default 2000.
    #[arg(long)]
    pub episodes: Option<u64>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Run directory: log.csv, curve.png, policy.safetensors, trainer_state.safetensors.
    #[arg(long)]
    pub out: PathBuf,
    /// Training hyper-parameters (TOML, see policy/src/train/config.rs).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Scenario config (TOML); default: the simulator's defaults.
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Continue the run in --out from its trainer state (config, seed, schedule restored;
    /// --setup/--episodes/--curriculum, when given, replace the schedule).
    #[arg(long)]
    pub resume: bool,
    /// setup:episodes list, e.g. 6.4_2:2000,12.8_4:100,18.12_6:100
    #[arg(long)]
    pub curriculum: Option<String>,
    /// Stop after this many updates in this invocation (for tests and benchmarks).
    #[arg(long)]
    pub max_updates: Option<u64>,
    /// No progress bar (log lines to stderr every update instead).
    #[arg(long)]
    pub quiet: bool,
}

const LOG_HEADER: &str = "update,episodes,agent_steps,stage,setup,team_reward,parts_delivered,\
collisions,mu,policy_loss,value_loss,entropy,approx_kl,clip_frac,actor_grad_norm,\
critic_grad_norm,rollout_secs,train_secs,wall_secs,agent_steps_per_sec";

fn schedule_from_args(a: &TrainArgs) -> Result<Option<Vec<Stage>>> {
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

/// Lines of an existing log up to (and including) `update`; the wall time reached.
fn read_log(path: &Path, update: u64) -> Result<(Vec<String>, f64)> {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let mut keep = vec![];
    let mut wall = 0.0;
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let Some(u) = f.first().and_then(|u| u.parse::<u64>().ok()) else {
            continue;
        };
        if u <= update {
            wall = f.get(18).and_then(|w| w.parse().ok()).unwrap_or(wall);
            keep.push(line.to_string());
        }
    }
    Ok((keep, wall))
}

/// Curve points and stage-change episodes from log lines.
pub fn curve_from_log(lines: &[String]) -> (Vec<CurvePoint>, Vec<f64>) {
    let mut pts = vec![];
    let mut stages = vec![];
    let mut last_stage: Option<String> = None;
    for l in lines {
        let f: Vec<&str> = l.split(',').collect();
        if f.len() < 9 {
            continue;
        }
        let num = |i: usize| f[i].parse::<f64>().unwrap_or(f64::NAN);
        let (eps, stage) = (num(1), f[3].to_string());
        if let Some(s) = &last_stage {
            if *s != stage {
                // the stage began one update before this point's episode count
                stages.push(pts.last().map(|p: &CurvePoint| p.episodes).unwrap_or(0.0));
            }
        }
        last_stage = Some(stage);
        pts.push(CurvePoint {
            episodes: eps,
            reward: num(5),
            mu: num(8),
        });
    }
    (pts, stages)
}

fn log_line(s: &UpdateStats, wall: f64, sps: f64) -> String {
    format!(
        "{},{},{},{},{},{:.4},{:.4},{:.4},{:.5},{:.6},{:.6},{:.6},{:.6},{:.5},{:.5},{:.5},{:.4},{:.4},{:.3},{:.1}",
        s.update,
        s.episodes,
        s.agent_steps,
        s.stage,
        s.setup,
        s.team_reward,
        s.parts_delivered,
        s.collisions,
        s.mu,
        s.policy_loss,
        s.value_loss,
        s.entropy,
        s.approx_kl,
        s.clip_frac,
        s.actor_grad_norm,
        s.critic_grad_norm,
        s.rollout_secs,
        s.train_secs,
        wall,
        sps
    )
}

fn write_atomic(path: &Path, text: &str) -> Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, text)?;
    std::fs::rename(&tmp, path)?;
    Ok(())
}

fn save_all(t: &Trainer, out: &Path, lines: &[String]) -> Result<()> {
    t.save_policy(&out.join("policy.safetensors"))?;
    t.save_state(&out.join("trainer_state.safetensors"))?;
    let (pts, stages) = curve_from_log(lines);
    plot_training(&pts, &stages, &out.join("curve.png"))?;
    Ok(())
}

pub fn run(a: TrainArgs) -> Result<()> {
    std::fs::create_dir_all(&a.out).with_context(|| format!("create {}", a.out.display()))?;
    let state_path = a.out.join("trainer_state.safetensors");
    let log_path = a.out.join("log.csv");
    let schedule = schedule_from_args(&a)?;
    let mut t = if a.resume {
        if !state_path.exists() {
            bail!("--resume: no {} to resume from", state_path.display());
        }
        let mut t = Trainer::resume(&state_path, None).context("resume")?;
        match (&a.curriculum, &a.setup, a.episodes) {
            (Some(_), _, _) | (None, Some(_), _) => {
                t.set_schedule(schedule.expect("given"))?;
            }
            (None, None, Some(total)) => {
                // --episodes alone: a new total, the last stage absorbs the difference
                let mut s = t.schedule.clone();
                let before: u64 = s[..s.len() - 1].iter().map(|x| x.episodes).sum();
                if total <= before {
                    bail!("--episodes {total} ends before the last curriculum stage");
                }
                s.last_mut().expect("non-empty").episodes = total - before;
                t.set_schedule(s)?;
            }
            (None, None, None) => {}
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
            Some(p) => TrainConfig::from_toml(&std::fs::read_to_string(p)?)
                .map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?,
            None => TrainConfig::default(),
        };
        let scenario = crate::sim_cmd::load_config(&a.scenario)?;
        let schedule = schedule.unwrap_or(parse_curriculum("6.4_2:2000")?);
        Trainer::new(kind, cfg, scenario, schedule, a.seed)?
    };
    let (mut lines, mut wall) = if a.resume {
        read_log(&log_path, t.update)?
    } else {
        (vec![], 0.0)
    };

    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        let first = AtomicBool::new(true);
        ctrlc::set_handler(move || {
            if first.swap(false, Ordering::SeqCst) {
                eprintln!("\nstopping after the current update (Ctrl-C again to abort)...");
                stop.store(true, Ordering::SeqCst);
            } else {
                std::process::exit(130);
            }
        })
        .context("install Ctrl-C handler")?;
    }

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
        policy::train::format_curriculum(&t.schedule),
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
        lines.push(log_line(&s, wall, sps));
        let mut body = String::from(LOG_HEADER);
        body.push('\n');
        for l in &lines {
            body += l;
            body.push('\n');
        }
        write_atomic(&log_path, &body)?;
        let msg = format!(
            "{} R {:.1} parts {:.1} coll {:.1} MU {:.2} | {:.0} agent-steps/s",
            s.setup, s.team_reward, s.parts_delivered, s.collisions, s.mu, sps
        );
        pb.set_position(t.episodes.min(total));
        pb.set_message(msg.clone());
        if a.quiet {
            eprintln!("update {} ep {} {}", s.update, s.episodes, msg);
        }
        done_here += 1;
        since_save += 1;
        if since_save >= t.cfg.save_every {
            save_all(&t, &a.out, &lines)?;
            since_save = 0;
        }
    }
    save_all(&t, &a.out, &lines)?;
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
