//! The Cyclone DDS test peer and the Rust side around it, shared by ros/tests/cyclone.rs
//! (interop) and ros/tests/cyclone_refusals.rs (both sides refuse the same bad
//! documents). See cyclone.rs for what the peer is and how it is configured.
#![allow(dead_code)] // each test binary uses its own part

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{mpsc, Mutex};
use std::time::{Duration, Instant};

use keystore::Keystore;
use msgs::{PoseStamped, Profile, Twist};
use ros::{context_with, node::node, publisher, subscription, NodeSpec, Security};
use ros2_client::dds::{Context, Node};

/// RustDDS's log lines (secure discovery at info, the rest at warn) of this test binary,
/// for the tests to show what our side refused.
pub static RUST_LOG_LINES: Mutex<Vec<String>> = Mutex::new(Vec::new());

pub struct Capture(Vec<u8>);

impl std::io::Write for Capture {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Drop for Capture {
    fn drop(&mut self) {
        let text = String::from_utf8_lossy(&self.0);
        let mut lines = RUST_LOG_LINES.lock().unwrap_or_else(|e| e.into_inner());
        lines.extend(text.lines().map(str::to_string));
    }
}

pub fn init_log() {
    static LOG: std::sync::Once = std::sync::Once::new();
    LOG.call_once(|| {
        if std::env::var_os("RUST_LOG").is_some() {
            ros::process::init_tracing(None);
        } else {
            tracing_subscriber::fmt()
                .with_env_filter(tracing_subscriber::EnvFilter::new(
                    "warn,rustdds::discovery::secure_discovery=info",
                ))
                .with_ansi(false)
                .with_writer(|| Capture(Vec::new()))
                .init();
        }
    });
}

/// Our log lines that name the participant with GUID prefix `guid` (24 hex digits) and
/// contain `text`.
pub fn our_log(guid: &str, text: &str) -> Vec<String> {
    RUST_LOG_LINES
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .iter()
        .filter(|l| l.contains(guid) && l.contains(text))
        .cloned()
        .collect()
}

/// The Cyclone peer, built (once per test binary) into target/cyclone.
pub fn cyclone_peer() -> PathBuf {
    static BIN: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    BIN.get_or_init(|| {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let out = std::env::var_os("CARGO_TARGET_DIR")
            .map(PathBuf::from)
            .unwrap_or_else(|| root.join("target"))
            .join("cyclone");
        let o = Command::new("bash")
            .arg(root.join("tests/cyclone/build.sh"))
            .arg(&out)
            .stderr(Stdio::inherit())
            .output()
            .expect("run tests/cyclone/build.sh");
        assert!(
            o.status.success(),
            "tests/cyclone/build.sh failed (Cyclone DDS: apt-get install -y libddsc0debian \
             cyclonedds-dev cyclonedds-tools)"
        );
        PathBuf::from(String::from_utf8(o.stdout).unwrap().trim())
    })
    .clone()
}

pub fn keystore(name: &str) -> (PathBuf, Keystore) {
    crate::keystores::fleet("cyclone", name)
}

pub fn enclave(ks: &Keystore, name: &str) -> Security {
    Security::Enclave {
        enclave: name.into(),
        dir: ks.enclave_dir(name),
    }
}

pub fn participant(domain: u16, sec: &Security, name: &str) -> (Context, Node) {
    init_log();
    let ctx = context_with(domain, sec).unwrap_or_else(|e| panic!("{name}: {e:#}"));
    let spec = NodeSpec {
        namespace: "/",
        name,
        enable_rosout: false,
    };
    let n = node(&ctx, &spec).unwrap();
    (ctx, n)
}

pub fn pose(x: f64) -> PoseStamped {
    let mut p = PoseStamped::default();
    p.pose.position.x = x;
    p
}

/// What the Cyclone peer reported.
#[derive(Debug, Default)]
pub struct PeerResult {
    /// Its participant's GUID prefix (24 hex digits, as RustDDS logs it).
    pub guid: String,
    /// `result refused=...`: the entity Cyclone refused to create.
    pub refused: Option<String>,
    pub read: u64,
    /// Samples of the control topic (`--read2`).
    pub read2: u64,
    /// Poses read with a frame_id of 1024 characters or more.
    pub big: u64,
    pub wrote: u64,
    pub last_x: f64,
    pub matched_pub: u64,
    pub matched_sub: u64,
    /// Everything it printed (stdout, then Cyclone's log from stderr).
    pub log: String,
    /// Cyclone's log alone (stderr).
    pub cyclone_log: String,
}

impl PeerResult {
    fn parse(stdout: &str, stderr: &str) -> Self {
        let mut r = PeerResult {
            log: format!("{stdout}{stderr}"),
            cyclone_log: stderr.to_string(),
            ..Default::default()
        };
        if let Some(g) = stdout.lines().find_map(|l| l.strip_prefix("guid=")) {
            r.guid = g.trim().to_string();
        }
        let last = stdout
            .lines()
            .rev()
            .find(|l| l.starts_with("result "))
            .unwrap_or_else(|| panic!("the Cyclone peer printed no result:\n{}", r.log));
        for kv in last["result ".len()..].split_whitespace() {
            let (k, v) = kv.split_once('=').unwrap();
            match k {
                "refused" => r.refused = Some(v.to_string()),
                "read" => r.read = v.parse().unwrap(),
                "read2" => r.read2 = v.parse().unwrap(),
                "big" => r.big = v.parse().unwrap(),
                "wrote" => r.wrote = v.parse().unwrap(),
                "last_x" => r.last_x = v.parse().unwrap(),
                "matched_pub" => r.matched_pub = v.parse().unwrap(),
                "matched_sub" => r.matched_sub = v.parse().unwrap(),
                _ => {}
            }
        }
        r
    }
}

/// How the Cyclone peer runs.
pub struct PeerRun<'a> {
    pub domain: u16,
    /// The robot whose pose it reads and whose `cmd_vel` it writes (`robot_0`).
    pub robot: &'a str,
    /// The enclave directory it is configured from; `None`: no security.
    pub enclave: Option<&'a Path>,
    /// Its `cmd_vel` (linear x).
    pub vx: f64,
    /// At most this long; stop earlier after `until` poses (with its writer matched).
    pub secs: f64,
    pub until: Option<u32>,
    /// A control topic it also reads.
    pub read2: Option<&'a str>,
}

