//! Secure interop with Eclipse Cyclone DDS 0.10 (Debian's packages, with the DDS Security
//! plugins; issue 38): a C peer (`tests/cyclone/cyclone_peer.c`, built by
//! `tests/cyclone/build.sh`, which installs the packages if they are missing) configured
//! the way rmw_cyclonedds configures an SROS2 enclave (participant properties naming the
//! enclave's six files), against our participants (`ros::context_with`, what every fleet
//! process uses) with enclaves that `keystore` (`tending security create`) made.
//!
//! - with robot_0's enclave, Cyclone creates its participant (it used to refuse our
//!   governance: "Can not parse governance file (code: 137)"), authenticates with the
//!   bridge's enclave (our log says so), reads the poses the bridge publishes on
//!   `rt/robot_0/pose` (every other one with a 3000-character frame_id, which RustDDS
//!   sends in encrypted fragments), and its `rt/robot_0/cmd_vel` reaches the bridge;
//! - a Cyclone participant without security reads nothing and commands nobody, while it
//!   reads an unsecured participant's topic on the same domain (the control);
//! - a Cyclone participant with robot_0's enclave from another keystore (another CA) is
//!   refused both ways: it reads nothing and its commands reach nobody; Cyclone refuses
//!   our bridge's certificate (its log says why) and our recorder refuses Cyclone's (our
//!   log says why). Which side of a pair checks the other's certificate first is fixed
//!   by their GUIDs, which come from the certificate subjects: the lower one sends the
//!   handshake request, the other checks it (sim_bridge a24ac186.. < robot_0
//!   b18719de.. < recorder f2770dff..).
//!
//! Debugging: `RUST_LOG=...` prints RustDDS's log instead of capturing it;
//! `CYCLONE_PEER_URI` replaces the peer's Cyclone configuration (e.g. a finest trace).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{mpsc, Mutex};
use std::time::{Duration, Instant};

use keystore::{Keystore, Validity};
use msgs::{PoseStamped, Profile, Twist};
use ros::{context_with, node::node, publisher, subscription, NodeSpec, Security};
use ros2_client::dds::{Context, Node};

/// Domains of their own (ros/tests/security.rs uses 201..=230 by process id).
fn domain(offset: u16) -> u16 {
    170 + (std::process::id() % 4) as u16 * 6 + offset
}

/// RustDDS's log lines (secure discovery at info, the rest at warn) of this test binary,
/// for the tests to show what our side refused.
static RUST_LOG_LINES: Mutex<Vec<String>> = Mutex::new(Vec::new());

struct Capture(Vec<u8>);

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

