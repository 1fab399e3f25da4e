//! `tending fleet`: one `sim_bridge` and `robot_node` processes (one per robot, or groups
//! of robots for large fleets, [`layout`]), live metrics and health, clean shutdown
//! (SIGINT to every child, wait, then kill), non-zero exit when the run failed.
//!
//! While it runs, the fleet takes commands on stdin, one per line ([`live`],
//! docs/bench/live.md): `add robot [NAME]` starts one more robot_node (the bridge spawns
//! its body on its first cmd_vel), `kill NAME` SIGKILLs a robot (the bridge drops the body
//! when its cmd_vel goes stale), `stop NAME` SIGINTs it, `add machine [X Y]`,
//! `remove machine ID`, `add storage [X Y]`, `remove storage ID` go to the bridge (its
//! `/tending/command` language, through its stdin), `status` prints the processes, the
//! health and the last metrics. A robot hosted in a group process is killed or stopped by
//! restarting its group without it. `--record DIR` makes the bridge record a rosbag2 MCAP
//! bag of everything it publishes and receives.
//!
//! A child that exits with code 75 (`EX_TEMPFAIL`: its watchdog ended a hung start-up or
//! loop) is restarted with the same arguments, at most [`MAX_RESTARTS`] times per process;
//! any other early exit is a failure. The run also fails, with a one-line reason, when it
//! is unhealthy ([`health`]: robots not acting on the bridge's state, the bridge not
//! stepping at its rate, nothing delivered).

mod health;
mod layout;
mod live;

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Write};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender};
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};

use health::{Health, Sample};
use live::{parse_live, LiveCmd};

#[derive(clap::Args, Debug)]
pub struct FleetArgs {
    /// Setup N.M_K (N robots).
    #[arg(long, default_value = "6.4_2")]
    pub setup: String,
    /// Run time in seconds: wall time in realtime mode, sim time in lockstep mode.
    #[arg(long, default_value_t = 60.0)]
    pub duration: f64,
    /// Policy for every robot_node: a checkpoint path, `greedy` or `greedy-orca` for the
    /// scripted controllers, or (default) the bundled SMAPPO policy
    /// policy/pretrained/smappo_6.4_2.safetensors. A checkpoint runs behind the ORCA
    /// safety filter by default (`--robot-param orca_filter:=false` for the raw policy),
    /// or behind the action shield with `--robot-param shield:=true`.
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
    /// Robots hosted per robot_node process (each keeps its own controller and cmd_vel).
    /// Default: one per robot up to 10 processes per core; a larger fleet runs as 2
    /// processes per core (on 2 cores: 100 robots as 4 processes of 25).
    #[arg(long)]
    pub robots_per_process: Option<usize>,
    /// Extra `-p NAME:=VALUE` for every robot_node (repeatable; e.g. test_delay_ms:=50).
    #[arg(long = "robot-param")]
    pub robot_params: Vec<String>,
    /// Do not read commands from stdin.
    #[arg(long)]
    pub no_stdin: bool,
}

/// A child's exit code when its watchdog ended it (`ros::watchdog::EXIT_WATCHDOG`).
const EXIT_WATCHDOG: i32 = 75;
/// Watchdog restarts allowed per process.
const MAX_RESTARTS: u32 = 3;
/// A robot process (or the bridge) is given this long to start before its robots count in
/// the health check.
const STARTUP_GRACE: Duration = Duration::from_secs(15);
/// How long a stopped child may take to exit before it is killed.
const STOP_GRACE: Duration = Duration::from_secs(5);
const BRIDGE: &str = "sim_bridge";

/// Restart a process that exited with `code` after `restarts` restarts already?
fn should_restart(code: Option<i32>, restarts: u32) -> bool {
    code == Some(EXIT_WATCHDOG) && restarts < MAX_RESTARTS
}

