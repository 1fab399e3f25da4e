//! Core tests: robot naming and grace, command validation, lockstep answers, robots on
//! state, run-time commands.

use super::*;

/// A wall-clock source timestamp key (2026-12-02, microseconds since the epoch).
const WALL_CLOCK_US: i64 = 1_796_200_000_000_000;

fn core(mode: Mode) -> Core {
    let p = BridgeParams {
        mode,
        stale_timeout_s: 1.0,
        startup_grace_s: 5.0,
        ..BridgeParams::default()
    };
    Core::new(p, 0.0).unwrap()
}

#[test]
fn initial_robots_are_named_and_get_a_grace_period() {
    let mut c = core(Mode::Realtime);
    let names: Vec<_> = c.robot_names().cloned().collect();
    assert_eq!(names.len(), 6);
    assert!(c.has_robot("robot_0") && c.has_robot("robot_5"));
    assert!(c.expire(4.9).is_empty());
    c.on_cmd("robot_0", &Twist::planar(0.1, 0.0), None, 5.0);
    let gone = c.expire(5.5);
    assert_eq!(gone.len(), 5);
    assert_eq!(c.env.n_robots(), 1);
    assert!(c.expire(5.9).is_empty());
    assert_eq!(c.expire(6.01).len(), 1);
    assert_eq!(c.counters.despawned, 6);
}

#[test]
fn first_cmd_spawns_invalid_cmds_never_reach_the_sim() {
    let mut c = core(Mode::Realtime);
    let o = c.on_cmd("rover", &Twist::planar(0.5, 0.0), None, 0.0);
    assert!(matches!(o, CmdOutcome::Spawned(_)));
    assert_eq!(c.env.n_robots(), 7);
    let before: Vec<_> = c.robot_states();
    let nan = Twist::planar(f64::NAN, 0.0);
    assert_eq!(
        c.on_cmd("rover", &nan, None, 0.1),
        CmdOutcome::DroppedNonFinite
    );
    assert_eq!(
        c.on_cmd("ghost", &Twist::planar(f64::INFINITY, 0.0), None, 0.1),
        CmdOutcome::DroppedNonFinite
    );
    assert_eq!(c.env.n_robots(), 7, "a bad first cmd spawns nothing");
    c.on_undecodable_cmd();
    assert_eq!(c.counters.cmds_dropped_non_finite, 2);
    assert_eq!(c.counters.cmds_dropped_decode, 1);
    c.step(0.1, false).unwrap();
    // the rover moved right with its last valid command
    let after = c.robot_states();
    let rx = |v: &Vec<(String, [f32; 2], bool)>| v.iter().find(|r| r.0 == "rover").unwrap().1;
    assert!(rx(&after)[0] > rx(&before)[0]);
    assert!(after.iter().all(|r| r.1[0].is_finite()));
}

#[test]
fn lockstep_waits_for_every_answer_and_ignores_late_ones() {
    let mut c = core(Mode::Lockstep);
    c.mark_published(0.0);
    let k0 = c.stamp_key();
    assert_eq!(c.lockstep_status(0.1), (false, false));
    for i in 0..5 {
        c.on_cmd(
            &format!("robot_{i}"),
            &Twist::planar(0.5, 0.0),
            Some(k0),
            0.1,
        );
    }
    assert_eq!(c.lockstep_status(0.2), (false, false));
    // the first state is waited for until the start-up grace (5 s here), not only the
    // step timeout (2 s): security handshakes may still be running (ADR 0029)
    assert_eq!(c.lockstep_status(2.5), (false, false));
    assert_eq!(c.lockstep_status(5.1), (false, true));
    c.on_cmd("robot_5", &Twist::planar(0.0, 0.5), Some(k0), 0.3);
    assert!(c.lockstep_status(0.3).0);
    c.step(0.3, false).unwrap();
    c.mark_published(0.3);
    // a resent copy of an answer already received is a repeat (ADR 0029), not an answer
    // to the new state
    assert_eq!(
        c.on_cmd("robot_0", &Twist::planar(0.5, 0.0), Some(k0), 0.4),
        CmdOutcome::DroppedRepeated
    );
    assert!(!c.lockstep_status(0.4).0);
    assert_eq!(c.stamp_key(), 100_000);
    // an answer to the old state from a robot that had not given it is late
    c.on_cmd(
        "robot_1",
        &Twist::planar(0.5, 0.0),
        Some(c.stamp_key()),
        0.4,
    );
    assert_eq!(
        c.on_cmd("robot_1", &Twist::planar(0.5, 0.0), Some(k0), 0.4),
        CmdOutcome::DroppedLate
    );
    assert_eq!((c.counters.cmds_late, c.counters.cmds_repeated), (1, 1));
    // later states time out after the step timeout alone
    assert_eq!(c.lockstep_status(2.2), (false, false));
    assert_eq!(c.lockstep_status(2.4), (false, true));
}

