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

mod children;
mod domain;
mod health;
mod layout;
mod live;
mod params;
mod plan;
mod secure;

use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender};
use std::time::{Duration, Instant};

use anyhow::{bail, Result};

use children::{restarts_summary, BridgeProc, RobotProc};
use health::{Health, Sample};
use plan::Plan;

#[derive(clap::Args, Debug)]
pub struct FleetArgs {
    /// Setup N.M_K (N robots).
    #[arg(long, default_value = "6.4_2")]
    pub setup: String,
    /// Run time in seconds: wall time in realtime mode, sim time in lockstep mode.
    #[arg(long, default_value_t = 60.0)]
    pub duration: f64,
    /// Policy for every robot_node: a checkpoint path, `greedy`, `greedy-orca` or
    /// `matching-orca` for the scripted controllers, or (default) the bundled SMAPPO policy
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
    /// ROS_DOMAIN_ID for the fleet (default: the environment's, else 0), or `auto`: the
    /// first domain from there up with no other fleet on it (said on stderr). A domain
    /// with another fleet on it is refused (docs/adr/0032-one-fleet-per-domain.md).
    #[arg(long, value_parser = domain::parse_domain)]
    pub domain: Option<domain::DomainArg>,
    /// Seconds to watch the domain's ROS 2 graph for another fleet before starting
    /// (default 2, or 4 with --secure: handshakes come first); 0 skips the check.
    #[arg(long)]
    pub domain_check: Option<f64>,
    /// The scenario (TOML file, floor, observation bound) for the bridge and every robot.
    #[command(flatten)]
    pub scenario: sim::args::ScenarioArgs,
    /// Safety margins (TOML, plan::margins, e.g. configs/margins/*.toml): the ORCA
    /// filter's go to every robot_node (orca_clearance, orca_rest_clearance,
    /// orca_obstacle_horizon in the fleet's parameters file); default: the deployed ones.
    #[arg(long)]
    pub margins: Option<PathBuf>,
    /// Directory for the children's logs and the run's ROS 2 parameters file `fleet.yaml`
    /// (every child's `--params-file`; default: a temporary directory).
    #[arg(long)]
    pub log_dir: Option<PathBuf>,
    /// Bag directory: sim_bridge records every topic it publishes and every cmd_vel it
    /// receives (rosbag2 MCAP; its `record` parameter in fleet.yaml).
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Staleness timeout (s) of the bridge (a body whose cmd_vel is older is removed) and of
    /// every robot_node's inputs.
    #[arg(long, default_value_t = 2.0)]
    pub stale_timeout: f64,
    /// Command timeout (s) of the bridge (`cmd_vel_timeout_s`): a body whose cmd_vel is
    /// older is commanded zero velocity and brakes to a stop, like a base controller's
    /// command timeout; it is removed at --stale-timeout, which it must stay below.
    /// Default: 3 control periods (0.3 s at --rate-hz 10), so that a robot whose node died
    /// stops within a few ticks (docs/adr/0031-command-timeout.md). Realtime only;
    /// lockstep waits for commands.
    #[arg(long)]
    pub cmd_vel_timeout: Option<f64>,
    /// Robots hosted per robot_node process (each keeps its own controller and cmd_vel).
    /// Default: one per robot up to 10 processes per core; a larger fleet runs as 2
    /// processes per core (on 2 cores: 100 robots as 4 processes of 25). With --secure, one
    /// per robot only up to 4 processes per core (secure start-up grows with processes
    /// squared; on 2 cores 20 robots run as 4 processes of 5).
    #[arg(long)]
    pub robots_per_process: Option<usize>,
    /// Cell topics (docs/adr/0038-cell-topics.md): the bridge also publishes each square
    /// cell of this side (m) on `/tending/cells/c<i>_<j>`, and every robot reads the cells
    /// around it instead of every entity's topics, so what a robot receives is bounded by
    /// its neighbourhood. Use with `--nearest K` (an unbounded observation needs the whole
    /// floor anyway). Default: off (every entity's topics, the contract's).
    #[arg(long, value_parser = positive_metres)]
    pub cell_size: Option<f64>,
    /// Extra `-p NAME:=VALUE` for every robot_node (repeatable; e.g. test_delay_ms:=50).
    #[arg(long = "robot-param")]
    pub robot_params: Vec<String>,
    /// Do not read commands from stdin.
    #[arg(long)]
    pub no_stdin: bool,
    /// DDS Security, the SROS2 way: every process authenticates with its own enclave
    /// (a robot may publish only its own cmd_vel), traffic is encrypted, and
    /// ROS_SECURITY_STRATEGY=Enforce (a process without a valid enclave does not start).
    /// The keystore is --keystore, else a new one in the log directory.
    #[arg(long)]
    pub secure: bool,
    /// Keystore for --secure (`tending security create`); created if it does not exist,
    /// and missing enclaves are added (needs its private/ca.key.pem).
    #[arg(long, requires = "secure")]
    pub keystore: Option<PathBuf>,
}

