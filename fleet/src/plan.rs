//! What a fleet run starts and how: the resolved arguments, the scenario, the binaries,
//! and the command lines of `robot_node` and `sim_bridge` children.

use std::io::{BufRead, BufReader};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc::Sender;
use std::time::Instant;

use anyhow::{anyhow, bail, Context, Result};
use plan::MethodName;

use super::children::{BridgeProc, RobotProc};
use super::domain::{self, DomainArg, Guard, MAX_DOMAIN};
use super::{layout, params, FleetArgs, BRIDGE};

/// The bridge's `startup_grace_s` with DDS Security (its default is 10 s).
pub(super) const SECURE_STARTUP_GRACE_S: f64 = 30.0;

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
pub(super) fn bundled_policy() -> PathBuf {
    // this crate sits one level below the repository root, beside `policy/`
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../policy/pretrained/smappo_6.4_2.safetensors")
}

/// `--policy` as given: a script's name (`plan::MethodName`) is that robot_node controller
/// and no checkpoint; a path is a checkpoint; none means the bundled policy when it is
/// present (a checkout without it falls back to greedy, and says so).
fn resolve_policy(p: Option<PathBuf>) -> Result<(MethodName, Option<PathBuf>)> {
    let named = p
        .as_ref()
        .and_then(|p| p.to_str())
        .and_then(|s| s.parse::<MethodName>().ok());
    match (named, p) {
        (Some(MethodName::Random), _) => {
            bail!("--policy random: an offline baseline (tending eval), not a robot controller")
        }
        (Some(MethodName::Policy), _) => bail!("--policy policy: give the checkpoint's path"),
        (Some(script), _) => Ok((script, None)),
        (None, Some(p)) => Ok((MethodName::Policy, Some(p))),
        (None, None) => {
            let b = bundled_policy();
            if b.exists() {
                Ok((MethodName::Policy, Some(b)))
            } else {
                eprintln!("fleet: no bundled policy at {}, using greedy", b.display());
                Ok((MethodName::Greedy, None))
            }
        }
    }
}

/// The fleet's default command timeout in control periods: above the longest gap between
/// a live robot's commands at the bridge seen under load (0.26 s at 10 Hz), short enough
/// that a dead robot stops within a few ticks (docs/adr/0031-command-timeout.md).
pub(super) const CMD_TIMEOUT_PERIODS: f64 = 3.0;

/// `--cmd-vel-timeout` and `--stale-timeout`: a body stops at the first and is removed at
/// the second, so the first must be shorter (the bridge refuses it too, naming its
/// parameter; refused here once, with the flags' names).
fn check_timeouts(cmd_vel: f64, stale: f64) -> Result<()> {
    if !(stale.is_finite() && stale > 0.0) {
        bail!("--stale-timeout must be a number > 0, got {stale}");
    }
    if !(cmd_vel.is_finite() && cmd_vel > 0.0 && cmd_vel < stale) {
        bail!(
            "--cmd-vel-timeout must be > 0 and below --stale-timeout ({stale} s): a robot's \
             body stops at the command timeout and is removed at the staleness timeout; got \
             {cmd_vel} (its default is {CMD_TIMEOUT_PERIODS} control periods of --rate-hz)"
        );
    }
    Ok(())
}

/// A keystore's documents cover domains up to [`msgs::enclave::MAX_SECURE_DOMAIN`] (230:
/// Cyclone DDS refuses documents naming a higher one), below ROS's 232: refused here
/// once, with the reason, rather than by every child.
fn check_secure_domain(secure: bool, domain: u16) -> Result<()> {
    let max = msgs::enclave::MAX_SECURE_DOMAIN;
    if secure && domain > max {
        bail!(
            "ROS domain id {domain}: a secure fleet runs on domains 0..={max} (the keystore's \
             governance and permissions cover those; ROS allows up to {MAX_DOMAIN} without \
             security)"
        );
    }
    Ok(())
}

/// Lockstep fleets above this many robots get waits scaled with their size.
const LOCKSTEP_SCALED_ABOVE: f64 = 100.0;
/// ... this many seconds per robot (5 s at 1,000 robots).
const LOCKSTEP_S_PER_ROBOT: f64 = 0.005;

