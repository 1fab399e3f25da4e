//! World model tests: own-pose freshness, staleness, refused inputs, writer pinning and
//! the admit rule.

use super::*;
use msgs::topics::{machine, robot, storage};
use msgs::{PoseStamped, Time};

fn cfg() -> WorldModelConfig {
    WorldModelConfig {
        stale_timeout_s: 1.0,
        static_stale_timeout_s: 2.0,
        room: RoomBounds::default(),
        bound: obs::Bound::EVERYTHING,
        cells: None,
    }
}
fn pose(x: f64, y: f64) -> PoseStamped {
    PoseStamped::planar(Time::default(), "map", x, y)
}

#[test]
fn own_must_be_fresh() {
    let mut w = World::new("/robot_0", cfg());
    assert_eq!(w.observation(0.0).unwrap_err(), OwnStale::NoPose);
    w.on_pose(&robot("robot_0", Leaf::Pose), &pose(0.1, 0.2), 0.0)
        .unwrap();
    assert_eq!(w.observation(0.0).unwrap_err(), OwnStale::NoHasPart);
    w.on_flag(&robot("robot_0", Leaf::HasPart), true, 0.5)
        .unwrap();
    let o = w.observation(0.9).unwrap();
    assert_eq!(o.own_pos, [0.1, 0.2]);
    assert!(o.has_part);
    assert_eq!(w.observation(1.01).unwrap_err(), OwnStale::PoseStale);
    w.on_pose(&robot("robot_0", Leaf::Pose), &pose(0.1, 0.2), 1.0)
        .unwrap();
    assert_eq!(w.observation(1.6).unwrap_err(), OwnStale::HasPartStale);
}

#[test]
fn entities_drop_out_when_stale() {
    let mut w = World::new("robot_0", cfg());
    w.on_pose(&robot("robot_0", Leaf::Pose), &pose(0.0, 0.0), 0.0)
        .unwrap();
    w.on_flag(&robot("robot_0", Leaf::HasPart), false, 0.0)
        .unwrap();
    w.on_pose(&machine(1, Leaf::Pose), &pose(0.5, 0.5), 0.0)
        .unwrap();
    // machine without part_ready is not observed yet
    assert!(w.observation(0.0).unwrap().machines.is_empty());
    w.on_flag(&machine(1, Leaf::PartReady), true, 0.0).unwrap();
    w.on_pose(&storage(0, Leaf::Pose), &pose(-1.0, 1.0), 0.0)
        .unwrap();
    w.on_pose(&robot("robot_1", Leaf::Pose), &pose(0.3, 0.0), 0.0)
        .unwrap();
    w.on_flag(&robot("robot_1", Leaf::HasPart), true, 0.0)
        .unwrap();
    let o = w.observation(0.5).unwrap();
    assert_eq!(o.machines, vec![([0.5, 0.5], true)]);
    assert_eq!(o.storages, vec![[-1.0, 1.0]]);
    assert_eq!(o.peers, vec![([0.3, 0.0], true)]);
    // keep own fresh; peer goes stale after 1 s, machine/storage after 2 s
    w.on_pose(&robot("robot_0", Leaf::Pose), &pose(0.0, 0.0), 1.5)
        .unwrap();
    w.on_flag(&robot("robot_0", Leaf::HasPart), false, 1.5)
        .unwrap();
    let o = w.observation(1.5).unwrap();
    assert!(o.peers.is_empty());
    assert_eq!(o.machines.len(), 1);
    let o = w.observation(2.4).unwrap();
    assert!(o.machines.is_empty() && o.storages.is_empty());
    assert_eq!(w.known(), (1, 1, 1));
}

#[test]
fn static_timeout_can_be_disabled() {
    let mut c = cfg();
    c.static_stale_timeout_s = 0.0;
    let mut w = World::new("robot_0", c);
    w.on_pose(&storage(0, Leaf::Pose), &pose(-1.0, 1.0), 0.0)
        .unwrap();
    w.on_pose(&robot("robot_0", Leaf::Pose), &pose(0.0, 0.0), 100.0)
        .unwrap();
    w.on_flag(&robot("robot_0", Leaf::HasPart), false, 100.0)
        .unwrap();
    assert_eq!(w.observation(100.0).unwrap().storages.len(), 1);
}

