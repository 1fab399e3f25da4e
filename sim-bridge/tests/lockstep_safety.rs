//! Lockstep reproducibility of the safety controllers (docs/adr/0006): a fleet of
//! `robot_node`s running greedy-ORCA (`controller:=greedy-orca`, stateful: it estimates
//! velocities from successive observations) or the bundled policy behind the action shield
//! (`shield:=true`) or through the ORCA filter (`orca_filter:=true`) must reproduce the
//! offline episode of the same code exactly.
//! The harness is lockstep_repro.rs's, with extra robot_node parameters.
//!
//! Needs the `robot_node` binary next to `sim_bridge` (build both:
//! `cargo test --release -p sim-bridge -p robot-node`).

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use sim::{Env, ScenarioConfig, Setup};

fn bin_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_sim_bridge"))
        .parent()
        .unwrap()
        .to_path_buf()
}

fn robot_node_bin() -> PathBuf {
    let p = bin_dir().join("robot_node");
    assert!(
        p.exists(),
        "{} not built: run `cargo build --release -p robot-node` (or test -p robot-node too)",
        p.display()
    );
    p
}

struct Offline {
    delivered: u32,
    collected: u32,
    collisions: u32,
    mu: f64,
}

fn offline(env: &Env) -> Offline {
    let m = env.metrics();
    Offline {
        delivered: m.parts_delivered,
        collected: m.parts_collected,
        collisions: m.collisions,
        mu: m.utilization(),
    }
}

fn offline_greedy_orca(setup: Setup, seed: u64, steps: u32) -> (Offline, Env) {
    let mut env = Env::new(ScenarioConfig::default(), setup, seed).unwrap();
    let first = env.clone();
    let mut fleet = sim::baselines::GreedyOrcaFleet::new(&env).unwrap();
    let (mut batch, mut vels) = (obs::ObsBatch::default(), Vec::new());
    for _ in 0..steps {
        env.observe(&mut batch);
        fleet.act(&batch, &mut vels).unwrap();
        env.step_velocities(&vels).unwrap();
    }
    (offline(&env), first)
}

fn offline_filtered(setup: Setup, seed: u64, steps: u32, path: &std::path::Path) -> Offline {
    let mut env = Env::new(ScenarioConfig::default(), setup, seed).unwrap();
    let mut fleet = sim::baselines::GreedyOrcaFleet::new(&env).unwrap();
    let k = env.config().task.k_speed;
    let mut pol = policy::Policy::load(path).unwrap();
    let mut states: Vec<_> = (0..env.n_robots()).map(|_| pol.new_state()).collect();
    let (mut batch, mut vels) = (obs::ObsBatch::default(), Vec::new());
    for _ in 0..steps {
        env.observe(&mut batch);
        let prefs: Vec<[f32; 2]> = (0..batch.rows)
            .map(|r| {
                let a = pol
                    .act(&batch.row(r), &mut states[r], policy::ActMode::Greedy)
                    .unwrap();
                sim::action_to_velocity(a, k).unwrap()
            })
            .collect();
        fleet.filter(&batch, &prefs, &mut vels).unwrap();
        env.step_velocities(&vels).unwrap();
    }
    offline(&env)
}

fn offline_shielded(setup: Setup, seed: u64, steps: u32, path: &std::path::Path) -> Offline {
    let mut env = Env::new(ScenarioConfig::default(), setup, seed).unwrap();
    let sp = sim::baselines::shield_params(env.sizes(), env.config());
    let mut pol = policy::Policy::load(path).unwrap();
    let mut states: Vec<_> = (0..env.n_robots()).map(|_| pol.new_state()).collect();
    let mut batch = obs::ObsBatch::default();
    for _ in 0..steps {
        env.observe(&mut batch);
        let acts: Vec<u8> = (0..batch.rows)
            .map(|r| {
                let row = batch.row(r);
                let mut l = [0.0f32; 5];
                l.copy_from_slice(pol.logits(&row, &mut states[r]).unwrap());
                let safe = obs::shield::safe_actions(
                    row.own_row(0),
                    row.machines_row(0),
                    row.storages_row(0),
                    row.peers_row(0),
                    &sp,
                );
                obs::shield::mask_logits(&mut l, &safe);
                policy::nn::categorical::argmax(&l) as u8
            })
            .collect();
        env.step_actions(&acts).unwrap();
    }
    offline(&env)
}