/// `robot_3 x1, robot_7 x2`, or `none`.
fn restarts_summary(r: &BTreeMap<String, u32>) -> String {
    if r.is_empty() {
        return "none".into();
    }
    r.iter()
        .map(|(n, k)| format!("{n} x{k}"))
        .collect::<Vec<_>>()
        .join(", ")
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
            if name == BRIDGE {
                "sim-bridge"
            } else {
                "robot-node"
            }
        );
    }
    Ok(p)
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

fn signal(pid: u32, sig: i32) {
    // SAFETY: plain kill(2) on a child we spawned and have not reaped yet.
    unsafe {
        libc::kill(pid as i32, sig);
    }
}

/// Wait up to `grace` for `child` to exit, then SIGKILL it. None if it had to be killed.
fn wait_or_kill(child: &mut Child, grace: Duration) -> Option<std::process::ExitStatus> {
    let until = Instant::now() + grace;
    loop {
        match child.try_wait() {
            Ok(Some(s)) => return Some(s),
            Ok(None) if Instant::now() < until => std::thread::sleep(Duration::from_millis(20)),
            _ => {
                let _ = child.kill();
                let _ = child.wait();
                return None;
            }
        }
    }
}

/// One robot_node process and the robots it hosts.
struct RobotProc {
    robots: Vec<String>,
    label: String,
    child: Child,
    started: Instant,
}

struct BridgeProc {
    child: Child,
    stdin: ChildStdin,
    started: Instant,
}

/// Everything fixed for the run: what to start and how.
struct Plan {
    a: FleetArgs,
    setup: sim::Setup,
    cfg: sim::ScenarioConfig,
    sizes: sim::Sizes,
    domain: u16,
    lockstep: bool,
    log_dir: PathBuf,
    node_bin: PathBuf,
    bridge_bin: PathBuf,
    per_process: usize,
}

impl Plan {
    fn new(mut a: FleetArgs) -> Result<Plan> {
        // greedy-orca is a robot_node controller (obs::orca), not a checkpoint.
        if a.policy.as_deref() == Some(Path::new("greedy-orca")) {
            a.policy = Some("greedy".into());
            a.robot_params.push("controller:=greedy-orca".into());
        }
        a.policy = resolve_policy(a.policy.take());
        let setup: sim::Setup = a.setup.parse().map_err(|e| anyhow!("--setup: {e}"))?;
        if !(a.duration.is_finite() && a.duration > 0.0) {
            bail!("--duration must be > 0");
        }
        if a.robots_per_process == Some(0) {
            bail!("--robots-per-process must be at least 1");
        }
        let bridge_bin = sibling(BRIDGE)?;
        let node_bin = sibling("robot_node")?;
        if let Some(p) = &a.policy {
            // fail early with one clear error rather than N identical child errors
            if !p.is_file() {
                bail!("policy checkpoint {} does not exist", p.display());
            }
        }
        let cfg = match &a.config {
            Some(p) => sim::ScenarioConfig::load(p).map_err(|e| anyhow!("{}: {e}", p.display()))?,
            None => sim::ScenarioConfig::default(),
        };
        let sizes = *sim::Env::new(cfg.clone(), setup, a.seed)?.sizes();
        let domain = a.domain.unwrap_or_else(|| {
            std::env::var("ROS_DOMAIN_ID")
                .ok()
                .and_then(|d| d.trim().parse().ok())
                .unwrap_or(0)
        });
        // the ROS 2 limit (RTPS port arithmetic): refused here once, not by every child
        if domain > 232 {
            bail!("ROS domain id {domain} (--domain or ROS_DOMAIN_ID) is above 232");
        }
        let log_dir = a.log_dir.clone().unwrap_or_else(|| {
            std::env::temp_dir().join(format!("tending-fleet-{}", std::process::id()))
        });
        std::fs::create_dir_all(&log_dir)
            .with_context(|| format!("creating log directory {}", log_dir.display()))?;
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let per_process = layout::robots_per_process(setup.robots, cores, a.robots_per_process);
        Ok(Plan {
            lockstep: a.mode == "lockstep",
            a,
            setup,
            cfg,
            sizes,
            domain,
            log_dir,
            node_bin,
            bridge_bin,
            per_process,
        })
    }