#[test]
fn bad_inputs_are_refused_and_do_not_overwrite() {
    let mut w = World::new("robot_0", cfg());
    let t = robot("robot_0", Leaf::Pose);
    w.on_pose(&t, &pose(0.2, 0.2), 0.0).unwrap();
    w.on_flag(&robot("robot_0", Leaf::HasPart), false, 0.0)
        .unwrap();
    let mut nan = pose(0.0, 0.0);
    nan.pose.position.x = f64::NAN;
    assert_eq!(w.on_pose(&t, &nan, 0.1), Err(DropReason::NonFinite));
    let mut q = pose(0.0, 0.0);
    q.pose.orientation.z = f64::INFINITY;
    assert_eq!(w.on_pose(&t, &q, 0.1), Err(DropReason::NonFinite));
    assert_eq!(
        w.on_pose(&t, &pose(5.0, 0.0), 0.1),
        Err(DropReason::OutOfRoom)
    );
    assert_eq!(
        w.on_flag(&machine(0, Leaf::Pose), true, 0.1),
        Err(DropReason::Unexpected)
    );
    assert_eq!(w.observation(0.2).unwrap().own_pos, [0.2, 0.2]);
}
const BRIDGE: WriterId = [1; 16];
const IMPOSTOR: WriterId = [2; 16];
const BRIDGE2: WriterId = [3; 16];

/// Own position as last stored, whatever its age.
fn own_pose_at(w: &World) -> [f32; 2] {
    let p = w.own.pose.unwrap().value;
    [p[0] as f32, p[1] as f32]
}

#[test]
fn first_writer_is_pinned_and_an_impostor_is_refused() {
    let mut w = World::new("robot_1", cfg());
    let t = robot("robot_1", Leaf::Pose);
    assert_eq!(
        w.on_pose_from(&t, &pose(0.3, 0.3), BRIDGE, 0.0),
        Ok(Accepted::Stored)
    );
    // a valid, plausible pose from another writer: refused, the data is unchanged
    for k in 0..10 {
        let now = 0.05 * k as f64;
        assert_eq!(
            w.on_pose_from(&t, &pose(-1.0, -1.0), IMPOSTOR, now),
            Err(DropReason::ForeignWriter)
        );
        assert_eq!(
            w.on_pose_from(&t, &pose(0.3, 0.3 + 0.01 * k as f64), BRIDGE, now),
            Ok(Accepted::Stored)
        );
    }
    assert_eq!(own_pose_at(&w), [0.3, 0.39]);
    // the same for peers, machines, storages and flags (one rule for every topic)
    let peer = robot("robot_4", Leaf::Pose);
    let m = machine(2, Leaf::Pose);
    let s = storage(0, Leaf::Pose);
    for t in [&peer, &m, &s] {
        w.on_pose_from(t, &pose(0.1, 0.1), BRIDGE, 1.0).unwrap();
        assert_eq!(
            w.on_pose_from(t, &pose(0.2, 0.2), IMPOSTOR, 1.1),
            Err(DropReason::ForeignWriter)
        );
    }
    for t in [robot("robot_1", Leaf::HasPart), machine(2, Leaf::PartReady)] {
        w.on_flag_stamped(&t, false, None, BRIDGE, 1.0).unwrap();
        assert_eq!(
            w.on_flag_stamped(&t, true, None, IMPOSTOR, 1.1),
            Err(DropReason::ForeignWriter)
        );
    }
    let mut c = Counters::default();
    c.drop(DropReason::ForeignWriter);
    assert_eq!((c.dropped_foreign_writer, c.dropped()), (1, 1));
    assert_eq!(c.to_json()["dropped"]["foreign_writer"], 1);
}

#[test]
fn a_new_writer_takes_the_pin_once_the_pinned_data_is_stale() {
    // robots: stale_timeout_s = 1.0
    let mut w = World::new("robot_0", cfg());
    let t = robot("robot_0", Leaf::Pose);
    w.on_pose_from(&t, &pose(0.3, 0.3), BRIDGE, 10.0).unwrap();
    // the bridge dies at 10.0: still refused while its data is fresh (<= 1 s old)
    assert_eq!(
        w.on_pose_from(&t, &pose(0.5, 0.5), BRIDGE2, 11.0),
        Err(DropReason::ForeignWriter)
    );
    // a restarted bridge (new writer) is accepted once the old data is stale
    assert_eq!(
        w.on_pose_from(&t, &pose(0.5, 0.5), BRIDGE2, 11.01),
        Ok(Accepted::NewWriter)
    );
    assert_eq!(own_pose_at(&w), [0.5, 0.5]);
    // ...and now holds the pin: the old writer coming back is the foreign one
    assert_eq!(
        w.on_pose_from(&t, &pose(0.3, 0.3), BRIDGE, 11.1),
        Err(DropReason::ForeignWriter)
    );
    assert_eq!(
        w.on_pose_from(&t, &pose(0.6, 0.5), BRIDGE2, 11.2),
        Ok(Accepted::Stored)
    );
    // machines and storages release after static_stale_timeout_s (2.0 here)
    let m = machine(0, Leaf::Pose);
    w.on_pose_from(&m, &pose(0.5, 0.5), BRIDGE, 0.0).unwrap();
    assert_eq!(
        w.on_pose_from(&m, &pose(0.5, 0.5), BRIDGE2, 1.5),
        Err(DropReason::ForeignWriter)
    );
    assert_eq!(
        w.on_pose_from(&m, &pose(0.5, 0.5), BRIDGE2, 2.5),
        Ok(Accepted::NewWriter)
    );
}