/// Start the Cyclone peer reading a robot's pose and commanding it; its result arrives
/// on the returned channel.
pub fn spawn_peer(run: PeerRun) -> mpsc::Receiver<PeerResult> {
    let mut cmd = Command::new(cyclone_peer());
    let (pose, cmd_vel) = (
        format!("rt/{}/pose", run.robot),
        format!("rt/{}/cmd_vel", run.robot),
    );
    cmd.args(["--domain", &run.domain.to_string()])
        .args(["--read", &pose, "--write", &cmd_vel])
        .args([
            "--vx",
            &run.vx.to_string(),
            "--seconds",
            &run.secs.to_string(),
        ]);
    if let Some(n) = run.until {
        cmd.args(["--until", &n.to_string()]);
    }
    if let Some(t) = run.read2 {
        cmd.args(["--read2", t]);
    }
    if let Some(dir) = run.enclave {
        cmd.arg("--enclave").arg(dir);
    }
    // Cyclone's own log (warnings: refused handshakes and permissions) on stderr.
    cmd.env(
        "CYCLONEDDS_URI",
        std::env::var("CYCLONE_PEER_URI").unwrap_or_else(|_| {
            "<Tracing><Verbosity>warning</Verbosity><OutputFile>stderr</OutputFile></Tracing>"
                .into()
        }),
    );
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the Cyclone peer");
    let (tx, rx) = mpsc::channel();
    let stdout = child.stdout.take().unwrap();
    let stderr = child.stderr.take().unwrap();
    std::thread::spawn(move || {
        let err = std::thread::spawn(move || {
            let mut s = String::new();
            for l in BufReader::new(stderr).lines().map_while(Result::ok) {
                s.push_str(&l);
                s.push('\n');
            }
            s
        });
        let mut out = String::new();
        for l in BufReader::new(stdout).lines().map_while(Result::ok) {
            out.push_str(&l);
            out.push('\n');
        }
        let _ = child.wait();
        let err = err.join().unwrap_or_default();
        let _ = tx.send(PeerResult::parse(&out, &err));
    });
    rx
}

/// What the bridge received from the robot's `cmd_vel` while the peer ran.
pub struct BridgeSide {
    /// Linear x of every command.
    pub cmds: Vec<f64>,
}

/// The bridge's side while a Cyclone peer runs: publish `robot`'s pose (x = 1.5) every
/// 50 ms, every other one with a 3000-character frame_id (a sample sent in fragments),
/// and take `robot`'s commands, until the peer reports; `also` runs every tick
/// (controls).
pub fn bridge_with_peer(
    bridge: &mut Node,
    robot: &str,
    peer: mpsc::Receiver<PeerResult>,
    mut also: impl FnMut(),
) -> (PeerResult, BridgeSide) {
    let pose_pub =
        publisher::<PoseStamped>(bridge, &format!("/{robot}/pose"), Profile::RobotStream).unwrap();
    let cmd_sub =
        subscription::<Twist>(bridge, &format!("/{robot}/cmd_vel"), Profile::RobotStream).unwrap();
    let mut cmds = Vec::new();
    let t0 = Instant::now();
    let mut big = pose(1.5);
    big.header.frame_id = "f".repeat(3000);
    for tick in 0.. {
        let _ = pose_pub.publish(if tick % 2 == 1 {
            big.clone()
        } else {
            pose(1.5)
        });
        also();
        std::thread::sleep(Duration::from_millis(50));
        while let Ok(Some((m, _))) = cmd_sub.take() {
            cmds.push(m.linear.x);
        }
        if let Ok(r) = peer.try_recv() {
            eprintln!(
                "cyclone {}: read {} poses ({} fragmented, last x {}), {} of the control, wrote \
                 {}; the bridge got {} commands",
                r.guid,
                r.read,
                r.big,
                r.last_x,
                r.read2,
                r.wrote,
                cmds.len()
            );
            return (r, BridgeSide { cmds });
        }
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "the Cyclone peer did not finish"
        );
    }
    unreachable!()
}

/// The peer (`who`, writing -9.0) was kept out while a control of ours commanded 0.1: the
/// control's commands reached the bridge, the peer read no pose and none of its commands
/// arrived, and our log names its GUID with `our_refusal`. Returns those log lines.
pub fn kept_out(r: &PeerResult, b: &BridgeSide, who: &str, our_refusal: &str) -> Vec<String> {
    assert!(
        b.cmds.contains(&0.1),
        "control: no command of ours reached the bridge"
    );
    assert_eq!(r.read, 0, "{who} read poses");
    assert!(!b.cmds.contains(&-9.0), "{who} commanded the robot");
    let ours = our_log(&r.guid, our_refusal);
    assert!(
        !ours.is_empty(),
        "no refusal of {} in our log:\n{}",
        r.guid,
        r.log
    );
    ours
}