/// Everything fixed for the run: what to start and how.
pub(super) struct Plan {
    pub(super) a: FleetArgs,
    pub(super) setup: sim::Setup,
    pub(super) cfg: sim::ScenarioConfig,
    pub(super) sizes: sim::Sizes,
    /// The room the setup runs in (the paper's, or a grown floor's, docs/adr/0037).
    pub(super) room_size: f32,
    /// What every robot_node runs (`controller` in fleet.yaml).
    pub(super) controller: MethodName,
    pub(super) domain: u16,
    pub(super) lockstep: bool,
    pub(super) log_dir: PathBuf,
    pub(super) node_bin: PathBuf,
    pub(super) bridge_bin: PathBuf,
    pub(super) per_process: usize,
    /// `--secure`: the keystore every child's enclave is in.
    pub(super) keystore: Option<keystore::Keystore>,
    /// The bridge's `cmd_vel_timeout_s`: `--cmd-vel-timeout`, else
    /// [`CMD_TIMEOUT_PERIODS`] control periods.
    pub(super) cmd_vel_timeout: f64,
    /// `<log dir>/fleet.yaml`: every child's `--params-file`.
    pub(super) params_file: PathBuf,
    /// The ORCA filter's margins (`--margins`), for every robot_node.
    pub(super) margins: plan::FilterMargins,
}

impl Plan {
    pub(super) fn new(mut a: FleetArgs) -> Result<Plan> {
        let (controller, policy) = resolve_policy(a.policy.take())?;
        a.policy = policy;
        let setup: sim::Setup = a.setup.parse().map_err(|e| anyhow!("--setup: {e}"))?;
        if !(a.duration.is_finite() && a.duration > 0.0) {
            bail!("--duration must be > 0");
        }
        if !(a.rate_hz.is_finite() && a.rate_hz > 0.0) {
            bail!("--rate-hz must be a number > 0");
        }
        let cmd_vel_timeout = a.cmd_vel_timeout.unwrap_or(CMD_TIMEOUT_PERIODS / a.rate_hz);
        check_timeouts(cmd_vel_timeout, a.stale_timeout)?;
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
        let cfg = a.scenario.load()?;
        let o = cfg.observation;
        let unbounded = [o.nearest_machines, o.nearest_storages, o.nearest_peers]
            .iter()
            .any(Option::is_none);
        if a.cell_size.is_some() && unbounded {
            eprintln!(
                "fleet: warning: --cell-size without a bound on every group (--nearest K): a \
                 robot that observes a whole group reads every cell (docs/adr/0038)"
            );
        }
        // The setup's room and body sizes, from the counts (no environment needed).
        let sizes = sim::layout::sizes_for(setup, &cfg);
        let room_size = sim::layout::room_for(setup, &cfg);
        let margins = match &a.margins {
            Some(p) => plan::Margins::load(p).map_err(|e| anyhow!("--margins: {e}"))?,
            None => plan::Margins::default(),
        };
        // robot_node runs greedy-ORCA with its built-in margins: refuse rather than ignore
        if !margins.greedy_orca.is_default() {
            bail!(
                "--margins: robot_node runs greedy-ORCA with its built-in margins; the file's \
                 [greedy_orca] table is for `tending eval` and `tending sim` only"
            );
        }
        let env_domain = || {
            std::env::var("ROS_DOMAIN_ID")
                .ok()
                .and_then(|d| d.trim().parse().ok())
                .unwrap_or(0)
        };
        let domain = match a.domain {
            Some(DomainArg::Id(d)) => d,
            Some(DomainArg::Auto) | None => env_domain(),
        };
        // the ROS 2 limit (RTPS port arithmetic): refused here once, not by every child
        if domain > MAX_DOMAIN {
            bail!("ROS domain id {domain} (--domain or ROS_DOMAIN_ID) is above {MAX_DOMAIN}");
        }
        check_secure_domain(a.secure, domain)?;
        if a.domain_check.is_some_and(|s| !(s.is_finite() && s >= 0.0)) {
            bail!("--domain-check must be a number of seconds >= 0");
        }
        let log_dir = a.log_dir.clone().unwrap_or_else(|| {
            std::env::temp_dir().join(format!("tending-fleet-{}", std::process::id()))
        });
        std::fs::create_dir_all(&log_dir)
            .with_context(|| format!("creating log directory {}", log_dir.display()))?;
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let per_process =
            layout::robots_per_process(setup.robots, cores, a.secure, a.robots_per_process);
        let keystore = if a.secure {
            let root = a
                .keystore
                .clone()
                .unwrap_or_else(|| log_dir.join("keystore"));
            Some(super::secure::keystore(&root)?)
        } else {
            None
        };
        let plan = Plan {
            lockstep: a.mode == "lockstep",
            params_file: log_dir.join("fleet.yaml"),
            a,
            setup,
            cfg,
            room_size,
            controller,
            sizes,
            domain,
            log_dir,
            node_bin,
            bridge_bin,
            per_process,
            keystore,
            cmd_vel_timeout,
            margins: margins.filter,
        };
        plan.write_params()?;
        Ok(plan)
    }

