//! Core tests: robot naming and grace, command validation, lockstep answers, robots on
//! state, run-time commands.

use super::*;
use msgs::Marker;

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

/// The rover's x position.
fn rover_x(c: &Core) -> f32 {
    c.robot_states().iter().find(|r| r.0 == "rover").unwrap().1[0]
}

/// Steps at wall times `ts`: each step's x displacement of the rover, and the times at
/// which the step reported its commands timed out.
fn step_rover(c: &mut Core, ts: &[f64]) -> (Vec<f32>, Vec<f64>) {
    let (mut dx, mut stopped) = (Vec::new(), Vec::new());
    for &t in ts {
        let x0 = rover_x(c);
        if c.step(t, false).unwrap() == vec!["rover".to_string()] {
            stopped.push(t);
        }
        dx.push(rover_x(c) - x0);
    }
    (dx, stopped)
}

/// Realtime (ADR 0031): a body whose commands stop coming (its robot_node died) is
/// commanded zero velocity once its latest command is older than `cmd_vel_timeout_s`
/// (0.5 s) and is at rest within a step; a fresh command moves it again; it is removed at
/// the stale timeout (1 s here) after its last command, not at the command timeout.
#[test]
fn a_body_stops_at_the_command_timeout_and_is_removed_at_the_stale_timeout() {
    let mut c = core(Mode::Realtime);
    assert_eq!((c.p.cmd_vel_timeout_s, c.p.stale_timeout_s), (0.5, 1.0));
    c.on_cmd("rover", &Twist::planar(0.1, 0.0), None, 0.0);
    let ts: Vec<f64> = (1..=9).map(|i| 0.1 * i as f64).collect();
    let (dx, stopped) = step_rover(&mut c, &ts);
    // moving while the command is at most 0.5 s old (the steps at 0.1 .. 0.5 s)
    assert!(dx[..5].iter().all(|d| *d > 0.005), "{dx:?}");
    // stopped at 0.6 s, reported once, and at rest from then on
    assert_eq!(stopped, vec![ts[5]]);
    assert!(dx[5..].iter().all(|d| d.abs() < 1e-4), "{dx:?}");
    assert_eq!(
        (c.counters.cmd_timeouts, c.counters.cmd_timeout_steps),
        (1, 4)
    );
    // stopped, not removed: removal stays at the stale timeout
    assert!(c.expire(0.95).is_empty());
    assert!(c.has_robot("rover"));
    // a fresh command moves it again
    c.on_cmd("rover", &Twist::planar(0.1, 0.0), None, 0.95);
    let ts: Vec<f64> = (0..10).map(|i| 1.0 + 0.1 * i as f64).collect();
    let (dx, stopped) = step_rover(&mut c, &ts);
    assert!(dx[..5].iter().all(|d| *d > 0.005), "{dx:?}");
    assert_eq!(
        stopped,
        vec![ts[5]],
        "stopped again 0.5 s after the fresh command"
    );
    assert!(dx[5..].iter().all(|d| d.abs() < 1e-4), "{dx:?}");
    assert_eq!(c.counters.cmd_timeouts, 2);
    assert!(c.expire(1.9).is_empty());
    assert_eq!(c.expire(1.96), vec!["rover".to_string()]);
}

/// A base at full speed (0.5 m/s, where the velocity tracker's force cap binds) is at
/// rest within two steps of its command timing out.
#[test]
fn a_body_at_full_speed_stops_within_two_steps() {
    let mut c = core(Mode::Realtime);
    c.on_cmd("rover", &Twist::planar(0.5, 0.0), None, 0.0);
    c.on_cmd("rover", &Twist::planar(0.5, 0.0), None, 0.3); // keeps full speed to 0.8 s
    let ts: Vec<f64> = (1..=12).map(|i| 0.1 * i as f64).collect();
    let (dx, stopped) = step_rover(&mut c, &ts);
    let k = ts.iter().position(|&t| t == stopped[0]).unwrap();
    assert!(dx[k - 1] > 0.04, "full speed before the timeout: {dx:?}");
    assert!(dx[k + 2..].iter().all(|d| d.abs() < 1e-4), "{dx:?}");
}

