//! Shared helpers of the fault tests: processes that are killed when dropped, JSON lines
//! from a child's stdout, RSS, bag analysis, and security on or off.
//!
//! `TENDING_FAULTS_SECURE=1` runs every process of a fault test with DDS Security, each with
//! its own enclave from one keystore per test binary, enforced, as `tending fleet --secure`
//! runs them (the fleet-level tests pass `--secure`); every REPORT line says `"secure"`.
//! bench/faults/run.sh runs the suite both ways side by side.
#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

pub fn bin(name: &str) -> PathBuf {
    let p = PathBuf::from(env!("CARGO_BIN_EXE_sim_bridge"))
        .parent()
        .unwrap()
        .join(name);
    assert!(
        p.exists(),
        "{} not built: cargo build --release --bin tending -p robot-node -p sim-bridge",
        p.display()
    );
    p
}

pub fn wall_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64
}

pub fn sleep_s(s: f64) {
    std::thread::sleep(Duration::from_secs_f64(s));
}

/// A child process with its stdout lines collected; SIGKILLed when dropped.
pub struct Proc {
    pub name: String,
    pub child: Child,
    pub lines: Arc<Mutex<Vec<String>>>,
}

impl Proc {
    pub fn spawn(name: &str, mut cmd: Command) -> Proc {
        cmd.stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::null());
        let mut child = cmd
            .spawn()
            .unwrap_or_else(|e| panic!("starting {name}: {e}"));
        let out = child.stdout.take().unwrap();
        let lines = Arc::new(Mutex::new(Vec::new()));
        let l2 = lines.clone();
        std::thread::spawn(move || {
            for l in BufReader::new(out).lines().map_while(Result::ok) {
                l2.lock().unwrap().push(l);
            }
        });
        Proc {
            name: name.into(),
            child,
            lines,
        }
    }
    pub fn pid(&self) -> i32 {
        self.child.id() as i32
    }
    pub fn alive(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }
    pub fn signal(&self, sig: i32) {
        // SAFETY: kill(2) on our own, not yet reaped child
        unsafe {
            libc::kill(self.pid(), sig);
        }
    }
    /// SIGINT, wait up to `grace` for the exit; SIGKILL after. Returns true on a clean exit.
    pub fn stop(&mut self, grace: Duration) -> bool {
        if !self.alive() {
            return false;
        }
        self.signal(libc::SIGINT);
        let until = Instant::now() + grace;
        while Instant::now() < until {
            if let Ok(Some(s)) = self.child.try_wait() {
                // give the stdout reader a moment
                std::thread::sleep(Duration::from_millis(100));
                return s.success();
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
        false
    }
    /// The last stdout line that parses as a JSON object.
    pub fn last_json(&self) -> Option<serde_json::Value> {
        self.lines
            .lock()
            .unwrap()
            .iter()
            .rev()
            .find_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
            .filter(|v| v.is_object())
    }
    /// Resident set size in kB (from /proc).
    pub fn rss_kb(&self) -> u64 {
        rss_kb(self.pid())
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

pub fn rss_kb(pid: i32) -> u64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("VmRSS:"))
                .and_then(|v| v.split_whitespace().next()?.parse().ok())
        })
        .unwrap_or(0)
}

/// Sizes of a setup, as `tending fleet` passes them to every robot_node.
pub fn robot_size_args(setup: &str, seed: u64) -> Vec<String> {
    let cfg = sim::ScenarioConfig::default();
    let env = sim::Env::new(cfg.clone(), setup.parse().unwrap(), seed).unwrap();
    let s = *env.sizes();
    let f = |x: f32| format!("{:?}", x as f64);
    vec![
        format!("k_speed:={}", f(cfg.task.k_speed)),
        format!("robot_radius:={}", f(s.robot_radius)),
        format!("machine_half_x:={}", f(s.machine_half[0])),
        format!("machine_half_y:={}", f(s.machine_half[1])),
        format!("storage_half_x:={}", f(s.storage_half[0])),
        format!("storage_half_y:={}", f(s.storage_half[1])),
    ]
}

/// Whether this run of the fault tests has DDS Security on (`TENDING_FAULTS_SECURE=1`).
pub fn secure() -> bool {
    std::env::var("TENDING_FAULTS_SECURE").is_ok_and(|v| v == "1")
}

