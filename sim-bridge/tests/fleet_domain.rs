//! One fleet per ROS domain (issue 38, docs/adr/0032-one-fleet-per-domain.md), end to end
//! with the `tending` binary. This test's own participant plays the other fleet: a node
//! named `sim_bridge` and one named `robot_node` in `/robot_0` (what `ros2 node list` shows
//! of a running fleet), writing `/robot_0/cmd_vel`.
//! - On its domain `tending fleet` refuses to start, naming the domain, the nodes it saw
//!   and how to pick a free domain.
//! - `--domain auto` moves to the next free domain and says so.
//! - A fleet whose robot receives cmd_vel from a second writer once it runs (the other
//!   fleet arrived later, past the check) ends with an error and exit 1, although its
//!   bridge refused those commands.
//!
//! Needs `tending`, `sim_bridge` and `robot_node` in the same target directory.

use std::path::PathBuf;
use std::process::{Command, Output};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use msgs::{Profile, RosMessage, Twist};
use ros2_client::{Context, ContextOptions, Name, Node, NodeName, NodeOptions, Publisher};

fn tending() -> PathBuf {
    let p = PathBuf::from(env!("CARGO_BIN_EXE_sim_bridge"))
        .parent()
        .unwrap()
        .join("tending");
    assert!(p.exists(), "{} not built", p.display());
    p
}

/// A stand-in for another fleet on `domain`: its bridge's and a robot's nodes, and a
/// cmd_vel writer for that robot.
struct OtherFleet {
    _ctx: Context,
    _nodes: Vec<Node>,
    cmd: Publisher<Twist>,
}

impl OtherFleet {
    fn start(domain: u16) -> Self {
        let ctx = Context::with_options(ContextOptions::new().domain_id(domain)).unwrap();
        let node = |ns: &str, name: &str| {
            ctx.new_node(
                NodeName::new(ns, name).unwrap(),
                NodeOptions::new().enable_rosout(false),
            )
            .unwrap()
        };
        let bridge = node("/", "sim_bridge");
        let mut robot = node("/robot_0", "robot_node");
        let qos = Profile::RobotStream.qos();
        let t = robot
            .create_topic(
                &Name::parse("/robot_0/cmd_vel").unwrap(),
                Twist::type_name(),
                &qos,
            )
            .unwrap();
        let cmd = robot.create_publisher(&t, Some(qos)).unwrap();
        OtherFleet {
            _ctx: ctx,
            _nodes: vec![bridge, robot],
            cmd,
        }
    }
}

fn fleet(args: &[&str], env_domain: Option<u16>) -> Output {
    let mut c = Command::new(tending());
    c.arg("fleet").args(args).arg("--no-stdin");
    if let Some(d) = env_domain {
        c.env("ROS_DOMAIN_ID", d.to_string());
    }
    c.output().unwrap()
}

fn text(o: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&o.stdout).to_string(),
        String::from_utf8_lossy(&o.stderr).to_string(),
    )
}

#[test]
fn a_domain_with_another_fleet_on_it_is_refused() {
    let d = test_domains::domain(0);
    let _other = OtherFleet::start(d);
    std::thread::sleep(Duration::from_secs(1));
    let t0 = std::time::Instant::now();
    let o = fleet(
        &[
            "--setup",
            "2.2_1",
            "--duration",
            "10",
            "--domain",
            &d.to_string(),
        ],
        None,
    );
    let (out, err) = text(&o);
    assert_eq!(o.status.code(), Some(1), "{out}\n{err}");
    assert!(
        t0.elapsed() < Duration::from_secs(8),
        "refused only after the run"
    );
    for want in [
        format!("ROS domain {d} already has a fleet on it"),
        "/sim_bridge".into(),
        "/robot_0/robot_node".into(),
        "/robot_0/cmd_vel".into(),
        "--domain N (or ROS_DOMAIN_ID=N".into(),
        "--domain auto".into(),
    ] {
        assert!(err.contains(&want), "no `{want}` in:\n{err}");
    }
    // nothing was started
    assert!(!err.contains("robot_node processes"), "{err}");
}

#[test]
fn domain_auto_moves_to_the_next_free_domain_and_says_so() {
    let d = test_domains::domain(2);
    let _other = OtherFleet::start(d);
    std::thread::sleep(Duration::from_secs(1));
    let o = fleet(
        &["--setup", "2.2_1", "--duration", "6", "--domain", "auto"],
        Some(d),
    );
    let (out, err) = text(&o);
    assert!(o.status.success(), "{out}\n{err}");
    let next = d + 1;
    for want in [
        format!("--domain auto: ROS domain {d} is in use: nodes"),
        format!("ROS domain {next} is free: this fleet runs on ROS_DOMAIN_ID={next}"),
        format!("domain {next}, controller"),
    ] {
        assert!(err.contains(&want), "no `{want}` in:\n{err}");
    }
}

#[test]
fn cmd_vel_from_a_second_writer_fails_the_run() {
    let d = test_domains::domain(4);
    let stop = Arc::new(AtomicBool::new(false));
    let stop2 = stop.clone();
    // the other fleet arrives 8 s after this one started (past its check) and commands
    // robot_0 for 3 s
    let writer = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_secs(8));
        let other = OtherFleet::start(d);
        for _ in 0..30 {
            if stop2.load(Ordering::SeqCst) {
                break;
            }
            let _ = other.cmd.publish(Twist::planar(0.0, 0.0));
            std::thread::sleep(Duration::from_millis(100));
        }
    });
    let o = fleet(
        &[
            "--setup",
            "2.2_1",
            "--duration",
            "16",
            "--domain",
            &d.to_string(),
        ],
        None,
    );
    stop.store(true, Ordering::SeqCst);
    writer.join().unwrap();
    let (out, err) = text(&o);
    assert_eq!(o.status.code(), Some(1), "{out}\n{err}");
    assert!(
        err.contains("the fleet did not work")
            && err.contains("cmd_vel samples from a second writer"),
        "{err}"
    );
    let last = out
        .lines()
        .rev()
        .find_map(|l| l.strip_prefix("final: "))
        .expect("final metrics");
    let m: serde_json::Value = serde_json::from_str(last).unwrap();
    assert!(m["cmds_foreign_writer"].as_u64().unwrap() > 0, "{m}");
}
