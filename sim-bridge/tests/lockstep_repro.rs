//! Reproducibility: in lockstep, a fleet of `robot_node` processes on `sim_bridge` must
//! reproduce an offline episode of the same controller, setup and seed (same parts,
//! collisions and MU), with no lockstep timeout on either side.
//!
//! Needs the `robot_node` binary next to `sim_bridge` (build both:
//! `cargo test --release -p sim-bridge -p robot-node`).

mod lockstep_common;

use lockstep_common::{
    greedy_policy_actions, offline_episode, policy_with_states, pretrained, LockstepRun, Offline,
};

use sim::{Env, Setup};

fn offline_greedy(setup: Setup, seed: u64, steps: u32) -> Offline {
    offline_episode(
        setup,
        seed,
        steps,
        |env| learn::baselines::fleet_params(env.sizes(), env.config()).greedy_params(),
        |params, batch, env| {
            let acts: Vec<u8> = (0..batch.rows)
                .map(|r| {
                    plan::greedy::greedy_action(
                        batch.own_row(r),
                        batch.machines_row(r),
                        batch.storages_row(r),
                        batch.peers_row(r),
                        params,
                    )
                })
                .collect();
            env.step_actions(&acts).unwrap();
        },
    )
}

fn offline_policy(setup: Setup, seed: u64, steps: u32, path: &std::path::Path) -> Offline {
    let init = |env: &Env| policy_with_states(path, env);
    offline_episode(setup, seed, steps, init, |(pol, states), batch, env| {
        env.step_actions(&greedy_policy_actions(pol, states, batch))
            .unwrap();
    })
}

#[test]
fn greedy_fleet_in_lockstep_reproduces_the_offline_episode() {
    let setup = Setup::new(4, 3, 2);
    let (seed, steps) = (5, 200);
    let off = offline_greedy(setup, seed, steps);
    assert!(
        off.delivered > 0,
        "choose a seed where greedy delivers something"
    );
    LockstepRun::new(setup, seed, steps, test_domains::domain(0)).assert_reproduces("greedy", &off);
}

/// The bridge publishes the first state as soon as every robot's cmd_vel is discovered,
/// before the robots have subscribed to their state: the state and the answers go out again
/// until they get through (ADR 0029), and no robot is lost. (Without resends every robot
/// was despawned. The episode itself is not compared: a robot acting before it discovered
/// every peer sees fewer bodies than the offline episode does, which is what `settle_s`
/// is for.)
#[test]
fn lockstep_without_settling_loses_no_robot() {
    let setup = Setup::new(4, 3, 2);
    let (seed, steps) = (5, 60);
    let m = LockstepRun {
        bridge_params: &["settle_s:=0.0"],
        ..LockstepRun::new(setup, seed, steps, test_domains::domain(3))
    }
    .run();
    eprintln!("no settling: {m}");
    assert_eq!(m["step"], steps, "{m}");
    assert_eq!(m["despawned"], 0, "{m}");
    assert_eq!(m["lockstep_timeouts"], 0, "{m}");
    assert_eq!(m["robots_on_state"], setup.robots, "{m}");
}

#[test]
fn paper_policy_fleet_in_lockstep_reproduces_the_offline_episode() {
    // The paper's 5-move policy, raw: its actions are stepped as the simulator's own.
    let path = pretrained("smappo_moves_6.4_2.safetensors");
    let setup = Setup::new(6, 4, 2);
    let (seed, steps) = (0, 200);
    let off = offline_policy(setup, seed, steps, &path);
    // The raw policy: robot_node's default ORCA filter off (lockstep_safety covers it).
    LockstepRun {
        policy: Some(&path),
        robot_params: &["orca_filter:=false"],
        ..LockstepRun::new(setup, seed, steps, test_domains::domain(1))
    }
    .assert_reproduces("policy", &off);
}

/// The same episode with DDS Security on (every process in its own enclave, Enforce):
/// authentication, access control and encryption change nothing the fleet computes.
#[test]
fn secure_policy_fleet_in_lockstep_reproduces_the_offline_episode() {
    let path = pretrained("smappo_moves_6.4_2.safetensors");
    let setup = Setup::new(6, 4, 2);
    let (seed, steps) = (0, 200);
    let off = offline_policy(setup, seed, steps, &path);
    let root = std::env::temp_dir().join(format!("tending-lockstep-ks-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let ks = keystore::Keystore::create(&root).unwrap();
    let robots: Vec<String> = (0..setup.robots).map(|i| format!("robot_{i}")).collect();
    ks.create_fleet_enclaves(&robots, keystore::Validity::days_from_now(1))
        .unwrap();
    LockstepRun {
        policy: Some(&path),
        robot_params: &["orca_filter:=false"],
        keystore: Some(&root),
        ..LockstepRun::new(setup, seed, steps, test_domains::domain(2))
    }
    .assert_reproduces("secure policy", &off);
    std::fs::remove_dir_all(root).unwrap();
}
