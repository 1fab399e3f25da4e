//! Lockstep reproducibility of the safety controllers (docs/adr/0006, 0012): a fleet of
//! `robot_node`s running greedy-ORCA (`controller:=greedy-orca`, stateful: it estimates
//! velocities from successive observations), the paper's 5-move policy behind the action
//! shield (`shield:=true`) or through the ORCA filter (`orca_filter:=true`), or the bundled
//! target-action policy with robot_node's defaults (planner + filter) must reproduce the
//! offline episode of the same code exactly.
//! The harness (tests/lockstep_common) is lockstep_repro.rs's, with extra robot_node parameters.
//!
//! Needs the `robot_node` binary next to `sim_bridge` (build both:
//! `cargo test --release -p sim-bridge -p robot-node`).

mod lockstep_common;

use lockstep_common::{
    assert_same, fleet_lockstep, greedy_policy_actions, offline_episode, policy_with_states,
    pretrained, Offline,
};

use sim::{Env, ScenarioConfig, Setup};

fn offline_greedy_orca(setup: Setup, seed: u64, steps: u32) -> (Offline, Env) {
    let init = |env: &Env| {
        (
            sim::baselines::GreedyOrcaFleet::new(env).unwrap(),
            Vec::new(),
        )
    };
    offline_episode(setup, seed, steps, init, |(fleet, vels), batch, env| {
        fleet.act(batch, vels).unwrap();
        env.step_velocities(vels).unwrap();
    })
}

fn offline_filtered(setup: Setup, seed: u64, steps: u32, path: &std::path::Path) -> Offline {
    let init = |env: &Env| {
        let fleet =
            sim::baselines::GreedyOrcaFleet::new_filter(env, Some(obs::orca::FILTER_CLEARANCE))
                .unwrap();
        let k = env.config().task.k_speed;
        (fleet, k, policy_with_states(path, env), Vec::new())
    };
    offline_episode(
        setup,
        seed,
        steps,
        init,
        |(fleet, k, (pol, states), vels), batch, env| {
            let prefs: Vec<[f32; 2]> = greedy_policy_actions(pol, states, batch)
                .into_iter()
                .map(|a| sim::action_to_velocity(a, *k).unwrap())
                .collect();
            fleet.filter(batch, &prefs, vels).unwrap();
            env.step_velocities(vels).unwrap();
        },
    )
    .0
}

/// The bundled target-action policy as robot_node runs it by default and `tending eval`
/// evaluates it: the chosen box as a straight-line velocity (`obs::targets`) planned and
/// filtered by one fleet with the policy's parameters (40 mm clearance, its make-room).
fn offline_targets(setup: Setup, seed: u64, steps: u32, path: &std::path::Path) -> Offline {
    let init = |env: &Env| {
        let fleet =
            sim::baselines::GreedyOrcaFleet::new_filter(env, Some(obs::orca::FILTER_CLEARANCE))
                .unwrap();
        let (pol, states) = policy_with_states(path, env);
        assert_eq!(pol.actor().arch.actions, policy::ActionSpace::Targets);
        (fleet, pol, states, Vec::new(), Vec::new())
    };
    offline_episode(
        setup,
        seed,
        steps,
        init,
        |(fleet, pol, states, prefs, vels), batch, env| {
            let acts = greedy_policy_actions(pol, states, batch);
            fleet.target_velocities(batch, &acts, prefs).unwrap();
            fleet.filter(batch, prefs, vels).unwrap();
            env.step_velocities(vels).unwrap();
        },
    )
    .0
}

fn offline_shielded(setup: Setup, seed: u64, steps: u32, path: &std::path::Path) -> Offline {
    let init = |env: &Env| {
        let sp = sim::baselines::shield_params(env.sizes(), env.config());
        (sp, policy_with_states(path, env))
    };
    offline_episode(
        setup,
        seed,
        steps,
        init,
        |(sp, (pol, states)), batch, env| {
            let acts: Vec<u8> = (0..batch.rows)
                .map(|r| {
                    let row = batch.row(r);
                    let mut l = [0.0f32; 5];
                    l.copy_from_slice(pol.logits(&row, &mut states[r]).unwrap());
                    let safe = obs::shield::safe_actions(
                        row.own_row(0),
                        row.machines_row(0),
                        row.storages_row(0),
                        row.peers_row(0),
                        sp,
                    );
                    obs::shield::mask_logits(&mut l, &safe);
                    policy::nn::categorical::argmax(&l) as u8
                })
                .collect();
            env.step_actions(&acts).unwrap();
        },
    )
    .0
}

fn domain(offset: u16) -> u16 {
    (std::process::id() % 50) as u16 * 2 + 120 + offset
}

#[test]
fn greedy_orca_fleet_in_lockstep_reproduces_the_offline_episode() {
    let setup = Setup::new(6, 4, 2);
    let (seed, steps) = (3, 200);
    let (off, env0) = offline_greedy_orca(setup, seed, steps);
    assert!(
        off.delivered > 0,
        "choose a seed where greedy-orca delivers"
    );
    let m = fleet_lockstep(
        setup,
        seed,
        steps,
        domain(0),
        &env0,
        None,
        &["controller:=greedy-orca"],
    );
    assert_same("greedy-orca", &off, &m, steps);
}

#[test]
fn shielded_policy_fleet_in_lockstep_reproduces_the_offline_episode() {
    let path = pretrained("smappo_moves_6.4_2.safetensors");
    if !path.exists() {
        eprintln!("SKIPPED: no bundled checkpoint at {}", path.display());
        return;
    }
    let setup = Setup::new(6, 4, 2);
    let (seed, steps) = (0, 200);
    let off = offline_shielded(setup, seed, steps, &path);
    let env0 = Env::new(ScenarioConfig::default(), setup, seed).unwrap();
    let m = fleet_lockstep(
        setup,
        seed,
        steps,
        domain(1),
        &env0,
        Some(&path),
        &["shield:=true"],
    );
    assert_same("policy+shield", &off, &m, steps);
}

#[test]
fn orca_filtered_policy_fleet_in_lockstep_reproduces_the_offline_episode() {
    let path = pretrained("smappo_moves_6.4_2.safetensors");
    if !path.exists() {
        eprintln!("SKIPPED: no bundled checkpoint at {}", path.display());
        return;
    }
    let setup = Setup::new(6, 4, 2);
    let (seed, steps) = (1, 200);
    let off = offline_filtered(setup, seed, steps, &path);
    let env0 = Env::new(ScenarioConfig::default(), setup, seed).unwrap();
    let m = fleet_lockstep(
        setup,
        seed,
        steps,
        domain(2),
        &env0,
        Some(&path),
        &["orca_filter:=true"],
    );
    assert_same("policy+orca", &off, &m, steps);
}

#[test]
fn bundled_target_policy_fleet_in_lockstep_reproduces_the_offline_episode() {
    let path = pretrained("smappo_6.4_2.safetensors");
    let setup = Setup::new(6, 4, 2);
    let (seed, steps) = (2, 200);
    let off = offline_targets(setup, seed, steps, &path);
    assert!(off.delivered > 0, "choose a seed where the policy delivers");
    let env0 = Env::new(ScenarioConfig::default(), setup, seed).unwrap();
    // No parameters: the default (planner + 40 mm filter) is what is checked.
    let m = fleet_lockstep(setup, seed, steps, domain(3), &env0, Some(&path), &[]);
    assert_same("target policy", &off, &m, steps);
}
