//! `tending fleet`: one `sim_bridge` and one `robot_node` process per robot, live metrics,
//! clean shutdown (SIGINT to every child, wait, then kill), non-zero exit if a child fails.
//!
//! While it runs, the fleet takes commands on stdin, one per line (docs/bench/live.md):
//! `add robot [NAME]` starts one more robot_node (the bridge spawns its body on its first
//! cmd_vel), `kill NAME` SIGKILLs a robot_node (the bridge drops the body when its cmd_vel
//! goes stale), `stop NAME` SIGINTs it, `add machine [X Y]`, `remove machine ID`,
//! `add storage [X Y]`, `remove storage ID` go to the bridge (its `/tending/command`
//! language, through its stdin), `status` prints the processes and the last metrics.
//! `--record DIR` makes the bridge record a rosbag2 MCAP bag of everything it publishes and
//! receives.
//!
//! A robot_node that exits with code 75 (`EX_TEMPFAIL`: its watchdog ended a start-up or
//! control loop hung in the RustDDS entity-creation deadlock, docs/bench/ros.md) is
//! restarted with the same arguments, at most [`MAX_RESTARTS`] times per robot; `status`
//! and the end of the run report the restarts. Any other early exit is a failure.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};

#[derive(clap::Args, Debug)]
pub struct FleetArgs {
    /// Setup N.M_K (N robot_node processes).
    #[arg(long, default_value = "6.4_2")]
    pub setup: String,
    /// Run time in seconds: wall time in realtime mode, sim time in lockstep mode.
    #[arg(long, default_value_t = 60.0)]
    pub duration: f64,
    /// Policy for every robot_node: a checkpoint path, `greedy` for the scripted controller,
    /// or (default) the bundled SMAPPO policy policy/pretrained/smappo_6.4_2.safetensors.
    #[arg(long)]
    pub policy: Option<PathBuf>,
    /// realtime (bridge steps at --rate-hz) or lockstep (reproducible, see docs/adr/0003-lockstep.md).
    #[arg(long, default_value = "realtime", value_parser = ["realtime", "lockstep"])]
    pub mode: String,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[arg(long, default_value_t = 10.0)]
    pub rate_hz: f64,
    /// ROS_DOMAIN_ID for the fleet (default: the environment's, else 0).
    #[arg(long)]
    pub domain: Option<u16>,
    /// Scenario TOML for the bridge (default: built-in).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Directory for the children's logs (default: a temporary directory).
    #[arg(long)]
    pub log_dir: Option<PathBuf>,
    /// Bag directory: sim_bridge records every topic it publishes and every cmd_vel it
    /// receives (rosbag2 MCAP, `-p record:=DIR`).
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Staleness timeout (s) of the bridge (a body whose cmd_vel is older is removed) and of
    /// every robot_node's inputs.
    #[arg(long, default_value_t = 2.0)]
    pub stale_timeout: f64,
    /// Extra `-p NAME:=VALUE` for every robot_node (repeatable; e.g. test_delay_ms:=50).
    #[arg(long = "robot-param")]
    pub robot_params: Vec<String>,
    /// Do not read commands from stdin.
    #[arg(long)]
    pub no_stdin: bool,
}

fn sibling(name: &str) -> Result<PathBuf> {
    let exe = std::env::current_exe().context("locating the tending executable")?;
    let p = exe
        .parent()
        .ok_or_else(|| anyhow!("executable has no directory"))?
        .join(name);
    if !p.exists() {
        bail!(
            "{} not found next to {} (build it: cargo build --release -p {})",
            p.display(),
            exe.display(),
            if name == "sim_bridge" {
                "sim-bridge"
            } else {
                "robot-node"
            }
        );
    }
    Ok(p)
}

/// robot_node's exit code when its watchdog ended it (robot_node::watchdog::EXIT_WATCHDOG).
const EXIT_WATCHDOG: i32 = 75;
/// Watchdog restarts allowed per robot.
const MAX_RESTARTS: u32 = 3;

/// Restart a robot_node that exited with `code` after `restarts` restarts already?
fn should_restart(code: Option<i32>, restarts: u32) -> bool {
    code == Some(EXIT_WATCHDOG) && restarts < MAX_RESTARTS
}