    /// What the robots run, for the start-up line: the checkpoint, or the scripted
    /// controller (a `controller:=` robot parameter wins, as it does in robot_node).
    fn controller(&self) -> String {
        let forced = self
            .a
            .robot_params
            .iter()
            .rev()
            .find_map(|p| p.strip_prefix("controller:="));
        match (&self.a.policy, forced) {
            (_, Some(c)) if c != "policy" => c.to_string(),
            (Some(p), _) => p.display().to_string(),
            (None, _) => "greedy".into(),
        }
    }

    /// The ROS 2 environment of a child: the fleet's domain, and the distribution a
    /// sourced ROS 2 install would set (ros2-client warns in every process without it).
    fn ros_env(&self, c: &mut Command) {
        c.env("ROS_DOMAIN_ID", self.domain.to_string());
        if std::env::var_os("ROS_DISTRO").is_none() {
            c.env("ROS_DISTRO", "jazzy");
        }
    }

    /// A child's log file; a restarted child appends (its watchdog's message stays).
    fn log(&self, label: &str, append: bool) -> Result<std::fs::File> {
        let p = self.log_dir.join(format!("{label}.log"));
        let mut o = std::fs::OpenOptions::new();
        if append {
            o.create(true).append(true);
        } else {
            o.create(true).write(true).truncate(true);
        }
        o.open(&p)
            .with_context(|| format!("opening {}", p.display()))
    }

    fn spawn_robots(&self, robots: &[String], restart: bool) -> Result<RobotProc> {
        let f = |x: f32| format!("{:?}", x as f64);
        let label = layout::label(robots);
        let mut c = Command::new(&self.node_bin);
        self.ros_env(&mut c);
        match robots {
            [one] => c.args(["--ros-args", "-r", &format!("__ns:=/{one}")]),
            many => c.args(["--ros-args", "-p", &format!("robots:={}", many.join(","))]),
        };
        let s = &self.sizes;
        c.args(["-p", &format!("control_rate_hz:={}", self.a.rate_hz)])
            .args(["-p", &format!("k_speed:={}", f(self.cfg.task.k_speed))])
            .args(["-p", &format!("robot_radius:={}", f(s.robot_radius))])
            .args(["-p", &format!("machine_half_x:={}", f(s.machine_half[0]))])
            .args(["-p", &format!("machine_half_y:={}", f(s.machine_half[1]))])
            .args(["-p", &format!("storage_half_x:={}", f(s.storage_half[0]))])
            .args(["-p", &format!("storage_half_y:={}", f(s.storage_half[1]))])
            .args([
                "-p",
                &format!("stale_timeout_s:={:?}", self.a.stale_timeout),
            ])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(self.log(&label, restart)?)
            .process_group(0); // Ctrl-C reaches us only; we stop the children in order
        if self.lockstep {
            c.args(["-p", "lockstep:=true"]);
        }
        if let Some(p) = &self.a.policy {
            c.args(["-p", &format!("policy:={}", p.display())]);
        }
        for rp in &self.a.robot_params {
            c.args(["-p", rp]);
        }
        let child = c
            .spawn()
            .with_context(|| format!("starting {}", self.node_bin.display()))?;
        Ok(RobotProc {
            robots: robots.to_vec(),
            label,
            child,
            started: Instant::now(),
        })
    }

