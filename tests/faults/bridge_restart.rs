//! Fault (a): the bridge is SIGKILLed and restarted. Watched by an independent recorder
//! (`tending record`): every robot_node commands exactly zero velocity within its stale
//! timeout of the kill and keeps publishing; after the restart the fleet moves again.

mod common;
use common::*;

use std::process::Command;
use std::time::Duration;

use msgs::Twist;

const ROBOT_STALE_S: f64 = 1.0;

#[test]
fn robots_stop_within_the_stale_timeout_and_resume_after_a_bridge_restart() {
    let domain = test_domains::domain(0);
    let setup = "2.2_1";
    let dir = std::env::temp_dir().join(format!("tending-restart-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mut rec = {
        let mut c = Command::new(bin("tending"));
        c.arg("record")
            .arg(&dir)
            .args(["--domain-id", &domain.to_string(), "--duration", "60"]);
        // (`tending record`'s default enclave is the recorder's)
        security_env(&mut c, keystore::RECORDER_ENCLAVE, keystore::Role::Recorder);
        Proc::spawn("record", c)
    };
    let mut robots: Vec<Proc> = (0..2)
        .map(|i| {
            let n = format!("robot_{i}");
            Proc::spawn(&n, robot_cmd(&n, domain, setup, &[]))
        })
        .collect();
    let mut b1 = Proc::spawn("sim_bridge", bridge_cmd(domain, setup, &[]));
    sleep_s(10.0);
    assert!(b1.alive(), "bridge 1 died");
    let t_kill = wall_ns();
    b1.signal(libc::SIGKILL);
    let _ = b1.child.wait();
    sleep_s(6.0);
    let t_restart = wall_ns();
    let mut b2 = Proc::spawn("sim_bridge", bridge_cmd(domain, setup, &[]));
    sleep_s(10.0);
    let t_end = wall_ns();
    let m2 = b2.last_json();
    assert!(
        b2.stop(Duration::from_secs(5)),
        "bridge 2 did not stop cleanly"
    );
    for r in robots.iter_mut() {
        assert!(r.alive(), "{} died", r.name);
        assert!(
            r.stop(Duration::from_secs(5)),
            "{} did not stop cleanly",
            r.name
        );
    }
    assert!(
        rec.stop(Duration::from_secs(10)),
        "recorder did not stop cleanly"
    );

    let bag = bag::BagReader::open(&dir).unwrap();
    let mut failures = Vec::new();
    let mut moved_before = 0;
    let mut moved_after = 0;
    let mut rows = Vec::new();
    for i in 0..2 {
        let topic = format!("/robot_{i}/cmd_vel");
        let cmds: Vec<(u64, Twist)> = bag.decode_topic(&topic).unwrap();
        let nonzero = |t: &Twist| t.linear.x != 0.0 || t.linear.y != 0.0;
        let before = cmds
            .iter()
            .filter(|(t, c)| *t < t_kill && *t > t_kill - 6_000_000_000 && nonzero(c))
            .count();
        let last_nonzero_after_kill = cmds
            .iter()
            .filter(|(t, c)| *t >= t_kill && *t < t_restart && nonzero(c))
            .map(|(t, _)| (*t - t_kill) as f64 / 1e9)
            .fold(0.0, f64::max);
        let zeros_while_down = cmds
            .iter()
            .filter(|(t, c)| *t > t_kill + 2_000_000_000 && *t < t_restart && !nonzero(c))
            .count();
        let first_after = cmds
            .iter()
            .find(|(t, c)| *t >= t_restart && nonzero(c))
            .map(|(t, _)| (*t - t_restart) as f64 / 1e9);
        eprintln!(
            "{topic}: {before} moving commands in the 6 s before the kill; last moving command {last_nonzero_after_kill:.2} s after the kill; {zeros_while_down} zero commands while down; first moving command {first_after:?} s after the restart"
        );
        rows.push(serde_json::json!({
            "robot": format!("robot_{i}"),
            "moving_before_kill": before,
            "last_moving_after_kill_s": last_nonzero_after_kill,
            "zero_cmds_while_down": zeros_while_down,
            "first_moving_after_restart_s": first_after,
        }));
        if before > 0 {
            moved_before += 1;
        }
        if first_after.is_some() {
            moved_after += 1;
        }
        // stale after ROBOT_STALE_S without its own pose, plus one control period and
        // scheduling slack
        if last_nonzero_after_kill > ROBOT_STALE_S + 0.35 {
            failures.push(format!(
                "{topic}: still moving {last_nonzero_after_kill:.2} s after the bridge died"
            ));
        }
        // kept publishing (zero) at ~10 Hz while the bridge was down
        if zeros_while_down < 20 {
            failures.push(format!(
                "{topic}: only {zeros_while_down} zero commands while the bridge was down"
            ));
        }
    }
    if moved_before == 0 {
        failures.push("no robot moved before the kill".into());
    }
    if moved_after == 0 {
        failures.push("no robot moved after the restart".into());
    }
    let delivered_after = m2
        .as_ref()
        .map(|m| num(m, "parts_delivered"))
        .unwrap_or(0.0);
    eprintln!("bridge 2 metrics: {m2:?}");
    report(serde_json::json!({
        "fault": "bridge SIGKILLed and restarted",
        "robots": rows,
        "bridge2_parts_delivered_in_10s": delivered_after,
        "down_s": (t_restart - t_kill) as f64 / 1e9,
        "after_s": (t_end - t_restart) as f64 / 1e9,
    }));
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    let _ = std::fs::remove_dir_all(&dir);
}
