//! Pick/place, machine timers, reward terms, metrics, live add/remove, bad inputs.
mod common;
use common::*;
use sim::{Env, ScenarioConfig, Setup, SimError};

fn cfg_only(term: &str) -> ScenarioConfig {
    // Every reward term zero except `term` (to test one at a time).
    let mut c = ScenarioConfig::default();
    let r = &mut c.rewards;
    r.pick = 0.0;
    r.place = 0.0;
    r.collision = 0.0;
    r.progress = 0.0;
    r.utilization = 0.0;
    r.time = 0.0;
    match term {
        "pick" => r.pick = 3.0,
        "place" => r.place = 5.0,
        "collision" => r.collision = -1.0,
        "progress" => r.progress = 2.0,
        "utilization" => r.utilization = -0.1,
        "time" => r.time = -0.01,
        _ => panic!("{term}"),
    }
    c
}

/// Robot just left of a machine at the origin (within reach after one small step).
fn near_machine(cfg: ScenarioConfig) -> Env {
    // machine half 0.12, robot radius 0.08: surface gap 0.05 < reach 0.08, > collision 0.005
    env_with_cfg(cfg, "1.1_1", &[[-0.25, 0.0]], &[[0.0, 0.0]], &[[0.0, 0.8]])
}

#[test]
fn pick_needs_reach_and_a_ready_part_and_starts_the_timer() {
    let mut env = near_machine(cfg_only("pick"));
    env.step_actions(&[0]).unwrap();
    assert!(env.events()[0].picked.is_some());
    assert!(env.robots().next().unwrap().has_part);
    assert_eq!(env.rewards()[0], 3.0);
    assert_eq!(env.metrics().parts_collected, 1);
    let m = env.machines().next().unwrap();
    assert!(!m.part_ready);
    assert_eq!(m.timer, 20);
    assert_eq!(env.metrics().collisions, 0, "picking must not need contact");
    // The timer counts down and the part is ready again after exactly 20 more steps.
    for k in 1..=20 {
        env.step_actions(&[0]).unwrap();
        let m = env.machines().next().unwrap();
        assert_eq!(m.part_ready, k == 20, "step {k} timer {}", m.timer);
    }
    // One part per robot: it cannot pick the new part while carrying one.
    env.step_actions(&[0]).unwrap();
    assert!(env.machines().next().unwrap().part_ready);
    assert_eq!(env.metrics().parts_collected, 1);
}

#[test]
fn out_of_reach_robot_does_not_pick() {
    let mut env = env_with_cfg(
        cfg_only("pick"),
        "1.1_1",
        &[[-0.5, 0.0]],
        &[[0.0, 0.0]],
        &[[0.0, 0.8]],
    );
    env.step_actions(&[0]).unwrap();
    assert!(env.events()[0].picked.is_none());
    assert_eq!(env.rewards()[0], 0.0);
}

#[test]
fn place_delivers_and_rewards() {
    let mut env = env_with_cfg(
        cfg_only("place"),
        "1.1_1",
        &[[-0.25, 0.0]],
        &[[0.0, 0.0]],
        &[[-0.25, 0.3]],
    );
    env.step_actions(&[0]).unwrap(); // pick
    assert!(env.robots().next().unwrap().has_part);
    assert_eq!(env.rewards()[0], 0.0);
    // storage half height 0.08 at y=0.3: bottom surface at 0.22; robot top at 0.08
    let mut placed = false;
    for _ in 0..10 {
        env.step_actions(&[4]).unwrap();
        if env.events()[0].placed.is_some() {
            placed = true;
            assert_eq!(env.rewards()[0], 5.0);
            break;
        }
    }
    assert!(placed);
    assert!(!env.robots().next().unwrap().has_part);
    assert_eq!(env.metrics().parts_delivered, 1);
    assert_eq!(env.metrics().collisions, 0);
}

#[test]
fn progress_reward_is_scaled_distance_reduction() {
    let mut env = env_with_cfg(
        cfg_only("progress"),
        "1.1_1",
        &[[-0.8, 0.0]],
        &[[0.5, 0.0]],
        &[[0.0, 0.8]],
    );
    let x0 = env.robots().next().unwrap().pos[0];
    env.step_actions(&[2]).unwrap();
    let x1 = env.robots().next().unwrap().pos[0];
    let expect = 2.0 * (x1 - x0);
    assert!(expect > 0.0);
    assert!(
        (env.rewards()[0] - expect).abs() < 1e-5,
        "{} vs {expect}",
        env.rewards()[0]
    );
    // Moving away is penalized.
    env.step_actions(&[1]).unwrap();
    env.step_actions(&[1]).unwrap();
    assert!(env.rewards()[0] < 0.0);
}