    /// Start the bridge; its stdout (metrics lines) goes to `metrics`.
    fn spawn_bridge(&self, restart: bool, metrics: Sender<String>) -> Result<BridgeProc> {
        let a = &self.a;
        let mut b = Command::new(&self.bridge_bin);
        self.ros_env(&mut b);
        b.args(["--ros-args", "-p", &format!("setup:={}", self.setup)])
            .args(["-p", &format!("seed:={}", a.seed)])
            .args(["-p", &format!("mode:={}", a.mode)])
            .args(["-p", &format!("rate_hz:={}", a.rate_hz)])
            .args(["-p", &format!("stale_timeout_s:={:?}", a.stale_timeout)])
            .args(["-p", "stdin_commands:=true"])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(self.log(BRIDGE, restart)?)
            .process_group(0);
        if let Some(c) = &a.config {
            b.args(["-p", &format!("config:={}", c.display())]);
        }
        if let Some(r) = &a.record {
            b.args(["-p", &format!("record:={}", r.display())]);
        }
        if self.lockstep {
            let steps = (a.duration * a.rate_hz).round().max(1.0) as u64;
            b.args(["-p", &format!("max_steps:={steps}")]);
        }
        let mut child = b
            .spawn()
            .with_context(|| format!("starting {}", self.bridge_bin.display()))?;
        let out = child.stdout.take().expect("piped");
        let stdin = child.stdin.take().expect("piped");
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                if metrics.send(line).is_err() {
                    break;
                }
            }
        });
        Ok(BridgeProc {
            child,
            stdin,
            started: Instant::now(),
        })
    }
}

/// A running fleet: its processes and what it has seen.
struct Fleet {
    plan: Plan,
    robots: Vec<RobotProc>,
    bridge: BridgeProc,
    metrics_tx: Sender<String>,
    metrics_rx: Receiver<String>,
    commands: Receiver<String>,
    t0: Instant,
    wall_limit: Duration,
    last: Option<serde_json::Value>,
    health: Health,
    /// Watchdog restarts by process label (`sim_bridge` for the bridge).
    restarts: BTreeMap<String, u32>,
    next_robot: usize,
    /// Why the run ended early, if it did.
    failure: Option<String>,
    /// The bridge ended by itself (lockstep `max_steps`).
    bridge_finished: bool,
}

pub fn run(a: FleetArgs) -> Result<()> {
    let stop = ros::stop_flag()?;
    let mut fleet = Fleet::start(Plan::new(a)?)?;
    fleet.supervise(&stop);
    fleet.finish()
}

impl Fleet {
    fn start(plan: Plan) -> Result<Fleet> {
        let names: Vec<String> = (0..plan.setup.robots)
            .map(|i| format!("robot_{i}"))
            .collect();
        let mut robots = Vec::new();
        for group in layout::groups(&names, plan.per_process) {
            robots.push(plan.spawn_robots(&group, false)?);
        }
        let (metrics_tx, metrics_rx) = std::sync::mpsc::channel();
        let bridge = plan.spawn_bridge(false, metrics_tx.clone())?;
        eprintln!(
            "fleet: {} robots in {} robot_node processes + sim_bridge, setup {}, {} mode, domain {}, controller {}, logs in {}",
            names.len(),
            robots.len(),
            plan.setup,
            plan.a.mode,
            plan.domain,
            plan.controller(),
            plan.log_dir.display()
        );
        let (cmd_tx, commands) = std::sync::mpsc::channel::<String>();
        if !plan.a.no_stdin {
            std::thread::spawn(move || {
                for line in std::io::stdin().lock().lines().map_while(Result::ok) {
                    if cmd_tx.send(line).is_err() {
                        break;
                    }
                }
            });
        }
        // lockstep ends when the bridge reaches max_steps; allow generous wall time for it
        let wall_limit = if plan.lockstep {
            Duration::from_secs_f64(plan.a.duration * 20.0 + 60.0)
        } else {
            Duration::from_secs_f64(plan.a.duration)
        };
        let health = Health::new((!plan.lockstep).then_some(plan.a.rate_hz));
        Ok(Fleet {
            next_robot: plan.setup.robots,
            plan,
            robots,
            bridge,
            metrics_tx,
            metrics_rx,
            commands,
            t0: Instant::now(),
            wall_limit,
            last: None,
            health,
            restarts: BTreeMap::new(),
            failure: None,
            bridge_finished: false,
        })
    }

    fn at(&self) -> f64 {
        self.t0.elapsed().as_secs_f64()
    }

