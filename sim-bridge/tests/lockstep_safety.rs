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

use lockstep_common::{assert_same, fleet_lockstep, Offline};
use std::path::PathBuf;

use sim::{Env, ScenarioConfig, Setup};

fn offline(env: &Env) -> Offline {
    let m = env.metrics();
    Offline {
        delivered: m.parts_delivered,
        collected: m.parts_collected,
        collisions: m.collisions,
        mu: m.utilization(),
    }
}

fn offline_greedy_orca(setup: Setup, seed: u64, steps: u32) -> (Offline, Env) {
    let mut env = Env::new(ScenarioConfig::default(), setup, seed).unwrap();
    let first = env.clone();
    let mut fleet = sim::baselines::GreedyOrcaFleet::new(&env).unwrap();
    let (mut batch, mut vels) = (obs::ObsBatch::default(), Vec::new());
    for _ in 0..steps {
        env.observe(&mut batch);
        fleet.act(&batch, &mut vels).unwrap();
        env.step_velocities(&vels).unwrap();
    }
    (offline(&env), first)
}

fn offline_filtered(setup: Setup, seed: u64, steps: u32, path: &std::path::Path) -> Offline {
    let mut env = Env::new(ScenarioConfig::default(), setup, seed).unwrap();
    let mut fleet =
        sim::baselines::GreedyOrcaFleet::new_filter(&env, obs::orca::FILTER_CLEARANCE).unwrap();
    let k = env.config().task.k_speed;
    let mut pol = policy::Policy::load(path).unwrap();
    let mut states: Vec<_> = (0..env.n_robots()).map(|_| pol.new_state()).collect();
    let (mut batch, mut vels) = (obs::ObsBatch::default(), Vec::new());
    for _ in 0..steps {
        env.observe(&mut batch);
        let prefs: Vec<[f32; 2]> = (0..batch.rows)
            .map(|r| {
                let a = pol
                    .act(&batch.row(r), &mut states[r], policy::ActMode::Greedy)
                    .unwrap();
                sim::action_to_velocity(a, k).unwrap()
            })
            .collect();
        fleet.filter(&batch, &prefs, &mut vels).unwrap();
        env.step_velocities(&vels).unwrap();
    }
    offline(&env)
}

/// The bundled target-action policy as robot_node runs it by default: the chosen box as a
/// straight-line velocity (`obs::targets`), through the 40 mm ORCA filter.
fn offline_targets(setup: Setup, seed: u64, steps: u32, path: &std::path::Path) -> Offline {
    let mut env = Env::new(ScenarioConfig::default(), setup, seed).unwrap();
    let mut fleet =
        sim::baselines::GreedyOrcaFleet::new_filter(&env, obs::orca::FILTER_CLEARANCE).unwrap();
    let planner = sim::baselines::GreedyOrcaFleet::new(&env).unwrap();
    let mut pol = policy::Policy::load(path).unwrap();
    assert_eq!(pol.actor().arch.actions, policy::ActionSpace::Targets);
    let mut states: Vec<_> = (0..env.n_robots()).map(|_| pol.new_state()).collect();
    let (mut batch, mut prefs, mut vels) = (obs::ObsBatch::default(), Vec::new(), Vec::new());
    for _ in 0..steps {
        env.observe(&mut batch);
        let acts: Vec<u8> = (0..batch.rows)
            .map(|r| {
                pol.act(&batch.row(r), &mut states[r], policy::ActMode::Greedy)
                    .unwrap()
            })
            .collect();
        planner
            .target_velocities(&batch, &acts, &mut prefs)
            .unwrap();
        fleet.filter(&batch, &prefs, &mut vels).unwrap();
        env.step_velocities(&vels).unwrap();
    }
    offline(&env)
}

fn offline_shielded(setup: Setup, seed: u64, steps: u32, path: &std::path::Path) -> Offline {
    let mut env = Env::new(ScenarioConfig::default(), setup, seed).unwrap();
    let sp = sim::baselines::shield_params(env.sizes(), env.config());
    let mut pol = policy::Policy::load(path).unwrap();
    let mut states: Vec<_> = (0..env.n_robots()).map(|_| pol.new_state()).collect();
    let mut batch = obs::ObsBatch::default();
    for _ in 0..steps {
        env.observe(&mut batch);
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
                    &sp,
                );
                obs::shield::mask_logits(&mut l, &safe);
                policy::nn::categorical::argmax(&l) as u8
            })
            .collect();
        env.step_actions(&acts).unwrap();
    }
    offline(&env)
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
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../policy/pretrained/smappo_moves_6.4_2.safetensors");
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
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../policy/pretrained/smappo_moves_6.4_2.safetensors");
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
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../policy/pretrained/smappo_6.4_2.safetensors");
    let setup = Setup::new(6, 4, 2);
    let (seed, steps) = (2, 200);
    let off = offline_targets(setup, seed, steps, &path);
    assert!(off.delivered > 0, "choose a seed where the policy delivers");
    let env0 = Env::new(ScenarioConfig::default(), setup, seed).unwrap();
    // No parameters: the default (planner + 40 mm filter) is what is checked.
    let m = fleet_lockstep(setup, seed, steps, domain(3), &env0, Some(&path), &[]);
    assert_same("target policy", &off, &m, steps);
}