/// This test binary's keystore (created on first use in the temp directory).
pub fn fault_keystore() -> &'static keystore::Keystore {
    static KS: std::sync::OnceLock<keystore::Keystore> = std::sync::OnceLock::new();
    KS.get_or_init(|| {
        let root = std::env::temp_dir().join(format!("tending-faults-ks-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let ks = keystore::Keystore::create(&root).expect("creating the fault tests' keystore");
        let v = keystore::Validity::days_from_now(1);
        ks.create_enclave(keystore::BRIDGE_ENCLAVE, &keystore::Role::Bridge, v)
            .expect("the bridge's enclave");
        ks
    })
}

/// With security on: `c` runs with DDS Security enforced and `enclave` (created for
/// `role` if missing) in its keystore; the caller names the enclave on its command line.
/// Returns whether security is on.
pub fn security_env(c: &mut Command, enclave: &str, role: keystore::Role) -> bool {
    if !secure() {
        return false;
    }
    let ks = fault_keystore();
    if !ks.enclave_dir(enclave).join("permissions.p7s").is_file() {
        ks.create_enclave(enclave, &role, keystore::Validity::days_from_now(1))
            .unwrap_or_else(|e| panic!("enclave {enclave}: {e:#}"));
    }
    c.env("ROS_SECURITY_KEYSTORE", ks.root())
        .env("ROS_SECURITY_ENABLE", "true")
        .env("ROS_SECURITY_STRATEGY", "Enforce");
    true
}

/// [`security_env`] for a ROS 2 node, after its `--ros-args`: `--enclave ENCLAVE`.
fn with_enclave(c: &mut Command, enclave: &str, role: keystore::Role) {
    if security_env(c, enclave, role) {
        c.args(["--enclave", enclave]);
    }
}

/// A robot_node command for `name` on `domain` (stats as JSON lines every second).
pub fn robot_cmd(name: &str, domain: u16, setup: &str, extra: &[&str]) -> Command {
    let mut c = Command::new(bin("robot_node"));
    c.env("ROS_DOMAIN_ID", domain.to_string()).args([
        "--ros-args",
        "-r",
        &format!("__ns:=/{name}"),
    ]);
    with_enclave(
        &mut c,
        &keystore::robot_enclave(name),
        keystore::Role::Robots(vec![name.to_string()]),
    );
    c.args(["-p", "stale_timeout_s:=1.0", "-p", "stats_json:=true"])
        .args(["-p", "stats_period_s:=1.0"]);
    for a in robot_size_args(setup, 0) {
        c.args(["-p", &a]);
    }
    for e in extra {
        c.args(["-p", e]);
    }
    c
}

/// A realtime sim_bridge command.
pub fn bridge_cmd(domain: u16, setup: &str, extra: &[&str]) -> Command {
    let mut c = Command::new(bin("sim_bridge"));
    c.env("ROS_DOMAIN_ID", domain.to_string()).arg("--ros-args");
    with_enclave(&mut c, keystore::BRIDGE_ENCLAVE, keystore::Role::Bridge);
    // A secure handshake under load takes seconds (docs/bench/security.md): the bridge
    // waits for the robots as `tending fleet --secure` has it wait.
    if secure() {
        c.args(["-p", "startup_grace_s:=30.0"]);
    }
    c.args(["-p", &format!("setup:={setup}")]).args([
        "-p",
        "seed:=0",
        "-p",
        "stale_timeout_s:=2.0",
    ]);
    for e in extra {
        c.args(["-p", e]);
    }
    c
}

/// A numeric field of a JSON object (nested with `/`).
pub fn num(v: &serde_json::Value, path: &str) -> f64 {
    let mut x = v;
    for k in path.split('/') {
        x = &x[k];
    }
    x.as_f64().unwrap_or(f64::NAN)
}

/// Append one JSON line to `$TENDING_FAULTS_REPORT` (bench/faults/run.sh collects them),
/// with `"secure"`: whether DDS Security was on.
pub fn report(mut v: serde_json::Value) {
    if let Some(o) = v.as_object_mut() {
        o.insert("secure".into(), secure().into());
    }
    eprintln!("REPORT {v}");
    if let Ok(path) = std::env::var("TENDING_FAULTS_REPORT") {
        use std::io::Write;
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .unwrap();
        writeln!(f, "{v}").unwrap();
    }
}