#[test]
fn invalid_samples_neither_take_nor_refresh_a_pin() {
    let mut w = World::new("robot_0", cfg());
    let t = robot("robot_0", Leaf::Pose);
    let mut nan = pose(0.0, 0.0);
    nan.pose.position.y = f64::NAN;
    // a writer of garbage does not get pinned...
    assert_eq!(
        w.on_pose_from(&t, &nan, IMPOSTOR, 0.0),
        Err(DropReason::NonFinite)
    );
    assert_eq!(
        w.on_pose_from(&t, &pose(5.0, 0.0), IMPOSTOR, 0.0),
        Err(DropReason::OutOfRoom)
    );
    // ...so the first valid writer is
    assert_eq!(
        w.on_pose_from(&t, &pose(0.1, 0.1), BRIDGE, 0.1),
        Ok(Accepted::Stored)
    );
    // the pinned writer's invalid samples are counted as invalid, not as foreign,
    // and do not keep its pin alive
    assert_eq!(
        w.on_pose_from(&t, &nan, BRIDGE, 0.5),
        Err(DropReason::NonFinite)
    );
    // (the last valid sample was at 0.1: stale after 1.1)
    assert_eq!(
        w.on_pose_from(&t, &pose(0.2, 0.2), IMPOSTOR, 1.05),
        Err(DropReason::ForeignWriter)
    );
    assert_eq!(
        w.on_pose_from(&t, &pose(0.2, 0.2), IMPOSTOR, 1.15),
        Ok(Accepted::NewWriter)
    );
}

#[test]
fn static_pins_release_after_the_robot_timeout_when_static_staleness_is_off() {
    let mut c = cfg();
    c.static_stale_timeout_s = 0.0;
    let mut w = World::new("robot_0", c);
    let s = storage(1, Leaf::Pose);
    assert_eq!(w.pin_release_s(&s.entity), 1.0);
    assert_eq!(w.pin_release_s(&robot("robot_3", Leaf::Pose).entity), 1.0);
    w.on_pose_from(&s, &pose(0.5, 0.5), BRIDGE, 0.0).unwrap();
    assert_eq!(
        w.on_pose_from(&s, &pose(0.5, 0.5), BRIDGE2, 0.9),
        Err(DropReason::ForeignWriter)
    );
    assert_eq!(
        w.on_pose_from(&s, &pose(0.5, 0.5), BRIDGE2, 1.1),
        Ok(Accepted::NewWriter)
    );
}

#[test]
fn admit_rule() {
    let held = |writer, at| {
        Some(Sample {
            value: 0u8,
            at,
            stamp: None,
            writer,
        })
    };
    assert_eq!(admit::<u8>(&None, BRIDGE, 0.0, 1.0), Ok(Accepted::Stored));
    assert_eq!(
        admit(&held(BRIDGE, 0.0), BRIDGE, 9.0, 1.0),
        Ok(Accepted::Stored)
    );
    assert_eq!(
        admit(&held(BRIDGE, 0.0), IMPOSTOR, 1.0, 1.0),
        Err(DropReason::ForeignWriter)
    );
    assert_eq!(
        admit(&held(BRIDGE, 0.0), IMPOSTOR, 1.001, 1.0),
        Ok(Accepted::NewWriter)
    );
}

#[test]
fn fixtures_without_data_are_counted_apart_from_peers() {
    let mut w = World::new("robot_0", cfg());
    w.touch(&Entity::Machine(0));
    w.touch(&Entity::Storage(0));
    w.touch(&Entity::Robot("robot_1".into()));
    assert_eq!(
        (w.entities_without_data(), w.fixtures_without_data()),
        (3, 2)
    );
    // a machine needs its pose and its part_ready flag
    w.on_pose(&machine(0, Leaf::Pose), &pose(1.0, 1.0), 0.0)
        .unwrap();
    assert_eq!(w.fixtures_without_data(), 2);
    w.on_flag(&machine(0, Leaf::PartReady), true, 0.0).unwrap();
    w.on_pose(&storage(0, Leaf::Pose), &pose(-1.0, 1.0), 0.0)
        .unwrap();
    // only the peer is missing now: robots may act once SETTLE_MAX has passed
    assert_eq!(
        (w.entities_without_data(), w.fixtures_without_data()),
        (1, 0)
    );
}