fn positive_metres(s: &str) -> std::result::Result<f64, String> {
    match s.parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 => Ok(x),
        _ => Err(format!("expected a length in metres > 0, got {s:?}")),
    }
}

/// A robot process (or the bridge) is given this long to start before its robots count in
/// the health check.
const STARTUP_GRACE: Duration = Duration::from_secs(15);
const BRIDGE: &str = "sim_bridge";

/// A running fleet: its processes and what it has seen. One method per phase: [`start`],
/// [`supervise`] (commands, metrics, children's exits), [`finish`] (stop and judge);
/// live commands are in [`live`], restarts in [`children`].
///
/// [`start`]: Fleet::start
/// [`supervise`]: Fleet::supervise
/// [`finish`]: Fleet::finish
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
    /// Holds this fleet's node on its domain while it runs (another fleet sees it).
    _guard: domain::Guard,
    /// The bridge ended by itself (lockstep `max_steps`).
    bridge_finished: bool,
}

pub fn run(a: FleetArgs) -> Result<()> {
    let stop = ros::stop_flag()?;
    let mut plan = Plan::new(a)?;
    let guard = plan.claim_domain()?;
    let mut fleet = Fleet::start(plan, guard)?;
    fleet.supervise(&stop);
    fleet.finish()
}

/// Lines typed on stdin, read by a thread (none with `read` false).
fn stdin_lines(read: bool) -> Receiver<String> {
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    if read {
        std::thread::spawn(move || {
            for line in std::io::stdin().lock().lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
    }
    rx
}

impl Fleet {
    fn start(plan: Plan, guard: domain::Guard) -> Result<Fleet> {
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
        if let Some(ks) = &plan.keystore {
            eprintln!(
                "fleet: DDS Security enforced, one enclave per process, keystore {}",
                ks.root().display()
            );
        }
        let commands = stdin_lines(!plan.a.no_stdin);
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
            _guard: guard,
        })
    }

    fn at(&self) -> f64 {
        self.t0.elapsed().as_secs_f64()
    }

    /// Run until the duration is over, the bridge finished, Ctrl-C, or a failure.
    fn supervise(&mut self, stop: &AtomicBool) {
        loop {
            self.drain_commands();
            if stop.load(Ordering::SeqCst) {
                eprintln!("fleet: interrupted, stopping");
                return;
            }
            if self.t0.elapsed() >= self.wall_limit {
                return;
            }
            self.wait_metrics();
            self.check_bridge();
            self.check_robots();
            if self.failure.is_some() || self.bridge_finished {
                return;
            }
        }
    }

    /// Apply the commands typed since the last call.
    fn drain_commands(&mut self) {
        let lines: Vec<String> = self.commands.try_iter().collect();
        for line in lines {
            self.on_command(line.trim());
        }
    }

    /// Wait up to 100 ms for the bridge's next metrics line.
    fn wait_metrics(&mut self) {
        match self.metrics_rx.recv_timeout(Duration::from_millis(100)) {
            Ok(line) => self.on_metrics(&line),
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => unreachable!("we hold a sender"),
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
            foreign_cmds: u("cmds_foreign_writer"),
        };
        self.health.observe(sample);
        println!(
            "t={:>6.1}s step={:>5} robots={:>3} on_state={:>3} delivered={:>4} collected={:>4} collisions={:>4} (robot {} machine {} storage {} wall {}; events {}) MU={:.3} health: {}",
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
            v["collision_events"],
            v["mu"].as_f64().unwrap_or(0.0),
            self.health.status()
        );
        self.last = Some(v);
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
        let failed = children::stop_all(&mut robots, &mut bridge);
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
