//! `tending fleet`: one `sim_bridge` and one `robot_node` process per robot, live metrics,
//! clean shutdown (SIGINT to every child, wait, then kill), non-zero exit if a child fails.

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
    /// Policy checkpoint for every robot_node (default: the greedy controller).
    #[arg(long)]
    pub policy: Option<PathBuf>,
    /// realtime (bridge steps at --rate-hz) or lockstep (reproducible, see docs/adr/0001-lockstep.md).
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

struct Proc {
    name: String,
    child: Child,
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

pub fn run(a: FleetArgs) -> Result<()> {
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

    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst))
            .context("installing the Ctrl-C handler")?;
    }

    use std::os::unix::process::CommandExt;
    let mut procs: Vec<Proc> = Vec::new();
    let f = |x: f32| format!("{:?}", x as f64);
    for i in 0..setup.robots {
        let name = format!("robot_{i}");
        let mut c = Command::new(&node_bin);
        c.env("ROS_DOMAIN_ID", domain.to_string())
            .args(["--ros-args", "-r", &format!("__ns:=/{name}")])
            .args(["-p", &format!("control_rate_hz:={}", a.rate_hz)])
            .args(["-p", &format!("k_speed:={}", f(cfg.task.k_speed))])
            .args(["-p", &format!("robot_radius:={}", f(sizes.robot_radius))])
            .args(["-p", &format!("machine_half_x:={}", f(sizes.machine_half[0]))])
            .args(["-p", &format!("machine_half_y:={}", f(sizes.machine_half[1]))])
            .args(["-p", &format!("storage_half_x:={}", f(sizes.storage_half[0]))])
            .args(["-p", &format!("storage_half_y:={}", f(sizes.storage_half[1]))])
            .args(["-p", "stale_timeout_s:=2.0"])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(log(&name)?)
            .process_group(0); // Ctrl-C reaches us only; we stop the children in order
        if lockstep {
            c.args(["-p", "lockstep:=true"]);
        }
        if let Some(p) = &a.policy {
            c.args(["-p", &format!("policy:={}", p.display())]);
        }
        let child = c
            .spawn()
            .with_context(|| format!("starting {}", node_bin.display()))?;
        procs.push(Proc { name, child });
    }
    let mut b = Command::new(&bridge_bin);
    b.env("ROS_DOMAIN_ID", domain.to_string())
        .args(["--ros-args", "-p", &format!("setup:={setup}")])
        .args(["-p", &format!("seed:={}", a.seed)])
        .args(["-p", &format!("mode:={}", a.mode)])
        .args(["-p", &format!("rate_hz:={}", a.rate_hz)])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(log("sim_bridge")?)
        .process_group(0);
    if let Some(c) = &a.config {
        b.args(["-p", &format!("config:={}", c.display())]);
    }
    if lockstep {
        let steps = (a.duration * a.rate_hz).round().max(1.0) as u64;
        b.args(["-p", &format!("max_steps:={steps}")]);
    }
    let mut bridge = b
        .spawn()
        .with_context(|| format!("starting {}", bridge_bin.display()))?;
    let out = bridge.stdout.take().expect("piped");
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

    let t0 = Instant::now();
    // lockstep ends when the bridge reaches max_steps; allow generous wall time for it
    let wall_limit = if lockstep {
        Duration::from_secs_f64(a.duration * 20.0 + 60.0)
    } else {
        Duration::from_secs_f64(a.duration)
    };
    let mut last: Option<serde_json::Value> = None;
    let mut early_failure: Option<String> = None;
    let bridge_idx = procs.len() - 1;
    loop {
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
                let _ = procs[bridge_idx].child.wait();
                break;
            }
            Err(_) => {}
        }
        // a child that exits by itself before the end is a failure
        for p in procs.iter_mut() {
            if let Ok(Some(s)) = p.child.try_wait() {
                if p.name != "sim_bridge" || !s.success() {
                    early_failure = Some(format!("{} exited early ({s})", p.name));
                }
            }
        }
        if early_failure.is_some() {
            break;
        }
    }
    let failed = shutdown(&mut procs, Duration::from_secs(5));
    if let Some(v) = &last {
        println!("final: {v}");
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
