//! The harness both lockstep tests share: a `sim_bridge` plus one `robot_node` per robot
//! in lockstep, run to a step count, and the comparison with an offline episode.

#![allow(dead_code)] // each test file uses a different part of it

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use sim::{Env, ScenarioConfig, Setup};

pub fn bin_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_sim_bridge"))
        .parent()
        .unwrap()
        .to_path_buf()
}

pub fn robot_node_bin() -> PathBuf {
    let p = bin_dir().join("robot_node");
    assert!(
        p.exists(),
        "{} not built: run `cargo build --release -p robot-node` (or test -p robot-node too)",
        p.display()
    );
    p
}

pub struct Offline {
    pub delivered: u32,
    pub collected: u32,
    pub collisions: u32,
    pub mu: f64,
}

impl Offline {
    /// The metrics of `env`'s episode so far.
    pub fn of(env: &Env) -> Self {
        let m = env.metrics();
        Offline {
            delivered: m.parts_delivered,
            collected: m.parts_collected,
            collisions: m.collisions,
            mu: m.utilization(),
        }
    }
}

/// An offline episode of `steps` steps of `setup` from `seed` (default scenario): `init`
/// builds the controller from the first env, then every step `step` gets the controller,
/// the observation batch and the env to step. Returns the episode's metrics.
pub fn offline_episode<C>(
    setup: Setup,
    seed: u64,
    steps: u32,
    init: impl FnOnce(&Env) -> C,
    step: impl FnMut(&mut C, &obs::ObsBatch, &mut Env),
) -> Offline {
    offline_episode_in(&ScenarioConfig::default(), setup, seed, steps, init, step)
}

/// [`offline_episode`] in scenario `cfg`.
pub fn offline_episode_in<C>(
    cfg: &ScenarioConfig,
    setup: Setup,
    seed: u64,
    steps: u32,
    init: impl FnOnce(&Env) -> C,
    mut step: impl FnMut(&mut C, &obs::ObsBatch, &mut Env),
) -> Offline {
    let mut env = Env::new(cfg.clone(), setup, seed).unwrap();
    let mut ctrl = init(&env);
    let mut batch = obs::ObsBatch::default();
    for _ in 0..steps {
        env.observe(&mut batch);
        step(&mut ctrl, &batch, &mut env);
    }
    Offline::of(&env)
}

/// A bundled checkpoint of policy/pretrained (committed: missing is a failure, not a skip).
pub fn pretrained(file: &str) -> PathBuf {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../policy/pretrained")
        .join(file);
    assert!(
        p.exists(),
        "the bundled checkpoint {} is missing",
        p.display()
    );
    p
}

/// A checkpoint's policy with one recurrent state per robot of `env`.
pub fn policy_with_states(
    path: &std::path::Path,
    env: &Env,
) -> (policy::Policy, Vec<policy::PolicyState>) {
    let pol = policy::Policy::load(path).unwrap();
    let states = (0..env.n_robots()).map(|_| pol.new_state()).collect();
    (pol, states)
}

/// The most probable action of every row of `batch`.
pub fn greedy_policy_actions(
    pol: &mut policy::Policy,
    states: &mut [policy::PolicyState],
    batch: &obs::ObsBatch,
) -> Vec<u8> {
    (0..batch.rows)
        .map(|r| {
            pol.act(&batch.row(r), &mut states[r], policy::ActMode::Greedy)
                .unwrap()
        })
        .collect()
}