    /// Run until the duration is over, the bridge finished, Ctrl-C, or a failure.
    fn supervise(&mut self, stop: &AtomicBool) {
        loop {
            let lines: Vec<String> = self.commands.try_iter().collect();
            for line in lines {
                self.on_command(line.trim());
            }
            if stop.load(Ordering::SeqCst) {
                eprintln!("fleet: interrupted, stopping");
                return;
            }
            if self.t0.elapsed() >= self.wall_limit {
                return;
            }
            match self.metrics_rx.recv_timeout(Duration::from_millis(100)) {
                Ok(line) => self.on_metrics(&line),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => unreachable!("we hold a sender"),
            }
            self.check_bridge();
            self.check_robots();
            if self.failure.is_some() || self.bridge_finished {
                return;
            }
        }
    }

    /// Robots whose process (and the bridge) have been up longer than the start-up grace.
    fn robots_expected(&self) -> usize {
        if self.bridge.started.elapsed() < STARTUP_GRACE {
            return 0;
        }
        self.robots
            .iter()
            .filter(|p| p.started.elapsed() >= STARTUP_GRACE)
            .map(|p| p.robots.len())
            .sum()
    }

    fn on_metrics(&mut self, line: &str) {
        let Ok(v) = serde_json::from_str::<serde_json::Value>(line) else {
            return;
        };
        let u = |k: &str| v[k].as_u64().unwrap_or(0);
        let sample = Sample {
            wall: self.t0.elapsed(),
            step: u("step"),
            sim_time: v["sim_time"].as_f64().unwrap_or(0.0),
            robots_on_state: u("robots_on_state") as usize,
            robots_expected: self.robots_expected(),
            delivered: u("parts_delivered"),
        };
        self.health.observe(sample);
        println!(
            "t={:>6.1}s step={:>5} robots={:>3} on_state={:>3} delivered={:>4} collected={:>4} collisions={:>4} (robot {} machine {} storage {} wall {}) MU={:.3} health: {}",
            sample.sim_time,
            v["step"],
            v["robots"],
            v["robots_on_state"],
            v["parts_delivered"],
            v["parts_collected"],
            v["collisions"],
            v["collisions_robot_robot"],
            v["collisions_robot_machine"],
            v["collisions_robot_storage"],
            v["collisions_robot_wall"],
            v["mu"].as_f64().unwrap_or(0.0),
            self.health.status()
        );
        self.last = Some(v);
    }

    /// The bridge exited by itself: finished (lockstep), hung (restart) or failed.
    fn check_bridge(&mut self) {
        let Ok(Some(s)) = self.bridge.child.try_wait() else {
            return;
        };
        if s.success() {
            self.bridge_finished = true;
            return;
        }
        let done = self.restarts.get(BRIDGE).copied().unwrap_or(0);
        if !should_restart(s.code(), done) {
            self.failure = Some(match s.code() {
                Some(EXIT_WATCHDOG) => {
                    format!("{BRIDGE} hung ({s}: watchdog) after {done} restarts")
                }
                _ => format!("{BRIDGE} exited early ({s})"),
            });
            return;
        }
        let at = self.at();
        match self.plan.spawn_bridge(true, self.metrics_tx.clone()) {
            Ok(b) => {
                println!(
                    "fleet: t={at:.1}s {BRIDGE} (pid {}) hung and was ended by its watchdog ({s}): restarted as pid {} (restart {}/{MAX_RESTARTS}; a new episode)",
                    self.bridge.child.id(),
                    b.child.id(),
                    done + 1
                );
                self.restarts.insert(BRIDGE.into(), done + 1);
                self.bridge = b;
            }
            Err(e) => self.failure = Some(format!("{BRIDGE} hung ({s}); restart failed: {e:#}")),
        }
    }