#[test]
fn robots_on_state_counts_commands_answering_recent_state_only() {
    let mut c = core(Mode::Realtime);
    assert_eq!(c.metrics().robots_on_state, 0);
    let k0 = c.stamp_key();
    // robot_0 acts on state, robot_1 only sends unstamped zeros (never got its pose)
    c.on_cmd("robot_0", &Twist::planar(0.5, 0.0), Some(k0), 0.0);
    c.on_cmd("robot_1", &Twist::planar(0.0, 0.0), None, 0.0);
    c.on_cmd(
        "robot_2",
        &Twist::planar(0.0, 0.0),
        Some(WALL_CLOCK_US),
        0.0,
    );
    assert_eq!(c.metrics().robots_on_state, 1);
    // 20 steps (2 s of sim time) later robot_0's answer is too old
    for i in 0..20 {
        c.on_cmd("robot_1", &Twist::planar(0.0, 0.0), None, 0.1 * i as f64);
        c.step(0.1 * i as f64, false).unwrap();
    }
    assert_eq!(c.metrics().robots_on_state, 0);
    c.on_cmd(
        "robot_0",
        &Twist::planar(0.5, 0.0),
        Some(c.stamp_key()),
        2.0,
    );
    assert_eq!(c.metrics().robots_on_state, 1);
}

#[test]
fn run_time_commands() {
    let mut c = core(Mode::Realtime);
    assert_eq!(
        c.apply_command("add_machine", 0.0).unwrap(),
        "added machine_4"
    );
    assert_eq!(c.env.counts().machines, 5);
    c.apply_command("remove_machine 0", 0.0).unwrap();
    assert!(c.apply_command("remove_machine 0", 0.0).is_err());
    c.apply_command("add_storage", 0.0).unwrap();
    c.apply_command("remove_storage 1", 0.0).unwrap();
    assert_eq!(c.env.counts().storages, 2);
    c.apply_command("remove_robot robot_3", 0.0).unwrap();
    assert!(!c.has_robot("robot_3"));
    assert!(c.apply_command("add_robot machine_9", 0.0).is_err());
    assert!(c.apply_command("fly", 0.0).is_err());
    assert!(c.apply_command("add_machine 0.1", 0.0).is_err());
    assert_eq!(c.counters.commands_failed, 4);
    let m = c.markers();
    assert_eq!(m.markers[0].action, Marker::DELETEALL);
    assert_eq!(m.markers.len(), 1 + 5 + 4 + 2);
    let robots = m.markers.iter().filter(|x| x.ns == "robots").count();
    assert_eq!(robots, 5);
    let json = serde_json::to_string(&c.metrics()).unwrap();
    assert!(
        json.contains("\"robots\":5") && json.contains("\"mu\""),
        "{json}"
    );
}

#[test]
fn the_realtime_start_waits_for_commands_from_state_from_initial_robots_only() {
    let mut c = core(Mode::Realtime);
    assert_eq!(c.initial_robots_waiting().len(), 6);
    let k0 = c.stamp_key();
    // an unstamped command (robot_node before it has state) does not count
    c.on_cmd("robot_0", &Twist::planar(0.0, 0.0), None, 0.1);
    assert_eq!(c.initial_robots_waiting().len(), 6);
    // nor one that carries its publisher's wall clock, which is what an unstamped command
    // is on the wire (DDS source timestamp; 2026 in microseconds)
    c.on_cmd(
        "robot_0",
        &Twist::planar(0.0, 0.0),
        Some(WALL_CLOCK_US),
        0.1,
    );
    assert_eq!(c.initial_robots_waiting().len(), 6);
    for i in 0..5 {
        c.on_cmd(
            &format!("robot_{i}"),
            &Twist::planar(0.1, 0.0),
            Some(k0),
            0.2,
        );
    }
    assert_eq!(c.initial_robots_waiting(), vec!["robot_5"]);
    // a robot added live is not waited for
    c.on_cmd("rover", &Twist::planar(0.0, 0.0), None, 0.3);
    assert_eq!(c.initial_robots_waiting(), vec!["robot_5"]);
    c.on_cmd("robot_5", &Twist::planar(0.1, 0.0), Some(k0), 0.4);
    assert!(c.initial_robots_waiting().is_empty());
}