    /// Before anything starts: is the domain free of other fleets (`--domain auto`: the
    /// first free one from there up becomes the fleet's domain)? The guard holds this
    /// fleet's node on it while the fleet runs (not with --secure; see [`domain::claim`]).
    pub(super) fn claim_domain(&mut self) -> Result<Guard> {
        let mut guard = Guard::new();
        let secure = self.keystore.is_some();
        let for_s = self
            .a
            .domain_check
            .unwrap_or(if secure { 4.0 } else { 2.0 });
        if for_s == 0.0 {
            eprintln!(
                "fleet: --domain-check 0: not looking for another fleet on ROS domain {}",
                self.domain
            );
            return Ok(guard);
        }
        let security = match &self.keystore {
            // the bridge's identity: it reads the graph the bridge would share
            Some(ks) => ros::Security::Enclave {
                enclave: keystore::BRIDGE_ENCLAVE.to_string(),
                dir: ks.enclave_dir(keystore::BRIDGE_ENCLAVE),
            },
            None => ros::Security::Off,
        };
        let auto = self.a.domain == Some(DomainArg::Auto);
        self.domain = domain::claim(&mut guard, self.domain, auto, &security, for_s, !secure)?;
        check_secure_domain(secure, self.domain)?;
        Ok(guard)
    }