    /// A robot process that exits by itself before the end failed, unless its watchdog
    /// ended it (code 75): then it is restarted, up to MAX_RESTARTS times.
    fn check_robots(&mut self) {
        for i in 0..self.robots.len() {
            let Ok(Some(s)) = self.robots[i].child.try_wait() else {
                continue;
            };
            let label = self.robots[i].label.clone();
            let done = self.restarts.get(&label).copied().unwrap_or(0);
            if !should_restart(s.code(), done) {
                self.failure = Some(match s.code() {
                    Some(EXIT_WATCHDOG) => {
                        format!("{label} hung ({s}: watchdog) after {done} restarts")
                    }
                    _ => format!("{label} exited early ({s})"),
                });
                return;
            }
            let at = self.at();
            let robots = self.robots[i].robots.clone();
            match self.plan.spawn_robots(&robots, true) {
                Ok(p) => {
                    println!(
                        "fleet: t={at:.1}s {label} (pid {}) hung and was ended by its watchdog ({s}): restarted as pid {} (restart {}/{MAX_RESTARTS})",
                        self.robots[i].child.id(),
                        p.child.id(),
                        done + 1
                    );
                    self.restarts.insert(label, done + 1);
                    self.robots[i] = p;
                }
                Err(e) => {
                    self.failure = Some(format!("{label} hung ({s}); restart failed: {e:#}"));
                    return;
                }
            }
        }
    }

    fn on_command(&mut self, line: &str) {
        if line.is_empty() {
            return;
        }
        let at = self.at();
        match parse_live(line) {
            Err(e) => println!("fleet: t={at:.1}s error: {e}"),
            Ok(LiveCmd::AddRobot(name)) => self.add_robot(name),
            Ok(LiveCmd::Kill(name)) => self.remove_robot(&name, libc::SIGKILL),
            Ok(LiveCmd::Stop(name)) => self.remove_robot(&name, libc::SIGINT),
            Ok(LiveCmd::Bridge(l)) => {
                match writeln!(self.bridge.stdin, "{l}").and_then(|_| self.bridge.stdin.flush()) {
                    Ok(()) => println!("fleet: t={at:.1}s sent `{l}` to {BRIDGE}"),
                    Err(e) => println!("fleet: t={at:.1}s error: {BRIDGE} stdin: {e}"),
                }
            }
            Ok(LiveCmd::Status) => {
                let procs: Vec<String> = self
                    .robots
                    .iter()
                    .map(|p| format!("{}({})", p.label, p.child.id()))
                    .chain([format!("{BRIDGE}({})", self.bridge.child.id())])
                    .collect();
                println!(
                    "fleet: t={at:.1}s status: {} robots in {} processes: {}; health: {}; watchdog restarts: {}",
                    self.robots.iter().map(|p| p.robots.len()).sum::<usize>(),
                    procs.len(),
                    procs.join(" "),
                    self.health.status(),
                    restarts_summary(&self.restarts)
                );
                if let Some(v) = &self.last {
                    println!("fleet: last metrics {v}");
                }
            }
        }
    }

    fn hosts(&self, name: &str) -> bool {
        self.robots
            .iter()
            .any(|p| p.robots.iter().any(|r| r == name))
    }

    fn add_robot(&mut self, name: Option<String>) {
        let at = self.at();
        let name = name.unwrap_or_else(|| loop {
            let n = format!("robot_{}", self.next_robot);
            self.next_robot += 1;
            if !self.hosts(&n) {
                break n;
            }
        });
        if self.hosts(&name) || name == BRIDGE {
            println!("fleet: t={at:.1}s error: {name} is already running");
            return;
        }
        match self.plan.spawn_robots(std::slice::from_ref(&name), false) {
            Ok(p) => {
                println!("fleet: t={at:.1}s started {name} (pid {})", p.child.id());
                self.robots.push(p);
            }
            Err(e) => println!("fleet: t={at:.1}s error: {e:#}"),
        }
    }