#[test]
fn utilization_penalty_is_scale_times_uncollected_over_m() {
    let mut env = env_with_cfg(
        cfg_only("utilization"),
        "1.2_1",
        &[[-0.8, 0.8]],
        &[[0.0, 0.0], [0.6, 0.0]],
        &[[0.0, -0.8]],
    );
    env.step_actions(&[0]).unwrap();
    assert!((env.rewards()[0] - (-0.1 * 2.0 / 2.0)).abs() < 1e-6);
}

#[test]
fn time_penalty_only_when_nothing_else_happens() {
    let mut env = env_with_cfg(
        cfg_only("time"),
        "1.1_1",
        &[[-0.8, 0.8]],
        &[[0.0, 0.0]],
        &[[0.0, -0.8]],
    );
    // Uncollected part waiting -> R_u != 0 -> no time penalty (with default s_u).
    let mut c = cfg_only("time");
    c.rewards.utilization = -0.1;
    let mut env2 = env_with_cfg(c, "1.1_1", &[[-0.8, 0.8]], &[[0.0, 0.0]], &[[0.0, -0.8]]);
    env2.step_actions(&[0]).unwrap();
    assert!(
        (env2.rewards()[0] - (-0.1)).abs() < 1e-6,
        "{}",
        env2.rewards()[0]
    );
    // With R_u configured to 0 the time penalty applies.
    env.step_actions(&[0]).unwrap();
    assert!((env.rewards()[0] - (-0.01)).abs() < 1e-7);
}

/// Two robots 2 cm apart, facing each other; only the collision reward on.
fn two_robots_a_hair_apart() -> Env {
    let r = 0.08;
    env_with_cfg(
        cfg_only("collision"),
        "2.1_1",
        &[[-r - 0.01, 0.0], [r + 0.01, 0.0]],
        &[[0.0, 0.8]],
        &[[0.0, -0.8]],
    )
}

#[test]
fn collision_penalty_and_counts_per_robot() {
    let mut env = two_robots_a_hair_apart();
    // Drive into each other.
    env.step_actions(&[2, 1]).unwrap();
    assert_eq!(env.events()[0].collisions, 1);
    assert_eq!(env.rewards()[0], -1.0);
    assert_eq!(env.rewards()[1], -1.0);
    assert_eq!(env.metrics().collisions_robot_robot, 2);
    assert_eq!(env.metrics().collisions, 2);
}

#[test]
fn a_held_contact_is_one_collision_event_and_many_contact_steps() {
    let mut env = two_robots_a_hair_apart();
    // Pushed into each other for five steps: 10 contact steps, one onset per robot.
    for _ in 0..5 {
        env.step_actions(&[2, 1]).unwrap();
    }
    assert_eq!(env.metrics().collisions_robot_robot, 10);
    assert_eq!(env.metrics().collision_events, 2);
    assert!(env.events().iter().all(|e| !e.contact_onset));
    // Apart (moving away for a while), then together again: a second event each.
    for _ in 0..4 {
        env.step_actions(&[1, 2]).unwrap();
    }
    assert!(env.events().iter().all(|e| e.collisions == 0));
    let mut again = 0;
    for _ in 0..40 {
        env.step_actions(&[2, 1]).unwrap();
        again += env.events().iter().filter(|e| e.contact_onset).count();
    }
    assert_eq!(again, 2);
    assert_eq!(env.metrics().collision_events, 4);
    assert!(env.metrics().collisions > env.metrics().collision_events);
}

#[test]
fn mu_counts_parts_over_the_machines_lifetime() {
    let mut env = near_machine(ScenarioConfig::default());
    for _ in 0..200 {
        env.step_actions(&[0]).unwrap();
    }
    assert!(env.is_done());
    let m = env.metrics();
    assert_eq!(m.p_max, 10, "one machine, 200 steps, 20-step preparation");
    assert_eq!(m.parts_collected, 1);
    assert!((m.utilization() - 0.1).abs() < 1e-12);
}