/// `robot_3 x1, robot_7 x2`, or `none`.
fn restarts_summary(r: &std::collections::BTreeMap<String, u32>) -> String {
    if r.is_empty() {
        return "none".into();
    }
    r.iter()
        .map(|(n, k)| format!("{n} x{k}"))
        .collect::<Vec<_>>()
        .join(", ")
}

struct Proc {
    name: String,
    child: Child,
}

/// A command typed while the fleet runs (see the module docs).
#[derive(Debug, PartialEq)]
enum LiveCmd {
    AddRobot(Option<String>),
    Kill(String),
    Stop(String),
    /// A line for the bridge's `/tending/command` language.
    Bridge(String),
    Status,
}

fn parse_live(line: &str) -> Result<LiveCmd, String> {
    let w: Vec<&str> = line.split_whitespace().collect();
    let num = |s: &str| -> Result<(), String> {
        s.parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .map(|_| ())
            .ok_or_else(|| format!("bad number `{s}`"))
    };
    let pos = |rest: &[&str]| -> Result<String, String> {
        match rest {
            [] => Ok(String::new()),
            [x, y] => {
                num(x)?;
                num(y)?;
                Ok(format!(" {x} {y}"))
            }
            _ => Err("expected no position or `X Y`".into()),
        }
    };
    let robot_name = |n: &str| -> Result<String, String> {
        let n = n.trim_start_matches('/');
        if !n.is_empty()
            && !n.as_bytes()[0].is_ascii_digit()
            && n.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_')
            && !n.starts_with("machine_")
            && !n.starts_with("storage_")
        {
            Ok(n.to_string())
        } else {
            Err(format!("bad robot name `{n}`"))
        }
    };
    match w.as_slice() {
        ["add", "robot"] => Ok(LiveCmd::AddRobot(None)),
        ["add", "robot", n] => Ok(LiveCmd::AddRobot(Some(robot_name(n)?))),
        ["kill", n] | ["remove", "robot", n] => Ok(LiveCmd::Kill(robot_name(n)?)),
        ["stop", n] => Ok(LiveCmd::Stop(robot_name(n)?)),
        ["add", "machine", rest @ ..] => Ok(LiveCmd::Bridge(format!("add_machine{}", pos(rest)?))),
        ["add", "storage", rest @ ..] => Ok(LiveCmd::Bridge(format!("add_storage{}", pos(rest)?))),
        ["remove", "machine", id] => id
            .parse::<u32>()
            .map(|i| LiveCmd::Bridge(format!("remove_machine {i}")))
            .map_err(|_| format!("bad id `{id}`")),
        ["remove", "storage", id] => id
            .parse::<u32>()
            .map(|i| LiveCmd::Bridge(format!("remove_storage {i}")))
            .map_err(|_| format!("bad id `{id}`")),
        ["status"] => Ok(LiveCmd::Status),
        _ => Err(format!(
            "unknown command `{line}` (add robot [NAME] | kill NAME | stop NAME | add machine [X Y] | remove machine ID | add storage [X Y] | remove storage ID | status)"
        )),
    }
}

fn signal(pid: u32, sig: i32) {
    // SAFETY: plain kill(2) on a child we spawned and have not reaped yet.
    unsafe {
        libc::kill(pid as i32, sig);
    }
}

/// SIGINT every child still running, wait up to `grace`, then SIGKILL. Returns the
/// children that exited unsuccessfully (after having been asked to stop, or before).
fn shutdown(procs: &mut [Proc], grace: Duration) -> Vec<String> {
    for p in procs.iter_mut() {
        if let Ok(None) = p.child.try_wait() {
            signal(p.child.id(), libc::SIGINT);
        }
    }
    let until = Instant::now() + grace;
    let mut failed = Vec::new();
    for p in procs.iter_mut() {
        let status = loop {
            match p.child.try_wait() {
                Ok(Some(s)) => break Some(s),
                Ok(None) if Instant::now() < until => std::thread::sleep(Duration::from_millis(20)),
                _ => {
                    let _ = p.child.kill();
                    let _ = p.child.wait();
                    failed.push(format!("{} (killed after {grace:?})", p.name));
                    break None;
                }
            }
        };
        if let Some(s) = status {
            if !s.success() {
                failed.push(format!("{} ({s})", p.name));
            }
        }
    }
    failed
}