    /// Signal the process hosting `name`; a group process is restarted without it.
    fn remove_robot(&mut self, name: &str, sig: i32) {
        let at = self.at();
        let what = if sig == libc::SIGKILL {
            "SIGKILL"
        } else {
            "SIGINT"
        };
        if name == BRIDGE {
            println!("fleet: t={at:.1}s error: the bridge is not a robot");
            return;
        }
        let Some(i) = self
            .robots
            .iter()
            .position(|p| p.robots.iter().any(|r| r == name))
        else {
            println!("fleet: t={at:.1}s error: no running robot `{name}`");
            return;
        };
        let mut p = self.robots.remove(i);
        signal(p.child.id(), sig);
        let st = if sig == libc::SIGKILL {
            p.child.wait().ok()
        } else {
            wait_or_kill(&mut p.child, STOP_GRACE)
        };
        println!(
            "fleet: t={at:.1}s {what} {} (pid {}): {}",
            p.label,
            p.child.id(),
            st.map(|s| s.to_string()).unwrap_or("killed".into())
        );
        let rest: Vec<String> = p.robots.into_iter().filter(|r| r != name).collect();
        if rest.is_empty() {
            return;
        }
        match self.plan.spawn_robots(&rest, true) {
            Ok(q) => {
                println!(
                    "fleet: t={at:.1}s restarted {} without {name} (pid {})",
                    q.label,
                    q.child.id()
                );
                self.robots.push(q);
            }
            Err(e) => self.failure = Some(format!("restarting {} failed: {e:#}", rest.join(","))),
        }
    }

    /// Stop every child, print the final state, and judge the run.
    fn finish(self) -> Result<()> {
        let Fleet {
            plan,
            mut robots,
            mut bridge,
            metrics_tx,
            metrics_rx,
            mut last,
            health,
            restarts,
            failure,
            ..
        } = self;
        // robots first (the bridge keeps stepping while they leave), then the bridge
        let mut failed = Vec::new();
        for p in robots.iter_mut() {
            if let Ok(None) = p.child.try_wait() {
                signal(p.child.id(), libc::SIGINT);
            }
        }
        for p in robots.iter_mut() {
            match wait_or_kill(&mut p.child, STOP_GRACE) {
                Some(s) if !s.success() => failed.push(format!("{} ({s})", p.label)),
                Some(_) => {}
                None => failed.push(format!("{} (killed after {STOP_GRACE:?})", p.label)),
            }
        }
        if let Ok(None) = bridge.child.try_wait() {
            signal(bridge.child.id(), libc::SIGINT);
        }
        match wait_or_kill(&mut bridge.child, STOP_GRACE) {
            Some(s) if !s.success() => failed.push(format!("{BRIDGE} ({s})")),
            Some(_) => {}
            None => failed.push(format!("{BRIDGE} (killed after {STOP_GRACE:?})")),
        }
        drop(metrics_tx);
        // the bridge prints one last metrics line on exit: the run's final state
        while let Ok(line) = metrics_rx.recv_timeout(Duration::from_millis(500)) {
            if let Ok(v) = serde_json::from_str::<serde_json::Value>(&line) {
                last = Some(v);
            }
        }
        if let Some(v) = &last {
            println!("final: {v}");
        }
        // health is judged on what the run showed while it ran: the final line comes after
        // the robots were stopped
        println!(
            "fleet: health: {}; watchdog restarts: {}",
            health.summary(),
            restarts_summary(&restarts)
        );
        let logs = plan.log_dir.display();
        if let Some(e) = failure {
            bail!("{e}; logs in {logs}");
        }
        if !failed.is_empty() {
            bail!("children failed: {}; logs in {logs}", failed.join(", "));
        }
        if let Some(why) = health.verdict() {
            bail!("the fleet did not work: {why}; logs in {logs}");
        }
        Ok(())
    }
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
        let mut r = BTreeMap::new();
        assert_eq!(restarts_summary(&r), "none");
        r.insert("robot_7".to_string(), 2);
        r.insert("robot_3".to_string(), 1);
        assert_eq!(restarts_summary(&r), "robot_3 x1, robot_7 x2");
    }
}