#[test]
fn add_and_remove_mid_episode_keep_ids_and_metrics() {
    let mut env = Env::new(ScenarioConfig::default(), "4.2_2".parse().unwrap(), 5).unwrap();
    let mut rng_actions = 0u8;
    for _ in 0..50 {
        rng_actions = (rng_actions + 1) % 5;
        let a = vec![rng_actions; env.n_robots()];
        env.step_actions(&a).unwrap();
    }
    let ids_before: Vec<_> = env.robot_ids().to_vec();
    let new = env.add_robot(None).unwrap();
    assert!(!ids_before.contains(&new));
    env.remove_robot(ids_before[1]).unwrap();
    assert_eq!(env.n_robots(), 4);
    assert_eq!(
        env.robot_ids(),
        &[ids_before[0], ids_before[2], ids_before[3], new]
    );
    assert!(matches!(
        env.remove_robot(ids_before[1]),
        Err(SimError::UnknownId { .. })
    ));

    // Machines: P_max follows each machine's lifetime.
    let p50 = env.metrics().p_max;
    assert_eq!(p50, 2 * 50usize.div_ceil(20) as u32);
    let m_new = env.add_machine(None).unwrap();
    let first = env.machines().next().unwrap().id;
    env.remove_machine(first).unwrap();
    let s_new = env.add_storage(None).unwrap();
    assert_eq!(env.counts(), Setup::new(4, 2, 3));
    let mut obs = obs::ObsBatch::default();
    env.observe(&mut obs);
    assert_eq!(obs.rows, 4);
    assert_eq!(
        obs.counts,
        obs::Counts {
            machines: 2,
            storages: 3,
            peers: 3
        }
    );
    obs.validate().unwrap();
    for _ in 50..200 {
        let a = vec![0; env.n_robots()];
        env.step_actions(&a).unwrap();
    }
    // removed machine lived 50 steps (3), the survivor 200 (10), the new one 150 (8)
    assert_eq!(env.metrics().p_max, 3 + 10 + 8);
    env.remove_storage(s_new).unwrap();
    env.remove_machine(m_new).unwrap();
    assert_eq!(env.metrics().p_max, 3 + 10 + 8);
    // Removing every robot is allowed (a fleet can go empty) and the step still runs.
    for id in env.robot_ids().to_vec() {
        env.remove_robot(id).unwrap();
    }
    env.observe(&mut obs);
    assert_eq!(obs.rows, 0);
}

#[test]
fn bad_positions_for_new_bodies_are_refused() {
    let mut env = Env::new(ScenarioConfig::default(), "2.2_2".parse().unwrap(), 1).unwrap();
    assert!(matches!(
        env.add_robot(Some([5.0, 0.0])),
        Err(SimError::BadPosition { .. })
    ));
    assert!(matches!(
        env.add_robot(Some([f32::NAN, 0.0])),
        Err(SimError::BadPosition { .. })
    ));
    let m = env.machines().next().unwrap().centre;
    assert!(env.add_robot(Some(m)).is_err());
    assert!(env.add_machine(Some(m)).is_err());
}

#[test]
fn observation_matches_world_state() {
    let env = env_with(
        "3.2_1",
        &[[-0.5, -0.5], [0.5, 0.5], [0.0, 0.7]],
        &[[0.0, 0.0], [-0.6, 0.5]],
        &[[0.6, -0.6]],
    );
    let mut o = obs::ObsBatch::default();
    env.observe(&mut o);
    assert_eq!(o.own_row(1), &[0.5, 0.5, 0.0]);
    assert_eq!(o.machines_row(1), &[-0.5, -0.5, 1.0, -1.1, 0.0, 1.0]);
    let s = o.storages_row(0);
    assert!((s[0] - 1.1).abs() < 1e-6 && (s[1] + 0.1).abs() < 1e-6);
    // peers of robot 1: robots 0 and 2 in robot order
    let p = o.peers_row(1);
    assert_eq!(p.len(), 6);
    assert!((p[0] + 1.0).abs() < 1e-6 && (p[3] + 0.5).abs() < 1e-6);
}

#[test]
fn unknown_setup_names_and_zero_groups_are_errors() {
    assert!(matches!(
        "6.4".parse::<Setup>(),
        Err(SimError::BadSetupName(_))
    ));
    assert!(Env::new(ScenarioConfig::default(), Setup::new(2, 0, 1), 0).is_err());
    assert!(Env::new(ScenarioConfig::default(), Setup::new(2, 1, 0), 0).is_err());
    match Env::new(ScenarioConfig::default(), Setup::new(3000, 60, 30), 0) {
        Err(e @ SimError::DoesNotFit { .. }) => assert!(e.to_string().contains("3000.60_30")),
        Err(e) => panic!("wrong error {e}"),
        Ok(_) => panic!("3000 robots should not fit"),
    }
    // 1000 robots still fit (the scaling benchmark needs them).
    assert!(Env::new(ScenarioConfig::default(), Setup::new(1000, 16, 2), 0).is_ok());
}

#[test]
fn shipped_default_config_is_the_default() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/default.toml");
    let cfg = ScenarioConfig::load(&path).unwrap();
    assert_eq!(cfg, ScenarioConfig::default());
}