/// The checkpoint shipped in the repository (the README's main job runs it).
pub fn bundled_policy() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("policy/pretrained/smappo_6.4_2.safetensors")
}

/// `--policy` as given: `greedy` means no checkpoint; none means the bundled policy when it
/// is present (a checkout without it falls back to greedy, and says so).
fn resolve_policy(p: Option<PathBuf>) -> Option<PathBuf> {
    match p {
        Some(p) if p.as_os_str() == "greedy" => None,
        Some(p) => Some(p),
        None => {
            let b = bundled_policy();
            if b.exists() {
                Some(b)
            } else {
                eprintln!("fleet: no bundled policy at {}, using greedy", b.display());
                None
            }
        }
    }
}

pub fn run(mut a: FleetArgs) -> Result<()> {
    a.policy = resolve_policy(a.policy.take());
    let setup: sim::Setup = a.setup.parse().map_err(|e| anyhow!("--setup: {e}"))?;
    if !(a.duration.is_finite() && a.duration > 0.0) {
        bail!("--duration must be > 0");
    }
    let bridge_bin = sibling("sim_bridge")?;
    let node_bin = sibling("robot_node")?;
    if let Some(p) = &a.policy {
        // fail early with the checkpoint's own error rather than N identical child errors
        policy_check(p)?;
    }
    let cfg = match &a.config {
        Some(p) => sim::ScenarioConfig::load(p).map_err(|e| anyhow!("{}: {e}", p.display()))?,
        None => sim::ScenarioConfig::default(),
    };
    let env = sim::Env::new(cfg.clone(), setup, a.seed)?;
    let sizes = *env.sizes();
    let domain = a.domain.unwrap_or_else(|| {
        std::env::var("ROS_DOMAIN_ID")
            .ok()
            .and_then(|d| d.trim().parse().ok())
            .unwrap_or(0)
    });
    let lockstep = a.mode == "lockstep";
    let log_dir = a.log_dir.clone().unwrap_or_else(|| {
        std::env::temp_dir().join(format!("tending-fleet-{}", std::process::id()))
    });
    std::fs::create_dir_all(&log_dir)
        .with_context(|| format!("creating log directory {}", log_dir.display()))?;
    let log = |name: &str| -> Result<std::fs::File> {
        let p = log_dir.join(format!("{name}.log"));
        std::fs::File::create(&p).with_context(|| format!("creating {}", p.display()))
    };
    // a restarted robot_node appends to its log (the watchdog's message stays)
    let log_append = |name: &str| -> Result<std::fs::File> {
        let p = log_dir.join(format!("{name}.log"));
        std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&p)
            .with_context(|| format!("opening {}", p.display()))
    };

    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst))
            .context("installing the Ctrl-C handler")?;
    }

    use std::os::unix::process::CommandExt;
    let mut procs: Vec<Proc> = Vec::new();
    let f = |x: f32| format!("{:?}", x as f64);
    let spawn_robot = |name: &str, restart: bool| -> Result<Proc> {
        let mut c = Command::new(&node_bin);
        c.env("ROS_DOMAIN_ID", domain.to_string())
            .args(["--ros-args", "-r", &format!("__ns:=/{name}")])
            .args(["-p", &format!("control_rate_hz:={}", a.rate_hz)])
            .args(["-p", &format!("k_speed:={}", f(cfg.task.k_speed))])
            .args(["-p", &format!("robot_radius:={}", f(sizes.robot_radius))])
            .args([
                "-p",
                &format!("machine_half_x:={}", f(sizes.machine_half[0])),
            ])
            .args([
                "-p",
                &format!("machine_half_y:={}", f(sizes.machine_half[1])),
            ])
            .args([
                "-p",
                &format!("storage_half_x:={}", f(sizes.storage_half[0])),
            ])
            .args([
                "-p",
                &format!("storage_half_y:={}", f(sizes.storage_half[1])),
            ])
            .args(["-p", &format!("stale_timeout_s:={:?}", a.stale_timeout)])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(if restart {
                log_append(name)?
            } else {
                log(name)?
            })
            .process_group(0); // Ctrl-C reaches us only; we stop the children in order
        if lockstep {
            c.args(["-p", "lockstep:=true"]);
        }
        if let Some(p) = &a.policy {
            c.args(["-p", &format!("policy:={}", p.display())]);
        }
        for rp in &a.robot_params {
            c.args(["-p", rp]);
        }
        let child = c
            .spawn()
            .with_context(|| format!("starting {}", node_bin.display()))?;
        Ok(Proc {
            name: name.to_string(),
            child,
        })
    };
    for i in 0..setup.robots {
        procs.push(spawn_robot(&format!("robot_{i}"), false)?);
    }
    let mut next_robot = setup.robots;
    let mut b = Command::new(&bridge_bin);
    b.env("ROS_DOMAIN_ID", domain.to_string())
        .args(["--ros-args", "-p", &format!("setup:={setup}")])
        .args(["-p", &format!("seed:={}", a.seed)])
        .args(["-p", &format!("mode:={}", a.mode)])
        .args(["-p", &format!("rate_hz:={}", a.rate_hz)])
        .args(["-p", &format!("stale_timeout_s:={:?}", a.stale_timeout)])
        .args(["-p", "stdin_commands:=true"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(log("sim_bridge")?)
        .process_group(0);
    if let Some(c) = &a.config {
        b.args(["-p", &format!("config:={}", c.display())]);
    }
    if let Some(r) = &a.record {
        b.args(["-p", &format!("record:={}", r.display())]);
    }
    if lockstep {
        let steps = (a.duration * a.rate_hz).round().max(1.0) as u64;
        b.args(["-p", &format!("max_steps:={steps}")]);
    }
    let mut bridge = b
        .spawn()
        .with_context(|| format!("starting {}", bridge_bin.display()))?;
    let out = bridge.stdout.take().expect("piped");
    let mut bridge_in = bridge.stdin.take().expect("piped");
    procs.push(Proc {
        name: "sim_bridge".into(),
        child: bridge,
    });
    eprintln!(
        "fleet: {} robot_node + sim_bridge, setup {setup}, {} mode, domain {domain}, controller {}, logs in {}",
        setup.robots,
        a.mode,
        a.policy
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| "greedy".into()),
        log_dir.display()
    );

    let (tx, rx) = std::sync::mpsc::channel::<String>();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });

    let (ctx_tx, ctx_rx) = std::sync::mpsc::channel::<String>();
    if !a.no_stdin {
        std::thread::spawn(move || {
            for line in std::io::stdin().lock().lines().map_while(Result::ok) {
                if ctx_tx.send(line).is_err() {
                    break;
                }
            }
        });
    }

    let t0 = Instant::now();
    // lockstep ends when the bridge reaches max_steps; allow generous wall time for it
    let wall_limit = if lockstep {
        Duration::from_secs_f64(a.duration * 20.0 + 60.0)
    } else {
        Duration::from_secs_f64(a.duration)
    };
    let mut last: Option<serde_json::Value> = None;
    let mut early_failure: Option<String> = None;
    // watchdog restarts per robot name
    let mut restarts: std::collections::BTreeMap<String, u32> = Default::default();
    loop {
        for line in ctx_rx.try_iter() {
            let line = line.trim();
            if line.is_empty() {
                continue;
            }
            let at = t0.elapsed().as_secs_f64();
            match parse_live(line) {
                Err(e) => println!("fleet: t={at:.1}s error: {e}"),
                Ok(LiveCmd::AddRobot(name)) => {
                    let name = name.unwrap_or_else(|| {
                        let mut n = format!("robot_{next_robot}");
                        while procs.iter().any(|p| p.name == n) {
                            next_robot += 1;
                            n = format!("robot_{next_robot}");
                        }
                        next_robot += 1;
                        n
                    });
                    if procs.iter().any(|p| p.name == name) {
                        println!("fleet: t={at:.1}s error: {name} is already running");
                        continue;
                    }
                    match spawn_robot(&name, false) {
                        Ok(p) => {
                            println!("fleet: t={at:.1}s started {name} (pid {})", p.child.id());
                            procs.push(p);
                        }
                        Err(e) => println!("fleet: t={at:.1}s error: {e:#}"),
                    }
                }
                Ok(LiveCmd::Kill(name)) | Ok(LiveCmd::Stop(name)) if name == "sim_bridge" => {
                    println!("fleet: t={at:.1}s error: the bridge is not a robot")
                }
                Ok(cmd @ (LiveCmd::Kill(_) | LiveCmd::Stop(_))) => {
                    let (name, sig, what) = match &cmd {
                        LiveCmd::Kill(n) => (n.clone(), libc::SIGKILL, "SIGKILL"),
                        LiveCmd::Stop(n) => (n.clone(), libc::SIGINT, "SIGINT"),
                        _ => unreachable!(),
                    };
                    match procs.iter().position(|p| p.name == name) {
                        None => println!("fleet: t={at:.1}s error: no running robot `{name}`"),
                        Some(i) => {
                            let mut p = procs.remove(i);
                            signal(p.child.id(), sig);
                            let st = if sig == libc::SIGKILL {
                                p.child.wait().ok()
                            } else {
                                let until = Instant::now() + Duration::from_secs(5);
                                loop {
                                    match p.child.try_wait() {
                                        Ok(Some(s)) => break Some(s),
                                        Ok(None) if Instant::now() < until => {
                                            std::thread::sleep(Duration::from_millis(20))
                                        }
                                        _ => {
                                            let _ = p.child.kill();
                                            break p.child.wait().ok();
                                        }
                                    }
                                }
                            };
                            println!(
                                "fleet: t={at:.1}s {what} {name} (pid {}): {}",
                                p.child.id(),
                                st.map(|s| s.to_string()).unwrap_or("?".into())
                            );
                        }
                    }
                }
                Ok(LiveCmd::Bridge(l)) => {
                    use std::io::Write;
                    match writeln!(bridge_in, "{l}").and_then(|_| bridge_in.flush()) {
                        Ok(()) => println!("fleet: t={at:.1}s sent `{l}` to sim_bridge"),
                        Err(e) => println!("fleet: t={at:.1}s error: sim_bridge stdin: {e}"),
                    }
                }
                Ok(LiveCmd::Status) => {
                    let names: Vec<String> = procs
                        .iter()
                        .map(|p| format!("{}({})", p.name, p.child.id()))
                        .collect();
                    println!(
                        "fleet: t={at:.1}s status: {} processes: {}; watchdog restarts: {}",
                        names.len(),
                        names.join(" "),
                        restarts_summary(&restarts)
                    );
                    if let Some(v) = &last {
                        println!("fleet: last metrics {v}");
                    }
                }
            }
        }
        if stop.load(Ordering::SeqCst) {
            eprintln!("fleet: interrupted, stopping");
            break;
        }
        if t0.elapsed() >= wall_limit {
            break;
        }
        match rx.recv_timeout(Duration::from_millis(100)) {
            Ok(line) => {
                if let Ok(v) = serde_json::from_str::<serde_json::Value>(&line) {
                    println!(
                        "t={:>6.1}s step={:>5} robots={:>3} delivered={:>4} collected={:>4} collisions={:>4} MU={:.3}",
                        v["sim_time"].as_f64().unwrap_or(0.0),
                        v["step"],
                        v["robots"],
                        v["parts_delivered"],
                        v["parts_collected"],
                        v["collisions"],
                        v["mu"].as_f64().unwrap_or(0.0)
                    );
                    last = Some(v);
                }
            }
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => {
                // bridge closed stdout: it finished (lockstep max_steps) or died
                if let Some(i) = procs.iter().position(|p| p.name == "sim_bridge") {
                    let _ = procs[i].child.wait();
                }
                break;
            }
            Err(_) => {}
        }
        // a child that exits by itself before the end is a failure, except a robot_node
        // its watchdog ended (code 75): restarted, up to MAX_RESTARTS times per robot
        for proc_ in procs.iter_mut() {
            let Ok(Some(s)) = proc_.child.try_wait() else {
                continue;
            };
            let name = proc_.name.clone();
            let done = restarts.get(&name).copied().unwrap_or(0);
            if name != "sim_bridge" && should_restart(s.code(), done) {
                let at = t0.elapsed().as_secs_f64();
                let old = proc_.child.id();
                match spawn_robot(&name, true) {
                    Ok(p) => {
                        println!(
                            "fleet: t={at:.1}s {name} (pid {old}) hung and was ended by its watchdog ({s}): restarted as pid {} (restart {}/{MAX_RESTARTS})",
                            p.child.id(),
                            done + 1
                        );
                        restarts.insert(name, done + 1);
                        *proc_ = p;
                    }
                    Err(e) => {
                        early_failure =
                            Some(format!("{name} exited early ({s}); restart failed: {e:#}"))
                    }
                }
            } else if name != "sim_bridge" && s.code() == Some(EXIT_WATCHDOG) {
                early_failure = Some(format!(
                    "{name} exited early ({s}: watchdog) after {done} restarts"
                ));
            } else if name != "sim_bridge" || !s.success() {
                early_failure = Some(format!("{name} exited early ({s})"));
            }
        }
        if early_failure.is_some() {
            break;
        }
    }
    let failed = shutdown(&mut procs, Duration::from_secs(5));
    // the bridge prints one last metrics line on exit: that is the run's final state
    while let Ok(line) = rx.recv_timeout(Duration::from_millis(500)) {
        if let Ok(v) = serde_json::from_str::<serde_json::Value>(&line) {
            last = Some(v);
        }
    }
    if let Some(v) = &last {
        println!("final: {v}");
    }
    if !restarts.is_empty() {
        println!(
            "fleet: robot_node watchdog restarts: {}",
            restarts_summary(&restarts)
        );
    }
    if let Some(e) = early_failure {
        bail!("{e}; logs in {}", log_dir.display());
    }
    if !failed.is_empty() {
        bail!(
            "children failed: {}; logs in {}",
            failed.join(", "),
            log_dir.display()
        );
    }
    if last.is_none() {
        bail!("no metrics from sim_bridge; logs in {}", log_dir.display());
    }
    Ok(())
}