/// Child processes, asked to stop (SIGTERM) then killed when dropped, also when a test
/// panics.
pub struct Kill(pub Vec<Child>);
impl Drop for Kill {
    fn drop(&mut self) {
        for c in &mut self.0 {
            unsafe {
                libc::kill(c.id() as i32, libc::SIGTERM);
            }
        }
        let until = Instant::now() + Duration::from_secs(5);
        for c in &mut self.0 {
            while Instant::now() < until {
                if let Ok(Some(_)) = c.try_wait() {
                    break;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// The ROS 2 security environment of a process in enclave `enclave` of `keystore`
/// (Enforce: a process that cannot join securely does not start).
fn secure(cmd: &mut Command, keystore: &std::path::Path, enclave: &str) {
    cmd.env("ROS_SECURITY_KEYSTORE", keystore)
        .env("ROS_SECURITY_ENABLE", "true")
        .env("ROS_SECURITY_STRATEGY", "Enforce")
        .env_remove("ROS_SECURITY_ENCLAVE_OVERRIDE")
        .args(["--enclave", enclave]);
}

/// One lockstep run of a fleet: a `robot_node` per robot and `sim_bridge`, on `domain`,
/// for `steps` steps of `setup` from `seed` (default scenario). Set the optional fields
/// with struct update syntax: `LockstepRun { policy: Some(p), ..LockstepRun::new(..) }`.
pub struct LockstepRun<'a> {
    pub setup: Setup,
    pub seed: u64,
    pub steps: u32,
    pub domain: u16,
    /// Checkpoint every robot_node runs (`-p policy:=`); none: its scripted controller.
    pub policy: Option<&'a std::path::Path>,
    /// Extra robot_node parameters (`NAME:=VALUE`).
    pub robot_params: &'a [&'a str],
    /// Extra sim_bridge parameters, after the harness's own.
    pub bridge_params: &'a [&'a str],
    /// DDS Security from this keystore (enclaves `/tending/robot_<i>` and
    /// `/tending/sim_bridge`, as `tending security create` makes them).
    pub keystore: Option<&'a std::path::Path>,
    /// Scenario other than the default: the bridge reads it, and every robot_node gets its
    /// room (`room_size`) and observation bound (`nearest_*`).
    pub scenario: Option<&'a ScenarioConfig>,
}

impl<'a> LockstepRun<'a> {
    pub fn new(setup: Setup, seed: u64, steps: u32, domain: u16) -> Self {
        LockstepRun {
            setup,
            seed,
            steps,
            domain,
            policy: None,
            robot_params: &[],
            bridge_params: &[],
            keystore: None,
            scenario: None,
        }
    }

    /// Runs the fleet and asserts it reproduced the offline episode `off` exactly.
    pub fn assert_reproduces(&self, name: &str, off: &Offline) {
        let m = self.run();
        assert_same(name, off, &m, self.steps);
    }

    /// Runs the fleet; returns the bridge's final metrics line.
    pub fn run(&self) -> serde_json::Value {
        let LockstepRun {
            setup,
            seed,
            steps,
            domain,
            policy,
            robot_params: extra,
            bridge_params: bridge_extra,
            keystore,
            scenario,
        } = *self;
        let default_cfg = ScenarioConfig::default();
        let cfg = scenario.unwrap_or(&default_cfg);
        let env0 = Env::new(cfg.clone(), setup, seed).unwrap();
        let s = env0.sizes();
        let f = |x: f32| format!("{:?}", x as f64);
        let mut kids = Kill(Vec::new());
        // Robot logs go to files, printed when a robot went missing or the bridge timed out
        // waiting (a rare failure under load had nothing else to go on).
        let logs =
            std::env::temp_dir().join(format!("tending-lockstep-{}-{domain}", std::process::id()));
        std::fs::create_dir_all(&logs).unwrap();
        let log_of = |i: usize| logs.join(format!("robot_{i}.log"));
        for i in 0..setup.robots {
            let mut cmd = Command::new(robot_node_bin());
            cmd.env("ROS_DOMAIN_ID", domain.to_string())
                .args(["--ros-args", "-r", &format!("__ns:=/robot_{i}")])
                .args(["-p", "lockstep:=true"])
                .args(["-p", &format!("robot_radius:={}", f(s.robot_radius))])
                .args(["-p", &format!("machine_half_x:={}", f(s.machine_half[0]))])
                .args(["-p", &format!("machine_half_y:={}", f(s.machine_half[1]))])
                .args(["-p", &format!("storage_half_x:={}", f(s.storage_half[0]))])
                .args(["-p", &format!("storage_half_y:={}", f(s.storage_half[1]))])
                .args(["-p", "stale_timeout_s:=5.0"])
                .args([
                    "-p",
                    &format!("room_size:={}", f(env0.config().world.room_size)),
                ])
                .args(["--disable-rosout-logs"])
                .stdout(Stdio::null())
                .stderr(std::fs::File::create(log_of(i)).unwrap());
            if let Some(p) = policy {
                cmd.args(["-p", &format!("policy:={}", p.display())]);
            }
            let o = cfg.observation;
            for (name, k) in [
                ("nearest_machines", o.nearest_machines),
                ("nearest_storages", o.nearest_storages),
                ("nearest_peers", o.nearest_peers),
            ] {
                if let Some(k) = k {
                    cmd.args(["-p", &format!("{name}:={k}")]);
                }
            }
            for e in extra {
                cmd.args(["-p", e]);
            }
            if let Some(ks) = keystore {
                secure(&mut cmd, ks, &format!("/tending/robot_{i}"));
            }
            kids.0.push(cmd.spawn().unwrap());
        }
        let mut bridge = Command::new(env!("CARGO_BIN_EXE_sim_bridge"));
        bridge
            .env("ROS_DOMAIN_ID", domain.to_string())
            .args(["--ros-args", "-p", &format!("setup:={setup}")])
            .args(["-p", &format!("seed:={seed}"), "-p", "mode:=lockstep"])
            .args(["-p", &format!("max_steps:={steps}")])
            .args(["-p", "settle_s:=2.0", "-p", "lockstep_timeout_s:=3.0"])
            .args(["-p", "stale_timeout_s:=10.0", "--disable-rosout-logs"])
            .stdout(Stdio::piped())
            .stderr(std::fs::File::create(logs.join("sim_bridge.log")).unwrap());
        if let Some(ks) = keystore {
            // Authentication and key exchange between every pair of participants come first;
            // a handshake whose messages are lost under load is retried once a second, so
            // the first answers are waited for longer, as `tending fleet --secure` does.
            bridge.args(["-p", "settle_s:=8.0", "-p", "startup_grace_s:=30.0"]);
            secure(&mut bridge, ks, "/tending/sim_bridge");
        }
        if scenario.is_some() {
            let file = logs.join("scenario.toml");
            std::fs::write(&file, cfg.to_toml()).unwrap();
            bridge.args(["-p", &format!("config:={}", file.display())]);
        }
        for e in bridge_extra {
            bridge.args(["-p", e]);
        }
        let mut bridge = bridge.spawn().unwrap();
        let out = bridge.stdout.take().unwrap();
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                let _ = tx.send(line);
            }
        });
        let deadline = Instant::now() + Duration::from_secs(240);
        let mut last: Option<serde_json::Value> = None;
        loop {
            match rx.recv_timeout(Duration::from_millis(200)) {
                Ok(line) => {
                    if let Ok(v) = serde_json::from_str::<serde_json::Value>(&line) {
                        last = Some(v);
                    }
                }
                Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => break,
                Err(_) => {}
            }
            if Instant::now() > deadline {
                let _ = bridge.kill();
                drop(kids);
                print_logs(&logs, setup.robots);
                panic!("bridge did not finish {steps} steps in time; last metrics {last:?}");
            }
        }
        let status = bridge.wait().unwrap();
        drop(kids);
        if !status.success() {
            print_logs(&logs, setup.robots);
            panic!("sim_bridge exited with {status}; last metrics {last:?}");
        }
        let troubled = last
            .as_ref()
            .is_some_and(|m| m["despawned"] != 0 || m["lockstep_timeouts"] != 0);
        if troubled {
            print_logs(&logs, setup.robots);
        } else {
            let _ = std::fs::remove_dir_all(&logs);
        }
        last.expect("no metrics line from sim_bridge")
    }
}