fn init_log() {
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
fn our_log(guid: &str, text: &str) -> Vec<String> {
    RUST_LOG_LINES
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .iter()
        .filter(|l| l.contains(guid) && l.contains(text))
        .cloned()
        .collect()
}

/// The Cyclone peer, built (once per test binary) into target/cyclone.
fn cyclone_peer() -> PathBuf {
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

fn keystore(name: &str) -> (PathBuf, Keystore) {
    let root = std::env::temp_dir().join(format!("tending-cyclone-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let ks = Keystore::create(&root).unwrap();
    ks.create_fleet_enclaves(
        &["robot_0".into(), "robot_1".into()],
        Validity::days_from_now(1),
    )
    .unwrap();
    (root, ks)
}

fn enclave(ks: &Keystore, name: &str) -> Security {
    Security::Enclave {
        enclave: name.into(),
        dir: ks.enclave_dir(name),
    }
}

fn participant(domain: u16, sec: &Security, name: &str) -> (Context, Node) {
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

fn pose(x: f64) -> PoseStamped {
    let mut p = PoseStamped::default();
    p.pose.position.x = x;
    p
}

/// What the Cyclone peer reported.
#[derive(Debug, Default)]
struct PeerResult {
    /// Its participant's GUID prefix (24 hex digits, as RustDDS logs it).
    guid: String,
    /// `result refused=...`: the entity Cyclone refused to create.
    refused: Option<String>,
    read: u64,
    /// Samples of the control topic (`--read2`).
    read2: u64,
    /// Poses read with a frame_id of 1024 characters or more.
    big: u64,
    wrote: u64,
    last_x: f64,
    matched_pub: u64,
    matched_sub: u64,
    /// Everything it printed (stdout, then Cyclone's log from stderr).
    log: String,
    /// Cyclone's log alone (stderr).
    cyclone_log: String,
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
struct PeerRun<'a> {
    domain: u16,
    /// The robot whose pose it reads and whose `cmd_vel` it writes (`robot_0`).
    robot: &'a str,
    /// The enclave directory it is configured from; `None`: no security.
    enclave: Option<&'a Path>,
    /// Its `cmd_vel` (linear x).
    vx: f64,
    /// At most this long; stop earlier after `until` poses (with its writer matched).
    secs: f64,
    until: Option<u32>,
    /// A control topic it also reads.
    read2: Option<&'a str>,
}

/// Start the Cyclone peer reading a robot's pose and commanding it; its result arrives
/// on the returned channel.
fn spawn_peer(run: PeerRun) -> mpsc::Receiver<PeerResult> {
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
struct BridgeSide {
    /// Linear x of every command.
    cmds: Vec<f64>,
}

/// The bridge's side while a Cyclone peer runs: publish `robot`'s pose (x = 1.5) every
/// 50 ms, every other one with a 3000-character frame_id (a sample sent in fragments),
/// and take `robot`'s commands, until the peer reports; `also` runs every tick
/// (controls).
fn bridge_with_peer(
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

/// Cyclone with `robot`'s enclave reads the bridge's poses of `robot` and commands it.
fn cyclone_robot_talks_to_the_bridge(name: &str, d: u16, robot: &str) {
    let (root, ks) = keystore(name);
    let (_bc, mut bridge) = participant(d, &enclave(&ks, keystore::BRIDGE_ENCLAVE), "sim_bridge");
    let dir = ks.enclave_dir(&keystore::robot_enclave(robot));
    let peer = spawn_peer(PeerRun {
        domain: d,
        robot,
        enclave: Some(&dir),
        vx: 0.25,
        secs: 40.0,
        until: Some(20),
        read2: None,
    });
    let (r, b) = bridge_with_peer(&mut bridge, robot, peer, || ());
    assert!(
        r.refused.is_none(),
        "Cyclone refused our enclave:\n{}",
        r.log
    );
    assert!(r.read >= 20, "Cyclone read {} poses:\n{}", r.read, r.log);
    assert!(
        r.big >= 5,
        "Cyclone read {} fragmented poses:\n{}",
        r.big,
        r.log
    );
    assert_eq!(r.last_x, 1.5, "Cyclone read a wrong pose");
    assert!(
        b.cmds.len() >= 10,
        "the bridge got {} of Cyclone's commands:\n{}",
        b.cmds.len(),
        r.log
    );
    assert!(b.cmds.iter().all(|&x| x == 0.25), "{:?}", b.cmds);
    // The bridge authenticated it as an ordinary peer.
    let ok = our_log(&r.guid, "Authenticated successfully");
    assert!(!ok.is_empty(), "no authentication of {} in our log", r.guid);
    std::fs::remove_dir_all(root).unwrap();
}

/// robot_0's GUID (from its certificate's subject) is above the bridge's, so the bridge
/// sends the handshake request and Cyclone replies.
#[test]
fn a_cyclone_peer_with_a_robot_enclave_reads_the_pose_and_commands_the_robot() {
    cyclone_robot_talks_to_the_bridge("peer", domain(0), "robot_0");
}

/// robot_1's GUID is below the bridge's: Cyclone sends the request and the bridge
/// replies with its certificate and permissions, a ~4.7 kB sample sent in fragments
/// whose size ends on the ECDSA signature's 70-72 bytes. Before rustdds patch 0019 the
/// final fragment was not padded to 4 bytes, Cyclone refused it as malformed in most
/// runs, and the two never authenticated.
#[test]
fn a_cyclone_peer_that_sends_the_handshake_request_authenticates_too() {
    cyclone_robot_talks_to_the_bridge("request", domain(3), "robot_1");
}

/// A Cyclone participant without security, beside the secure bridge and robot_0, and
/// beside an unsecured Rust participant publishing `/robot_9/pose` (the control: it
/// reads that one, so it is on the domain and discovery works).
#[test]
fn an_unauthenticated_cyclone_participant_reads_nothing_and_commands_nobody() {
    let (root, ks) = keystore("open");
    let d = domain(1);
    let (_bc, mut bridge) = participant(d, &enclave(&ks, keystore::BRIDGE_ENCLAVE), "sim_bridge");
    let (_rc, mut robot) = participant(d, &enclave(&ks, "/tending/robot_0"), "robot_node");
    let (_oc, mut open) = participant(d, &Security::Off, "open");
    let robot_pose =
        subscription::<PoseStamped>(&mut robot, "/robot_0/pose", Profile::RobotStream).unwrap();
    let robot_cmd =
        publisher::<Twist>(&mut robot, "/robot_0/cmd_vel", Profile::RobotStream).unwrap();
    let open_pub =
        publisher::<PoseStamped>(&mut open, "/robot_9/pose", Profile::RobotStream).unwrap();
    let mut robot_got = 0;
    let peer = spawn_peer(PeerRun {
        domain: d,
        robot: "robot_0",
        enclave: None,
        vx: -9.0,
        secs: 10.0,
        until: None,
        read2: Some("rt/robot_9/pose"),
    });
    let (r, b) = bridge_with_peer(&mut bridge, "robot_0", peer, || {
        let _ = open_pub.publish(pose(9.0));
        let _ = robot_cmd.publish(Twist::planar(0.1, 0.0));
        while let Ok(Some(_)) = robot_pose.take() {
            robot_got += 1;
        }
    });
    assert!(r.refused.is_none(), "{}", r.log);
    assert!(
        r.read2 > 0,
        "control: Cyclone read no unsecured poses either:\n{}",
        r.log
    );
    assert!(robot_got > 0, "control: robot_0 (secure) read no poses");
    assert!(
        b.cmds.contains(&0.1),
        "control: no command of robot_0 reached the bridge"
    );
    assert_eq!(
        r.read, 0,
        "an unauthenticated Cyclone participant read poses"
    );
    assert_eq!(r.matched_sub + r.matched_pub, 0, "it was matched: {r:?}");
    assert!(
        !b.cmds.contains(&-9.0),
        "an unauthenticated Cyclone participant commanded robot_0"
    );
    std::fs::remove_dir_all(root).unwrap();
}

/// robot_0's enclave from another keystore (another CA, everything signed by it): a
/// valid identity that our fleet does not trust, and that does not trust ours.
#[test]
fn a_cyclone_peer_with_another_cas_certificate_is_refused_both_ways() {
    let (root, ks) = keystore("ca");
    let (root2, other) = keystore("other-ca");
    let d = domain(2);
    let (_bc, mut bridge) = participant(d, &enclave(&ks, keystore::BRIDGE_ENCLAVE), "sim_bridge");
    // Control: our robot_0 meanwhile reads the bridge's poses and commands robot_0.
    let (_rc, mut robot) = participant(d, &enclave(&ks, "/tending/robot_0"), "robot_node");
    // Our recorder, whose GUID is above Cyclone's, checks Cyclone's certificate (and
    // reads the poses too, a second control).
    let (_cc, mut recorder) = participant(d, &enclave(&ks, keystore::RECORDER_ENCLAVE), "recorder");
    let recorder_pose =
        subscription::<PoseStamped>(&mut recorder, "/robot_0/pose", Profile::RobotStream).unwrap();
    let mut recorder_got = 0;
    let robot_pose =
        subscription::<PoseStamped>(&mut robot, "/robot_0/pose", Profile::RobotStream).unwrap();
    let robot_cmd =
        publisher::<Twist>(&mut robot, "/robot_0/cmd_vel", Profile::RobotStream).unwrap();
    let mut robot_got = 0;
    let dir = other.enclave_dir("/tending/robot_0");
    let peer = spawn_peer(PeerRun {
        domain: d,
        robot: "robot_0",
        enclave: Some(&dir),
        vx: -9.0,
        secs: 10.0,
        until: None,
        read2: None,
    });
    let (r, b) = bridge_with_peer(&mut bridge, "robot_0", peer, || {
        let _ = robot_cmd.publish(Twist::planar(0.1, 0.0));
        while let Ok(Some(_)) = robot_pose.take() {
            robot_got += 1;
        }
        while let Ok(Some(_)) = recorder_pose.take() {
            recorder_got += 1;
        }
    });
    assert!(r.refused.is_none(), "its own enclave is valid:\n{}", r.log);
    assert!(robot_got > 0, "control: robot_0 read no poses");
    assert!(recorder_got > 0, "control: the recorder read no poses");
    assert!(
        b.cmds.contains(&0.1),
        "control: no command of robot_0 reached the bridge"
    );
    assert_eq!(r.read, 0, "a Cyclone peer of another CA read poses");
    assert!(
        !b.cmds.contains(&-9.0),
        "a Cyclone peer of another CA commanded robot_0"
    );
    // Our side: the recorder refused its certificate.
    let ours = our_log(&r.guid, "Replying to a handshake request failed");
    assert!(
        !ours.is_empty(),
        "no refusal of {} in our log:\n{}",
        r.guid,
        r.log
    );
    eprintln!(
        "our side refused it {} times, e.g.: {}",
        ours.len(),
        ours[0]
    );
    // Cyclone's side: it refused our bridge's certificate.
    let theirs: Vec<&str> = r
        .cyclone_log
        .lines()
        // e.g. "Begin handshake reply failed: Certificate not valid: error: unable to get
        // local issuer certificate; subject: /CN=\/tending\/sim_bridge(code: 200)"
        .filter(|l| l.contains("handshake") && l.contains("failed") && l.contains("sim_bridge"))
        .collect();
    assert!(
        !theirs.is_empty(),
        "no refusal in Cyclone's log:\n{}",
        r.cyclone_log
    );
    eprintln!(
        "Cyclone refused {} times, e.g.: {}",
        theirs.len(),
        theirs[0]
    );
    std::fs::remove_dir_all(root).unwrap();
    std::fs::remove_dir_all(root2).unwrap();
}