fn policy_check(p: &Path) -> Result<()> {
    if !p.is_file() {
        bail!("policy checkpoint {} does not exist", p.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn restart_only_watchdog_exits_up_to_the_cap() {
        assert!(should_restart(Some(EXIT_WATCHDOG), 0));
        assert!(should_restart(Some(75), MAX_RESTARTS - 1));
        assert!(!should_restart(Some(75), MAX_RESTARTS));
        for other in [Some(0), Some(1), Some(2), None] {
            assert!(!should_restart(other, 0), "{other:?}");
        }
        let mut r = std::collections::BTreeMap::new();
        assert_eq!(restarts_summary(&r), "none");
        r.insert("robot_7".to_string(), 2);
        r.insert("robot_3".to_string(), 1);
        assert_eq!(restarts_summary(&r), "robot_3 x1, robot_7 x2");
    }

    #[test]
    fn live_commands_parse() {
        assert_eq!(parse_live("add robot"), Ok(LiveCmd::AddRobot(None)));
        assert_eq!(
            parse_live("add robot rover_1"),
            Ok(LiveCmd::AddRobot(Some("rover_1".into())))
        );
        assert_eq!(
            parse_live("kill /robot_3"),
            Ok(LiveCmd::Kill("robot_3".into()))
        );
        assert_eq!(
            parse_live("stop robot_3"),
            Ok(LiveCmd::Stop("robot_3".into()))
        );
        assert_eq!(
            parse_live("add machine"),
            Ok(LiveCmd::Bridge("add_machine".into()))
        );
        assert_eq!(
            parse_live("add machine 0.5 -0.25"),
            Ok(LiveCmd::Bridge("add_machine 0.5 -0.25".into()))
        );
        assert_eq!(
            parse_live("remove machine 2"),
            Ok(LiveCmd::Bridge("remove_machine 2".into()))
        );
        assert_eq!(
            parse_live("add storage"),
            Ok(LiveCmd::Bridge("add_storage".into()))
        );
        assert_eq!(
            parse_live("remove storage 1"),
            Ok(LiveCmd::Bridge("remove_storage 1".into()))
        );
        assert_eq!(parse_live("status"), Ok(LiveCmd::Status));
        for bad in [
            "add machine 1",
            "add machine nan 0",
            "remove machine x",
            "kill 3robot",
            "kill machine_0",
            "fly",
        ] {
            assert!(parse_live(bad).is_err(), "{bad}");
        }
    }
}
