//! A robot_node stopped and continued (Ctrl-Z then `fg`, or a debugger attaching) keeps
//! working. Linux makes a blocked `epoll_wait` fail with EINTR after a stop and SIGCONT,
//! even without a signal handler; RustDDS's event loops ended on that error, and the
//! robot went deaf and mute for good (third_party patch 0012).
//!
//! A realtime bridge (setup 2.2_1, robot_1 never started, so its slot goes stale and only
//! robot_0 stays) and one robot_node. Once robot_0 acts on state, the test stops and
//! continues it five times, for 0.2 s each, then checks that the bridge still gets its
//! commands: no despawn, and robot_0 on state 3 s later.
//!
//! Needs the `robot_node` binary next to `sim_bridge` (see lockstep_repro.rs).

mod lockstep_common;

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use lockstep_common::{robot_node_bin, Kill};

fn signal(pid: u32, sig: i32) {
    // SAFETY: kill(2) on a child process id this test owns.
    let rc = unsafe { libc::kill(pid as i32, sig) };
    assert_eq!(rc, 0, "kill({pid}, {sig}) failed");
}

#[test]
fn a_robot_stopped_and_continued_keeps_commanding() {
    let d = test_domains::domain(0).to_string();
    let mut bridge = Kill(vec![Command::new(env!("CARGO_BIN_EXE_sim_bridge"))
        .env("ROS_DOMAIN_ID", &d)
        .args(["--ros-args", "-p", "setup:=2.2_1", "-p", "seed:=0"])
        .args(["-p", "metrics_period_s:=0.2", "-p", "startup_grace_s:=3.0"])
        .args(["--disable-rosout-logs"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("starting sim_bridge")]);
    let robot = Kill(vec![Command::new(robot_node_bin())
        .env("ROS_DOMAIN_ID", &d)
        .args([
            "--ros-args",
            "-r",
            "__ns:=/robot_0",
            "--disable-rosout-logs",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("starting robot_node")]);
    let robot_pid = robot.0[0].id();
    let out = bridge.0[0].stdout.take().unwrap();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for l in BufReader::new(out).lines().map_while(Result::ok) {
            if let Ok(v) = serde_json::from_str::<serde_json::Value>(&l) {
                let _ = tx.send(v);
            }
        }
    });
    // the latest metrics line, waiting up to `until`
    let latest = |until: Instant| -> serde_json::Value {
        let mut last = None;
        while Instant::now() < until {
            if let Ok(v) = rx.recv_timeout(Duration::from_millis(100)) {
                last = Some(v);
            }
        }
        while let Ok(v) = rx.try_recv() {
            last = Some(v);
        }
        last.expect("no metrics line from sim_bridge")
    };
    // robot_0 acting on state (robot_1 is removed after the start-up grace)
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let m = rx
            .recv_timeout(deadline.saturating_duration_since(Instant::now()))
            .expect("robot_0 never got on state");
        if m["robots_on_state"] == 1 && m["robots"] == 1 {
            break;
        }
    }
    let before = latest(Instant::now() + Duration::from_millis(300));
    for _ in 0..5 {
        signal(robot_pid, libc::SIGSTOP);
        std::thread::sleep(Duration::from_millis(200));
        signal(robot_pid, libc::SIGCONT);
        std::thread::sleep(Duration::from_millis(300));
    }
    let after = latest(Instant::now() + Duration::from_secs(3));
    eprintln!("before {before}\nafter {after}");
    assert_eq!(
        after["despawned"], before["despawned"],
        "robot_0 was removed after stop/continue: {after}"
    );
    assert_eq!(after["robots_on_state"], 1, "{after}");
    assert!(
        after["step"].as_u64() > before["step"].as_u64(),
        "the bridge stopped stepping: {after}"
    );
}