/// The telling lines of the bridge's and every robot's log (a rare failure under load had
/// nothing else to go on); the directory is kept.
fn print_logs(logs: &std::path::Path, robots: usize) {
    // Lines every secure start-up logs many times; they hide the ones that tell.
    let noise = ["have incompatible security", "crypto tokens. Storing them"];
    let names =
        std::iter::once("sim_bridge".to_string()).chain((0..robots).map(|i| format!("robot_{i}")));
    for name in names {
        let text = std::fs::read_to_string(logs.join(format!("{name}.log"))).unwrap_or_default();
        let tail: Vec<&str> = text
            .lines()
            .filter(|l| !noise.iter().any(|n| l.contains(n)))
            .rev()
            .take(25)
            .collect();
        eprintln!("--- {name} log, last {} telling lines:", tail.len());
        for l in tail.iter().rev() {
            eprintln!("{l}");
        }
    }
    eprintln!("logs kept in {}", logs.display());
}

pub fn assert_same(name: &str, off: &Offline, m: &serde_json::Value, steps: u32) {
    eprintln!(
        "{name}: offline delivered {} collected {} collisions {} MU {:.4} | fleet {m}",
        off.delivered, off.collected, off.collisions, off.mu
    );
    assert_eq!(m["step"], steps, "{m}");
    assert_eq!(m["done"], true, "{m}");
    assert_eq!(m["lockstep_timeouts"], 0, "{m}");
    assert_eq!(m["cmds_late"], 0, "{m}");
    assert_eq!(m["parts_delivered"], off.delivered, "{m}");
    assert_eq!(m["parts_collected"], off.collected, "{m}");
    assert_eq!(m["collisions"], off.collisions, "{m}");
    let mu = m["mu"].as_f64().unwrap();
    assert!((mu - off.mu).abs() < 1e-12, "MU {mu} vs offline {}", off.mu);
}