    /// What the robots run, for the start-up line: the checkpoint, or the scripted
    /// controller (a `controller:=` robot parameter wins, as it does in robot_node).
    pub(super) fn controller(&self) -> String {
        let forced = self
            .a
            .robot_params
            .iter()
            .rev()
            .find_map(|p| p.strip_prefix("controller:="));
        match (&self.a.policy, forced) {
            (_, Some(c)) if c != "policy" => c.to_string(),
            (Some(p), _) => p.display().to_string(),
            (None, _) => self.controller.to_string(),
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

    /// The run's parameters file ([`params`]): the bridge's section and the robots'.
    fn write_params(&self) -> Result<()> {
        let a = &self.a;
        let mut b = params::Section::default();
        b.set("setup", self.setup.to_string())
            .set("seed", a.seed)
            .set("mode", a.mode.as_str())
            .set("rate_hz", a.rate_hz)
            .set("stale_timeout_s", a.stale_timeout)
            .set("cmd_vel_timeout_s", self.cmd_vel_timeout)
            .set("stdin_commands", true);
        if a.scenario.floor.is_some() || a.scenario.nearest.is_some() {
            // the flags changed the file's scenario: the bridge reads the one in effect
            let f = self.log_dir.join("scenario.toml");
            std::fs::write(&f, self.cfg.to_toml())
                .with_context(|| format!("writing {}", f.display()))?;
            b.set("config", f.display().to_string());
        } else if let Some(c) = &a.scenario.scenario {
            b.set("config", c.display().to_string());
        }
        if let Some(r) = &a.record {
            b.set("record", r.display().to_string());
        }
        if let Some(c) = a.cell_size {
            b.set("cell_size", c);
        }
        if self.lockstep {
            b.set(
                "max_steps",
                (a.duration * a.rate_hz).round().max(1.0) as u64,
            );
        }
        if self.keystore.is_some() {
            // A secure handshake whose best-effort messages are lost under load is
            // retried once a second and took 3-9 s with two 6-robot fleets on 2 cores
            // (third_party/README.md). The bridge waits that long for a robot's first
            // answer (ADR 0029) before stepping without it.
            b.set("startup_grace_s", SECURE_STARTUP_GRACE_S);
        }
        let s = &self.sizes;
        let mut r = params::Section::default();
        r.set("controller", self.controller.as_str())
            .set("control_rate_hz", a.rate_hz)
            .set_f32("k_speed", self.cfg.task.k_speed)
            .set("prep_steps", self.cfg.task.prep_steps)
            .set_f32("robot_radius", s.robot_radius)
            .set_f32("machine_half_x", s.machine_half[0])
            .set_f32("machine_half_y", s.machine_half[1])
            .set_f32("storage_half_x", s.storage_half[0])
            .set_f32("storage_half_y", s.storage_half[1])
            .set_f32("room_size", self.room_size)
            .set("stale_timeout_s", a.stale_timeout)
            .set_f32("orca_clearance", self.margins.clearance)
            .set_f32("orca_rest_clearance", self.margins.rest_clearance)
            .set_f32("orca_obstacle_horizon", self.margins.obstacle_horizon);
        if self.lockstep {
            r.set("lockstep", true);
            let n = self.setup.robots as f64;
            if n > LOCKSTEP_SCALED_ABOVE {
                // A lockstep step of a large fleet takes about 1-2.5 ms of wall time per
                // robot on this 2-core machine (1,000 robots: 1-2.5 s). A robot that waits
                // only the default 0.5 s for its inputs acts on an incomplete state (the
                // episode diverges from the offline one), and answers resent every 0.5 s
                // flood the bridge (15,000 per process in a 20-step 1,000-robot run). Both
                // scale with the fleet; the bridge's step timeout stays above them.
                let s = n * LOCKSTEP_S_PER_ROBOT;
                r.set("lockstep_wait_s", s).set("lockstep_resend_s", s);
                b.set("lockstep_timeout_s", 2.0 * s);
            }
        }
        let o = self.cfg.observation;
        for (name, k) in [
            ("nearest_machines", o.nearest_machines),
            ("nearest_storages", o.nearest_storages),
            ("nearest_peers", o.nearest_peers),
        ] {
            if let Some(k) = k {
                r.set(name, k as u64);
            }
        }
        if let Some(p) = &a.policy {
            r.set("policy", p.display().to_string());
        }
        if let Some(c) = a.cell_size {
            r.set("cell_size", c);
        }
        params::write(&self.params_file, b, r)
    }

    pub(super) fn spawn_robots(&self, robots: &[String], restart: bool) -> Result<RobotProc> {
        let label = layout::label(robots);
        let mut c = Command::new(&self.node_bin);
        self.ros_env(&mut c);
        c.arg("--ros-args")
            .arg("--params-file")
            .arg(&self.params_file);
        match robots {
            [one] => c.args(["-r", &format!("__ns:=/{one}")]),
            many => c.args(["-p", &format!("robots:={}", many.join(","))]),
        };
        c.stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(self.log(&label, restart)?)
            .process_group(0); // Ctrl-C reaches us only; we stop the children in order
        for rp in &self.a.robot_params {
            c.args(["-p", rp]);
        }
        if let Some(ks) = &self.keystore {
            let enclave = super::secure::robots_enclave(ks, robots)?;
            super::secure::env(&mut c, ks, &enclave);
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
    pub(super) fn spawn_bridge(
        &self,
        restart: bool,
        metrics: Sender<String>,
    ) -> Result<BridgeProc> {
        let mut b = Command::new(&self.bridge_bin);
        self.ros_env(&mut b);
        b.arg("--ros-args")
            .arg("--params-file")
            .arg(&self.params_file)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(self.log(BRIDGE, restart)?)
            .process_group(0);
        if let Some(ks) = &self.keystore {
            super::secure::env(&mut b, ks, keystore::BRIDGE_ENCLAVE);
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

#[cfg(test)]
mod tests {
    use super::{bundled_policy, check_secure_domain, check_timeouts, resolve_policy};
    use plan::MethodName;

    /// The default fleet runs the bundled policy: its path resolves in a checkout (moving
    /// this crate once pointed it at a file that is not there, and the fleet fell back to
    /// greedy).
    #[test]
    fn the_default_fleet_runs_the_bundled_policy() {
        assert!(bundled_policy().is_file(), "{}", bundled_policy().display());
        let (controller, path) = resolve_policy(None).unwrap();
        assert_eq!(controller, MethodName::Policy);
        assert_eq!(path, Some(bundled_policy()));
    }

    #[test]
    fn a_secure_fleet_is_refused_above_domain_230_with_the_reason() {
        assert!(check_secure_domain(true, 230).is_ok());
        assert!(check_secure_domain(false, 232).is_ok());
        let e = check_secure_domain(true, 231).unwrap_err().to_string();
        assert!(e.contains("231") && e.contains("0..=230"), "{e}");
    }

    #[test]
    fn the_command_timeout_must_be_below_the_stale_timeout() {
        assert!(check_timeouts(0.5, 2.0).is_ok());
        for (c, s) in [
            (2.0, 2.0),
            (0.0, 2.0),
            (0.5, 0.4),
            (f64::NAN, 2.0),
            (0.1, 0.0),
        ] {
            let e = check_timeouts(c, s).unwrap_err().to_string();
            assert!(e.contains("-timeout"), "{c} {s}: {e}");
        }
        let e = check_timeouts(3.0, 2.0).unwrap_err().to_string();
        assert!(
            e.contains("--cmd-vel-timeout") && e.contains("--stale-timeout"),
            "{e}"
        );
    }
}