/// Lockstep waits for answers (ADR 0003/0029): an answer to the published state moves its
/// body however much wall time passed before the step; the command timeout is realtime's.
#[test]
fn lockstep_ignores_the_command_timeout() {
    let mut c = core(Mode::Lockstep);
    c.mark_published(0.0);
    let k0 = c.stamp_key();
    let before = c.robot_states();
    for i in 0..6 {
        c.on_cmd(
            &format!("robot_{i}"),
            &Twist::planar(0.1, 0.0),
            Some(k0),
            0.1,
        );
    }
    // a slow peer held the step until 0.9 s of wall time after the answers
    assert!(c.step(1.0, false).unwrap().is_empty());
    let after = c.robot_states();
    for (b, a) in before.iter().zip(&after) {
        assert!(a.1[0] > b.1[0] + 0.005, "{} did not move", a.0);
    }
    assert_eq!(c.counters.cmd_timeout_steps, 0);
}

#[test]
fn a_command_timeout_not_below_the_stale_timeout_is_refused() {
    let p = BridgeParams {
        cmd_vel_timeout_s: 2.0,
        ..BridgeParams::default()
    };
    let e = Core::new(p, 0.0).err().unwrap().to_string();
    assert!(
        e.contains("cmd_vel_timeout_s") && e.contains("stale_timeout_s"),
        "{e}"
    );
}

/// Two writers on one robot's cmd_vel (another fleet's robot of the same name on the
/// domain, ADR 0032): the first valid writer is pinned; the second is refused and counted
/// while the first commands, and takes over once the first has been silent for the
/// command timeout (a restarted robot_node); in lockstep, for the stale timeout.
#[test]
fn a_second_writer_on_a_robots_cmd_vel_is_refused_and_counted() {
    use CmdOutcome::*;
    let mut c = core(Mode::Realtime);
    let (ours, theirs) = ([1; 16], [2; 16]);
    let go = Twist::planar(0.1, 0.0);
    let back = Twist::planar(-0.1, 0.0);
    let nan = Twist::planar(f64::NAN, 0.0);
    // an invalid command pins nothing
    assert_eq!(
        c.on_cmd_from("robot_0", &nan, None, theirs, 0.0),
        DroppedNonFinite
    );
    assert_eq!(c.on_cmd_from("robot_0", &go, None, ours, 0.0), Accepted);
    assert_eq!(
        c.on_cmd_from("robot_0", &back, None, theirs, 0.05),
        DroppedForeignWriter
    );
    assert_eq!(c.robots["robot_0"].cmd, [0.1, 0.0]);
    assert_eq!(c.on_cmd_from("robot_0", &go, None, ours, 0.1), Accepted);
    // 0.45 s after ours: still pinned
    assert_eq!(
        c.on_cmd_from("robot_0", &back, None, theirs, 0.55),
        DroppedForeignWriter
    );
    assert_eq!(c.counters.cmds_foreign_writer, 2);
    // ours silent for more than the command timeout: the other writer takes over
    assert_eq!(
        c.on_cmd_from("robot_0", &back, None, theirs, 0.65),
        Accepted
    );
    assert_eq!(c.counters.cmd_writer_changes, 1);
    assert_eq!(c.robots["robot_0"].cmd, [-0.1, 0.0]);
    assert_eq!(
        c.on_cmd_from("robot_0", &go, None, ours, 0.7),
        DroppedForeignWriter
    );
    // other robots are pinned on their own
    assert_eq!(c.on_cmd_from("robot_1", &go, None, ours, 0.7), Accepted);
    let json = serde_json::to_string(&c.metrics()).unwrap();
    assert!(
        json.contains("\"cmds_foreign_writer\":3") && json.contains("\"cmd_writer_changes\":1"),
        "{json}"
    );
    // lockstep keeps the pin until the stale timeout (1 s here)
    let mut c = core(Mode::Lockstep);
    assert_eq!(c.on_cmd_from("robot_0", &go, None, ours, 0.0), Accepted);
    assert_eq!(
        c.on_cmd_from("robot_0", &go, None, theirs, 0.9),
        DroppedForeignWriter
    );
    assert_eq!(c.on_cmd_from("robot_0", &go, None, theirs, 1.1), Accepted);
}