struct Kill(Vec<Child>);
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

/// Run the fleet in lockstep; returns the bridge's final metrics line.
fn fleet_lockstep(
    setup: Setup,
    seed: u64,
    steps: u32,
    domain: u16,
    env0: &Env,
    policy: Option<&std::path::Path>,
    extra: &[&str],
) -> serde_json::Value {
    let s = env0.sizes();
    let f = |x: f32| format!("{:?}", x as f64);
    let mut kids = Kill(Vec::new());
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
            .args(["--disable-rosout-logs"])
            .stdout(Stdio::null())
            .stderr(Stdio::null());
        if let Some(p) = policy {
            cmd.args(["-p", &format!("policy:={}", p.display())]);
        }
        for e in extra {
            cmd.args(["-p", e]);
        }
        kids.0.push(cmd.spawn().unwrap());
    }
    let mut bridge = Command::new(env!("CARGO_BIN_EXE_sim_bridge"))
        .env("ROS_DOMAIN_ID", domain.to_string())
        .args(["--ros-args", "-p", &format!("setup:={setup}")])
        .args(["-p", &format!("seed:={seed}"), "-p", "mode:=lockstep"])
        .args(["-p", &format!("max_steps:={steps}")])
        .args(["-p", "settle_s:=2.0", "-p", "lockstep_timeout_s:=3.0"])
        .args(["-p", "stale_timeout_s:=10.0", "--disable-rosout-logs"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
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
            panic!("bridge did not finish {steps} steps in time; last metrics {last:?}");
        }
    }
    let status = bridge.wait().unwrap();
    assert!(status.success(), "sim_bridge exited with {status}");
    drop(kids);
    last.expect("no metrics line from sim_bridge")
}

fn assert_same(name: &str, off: &Offline, m: &serde_json::Value, steps: u32) {
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

fn domain(offset: u16) -> u16 {
    (std::process::id() % 50) as u16 * 2 + 120 + offset
}

#[test]
fn greedy_orca_fleet_in_lockstep_reproduces_the_offline_episode() {
    let setup = Setup::new(6, 4, 2);
    let (seed, steps) = (3, 200);
    let (off, env0) = offline_greedy_orca(setup, seed, steps);
    assert!(
        off.delivered > 0,
        "choose a seed where greedy-orca delivers"
    );
    let m = fleet_lockstep(
        setup,
        seed,
        steps,
        domain(0),
        &env0,
        None,
        &["controller:=greedy-orca"],
    );
    assert_same("greedy-orca", &off, &m, steps);
}

#[test]
fn shielded_policy_fleet_in_lockstep_reproduces_the_offline_episode() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../policy/pretrained/smappo_6.4_2.safetensors");
    if !path.exists() {
        eprintln!("SKIPPED: no bundled checkpoint at {}", path.display());
        return;
    }
    let setup = Setup::new(6, 4, 2);
    let (seed, steps) = (0, 200);
    let off = offline_shielded(setup, seed, steps, &path);
    let env0 = Env::new(ScenarioConfig::default(), setup, seed).unwrap();
    let m = fleet_lockstep(
        setup,
        seed,
        steps,
        domain(1),
        &env0,
        Some(&path),
        &["shield:=true"],
    );
    assert_same("policy+shield", &off, &m, steps);
}

#[test]
fn orca_filtered_policy_fleet_in_lockstep_reproduces_the_offline_episode() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../policy/pretrained/smappo_6.4_2.safetensors");
    if !path.exists() {
        eprintln!("SKIPPED: no bundled checkpoint at {}", path.display());
        return;
    }
    let setup = Setup::new(6, 4, 2);
    let (seed, steps) = (1, 200);
    let off = offline_filtered(setup, seed, steps, &path);
    let env0 = Env::new(ScenarioConfig::default(), setup, seed).unwrap();
    let m = fleet_lockstep(
        setup,
        seed,
        steps,
        domain(2),
        &env0,
        Some(&path),
        &["orca_filter:=true"],
    );
    assert_same("policy+orca", &off, &m, steps);
}
