//! Lockstep reproducibility of the safety controllers (docs/adr/0006, 0012): a fleet of
//! `robot_node`s running greedy-ORCA (`controller:=greedy-orca`, stateful: it estimates
//! velocities from successive observations), the paper's 5-move policy behind the action
//! shield (`shield:=true`) or through the ORCA filter (`orca_filter:=true`), the bundled
//! target-action policy with robot_node's defaults (planner + filter), or matching-ORCA
//! (`controller:=matching-orca`) must reproduce the offline episode of the same code
//! exactly.
//! The harness (tests/lockstep_common) is lockstep_repro.rs's, with extra robot_node parameters.
//!
//! Needs the `robot_node` binary next to `sim_bridge` (build both:
//! `cargo test --release -p sim-bridge -p robot-node`).

mod lockstep_common;

use lockstep_common::{
    offline_episode, offline_episode_in, policy_with_states, pretrained, LockstepRun, Offline,
};

use plan::pilot::{self, FilterMargins, MatchingOrca, Outputs, Pilot, Row, Safety};
use sim::{Env, ScenarioConfig, Setup};

fn offline_greedy_orca(setup: Setup, seed: u64, steps: u32) -> Offline {
    let init = |env: &Env| {
        (
            learn::baselines::GreedyOrcaFleet::new(env).unwrap(),
            Vec::new(),
        )
    };
    offline_episode(setup, seed, steps, init, |(fleet, vels), batch, env| {
        fleet.act(batch, vels).unwrap();
        env.step_velocities(vels).unwrap();
    })
}

/// One pilot per robot of `env` (`plan::Pilot`, the path `tending eval` and robot_node
/// drive a policy through) behind `safety`.
fn pilots(env: &Env, outputs: Outputs, safety: Safety) -> Vec<Pilot> {
    let fleet = learn::baselines::fleet_params(env.sizes(), env.config());
    vec![Pilot::new(&fleet, outputs, safety).unwrap(); env.n_robots()]
}

/// A policy as robot_node runs it: argmax actions (masked by each robot's shield when its
/// pilot has one) through its pilot.
fn offline_piloted(
    setup: Setup,
    seed: u64,
    steps: u32,
    path: &std::path::Path,
    outputs: Outputs,
    safety: Safety,
) -> Offline {
    let init = |env: &Env| {
        (
            pilots(env, outputs, safety),
            policy_with_states(path, env),
            Vec::new(),
        )
    };
    offline_episode(
        setup,
        seed,
        steps,
        init,
        |(pilots, (pol, states), vels), batch, env| {
            let acts: Vec<u8> = (0..batch.rows)
                .map(|r| {
                    let row = batch.row(r);
                    let mut l = pol.logits(&row, &mut states[r]).unwrap().to_vec();
                    pilots[r].shield_logits(Row::of(&row, 0), &mut l);
                    nn::categorical::argmax(&l) as u8
                })
                .collect();
            pilot::commands(pilots, batch, &acts, vels);
            env.step_velocities(vels).unwrap();
        },
    )
}

/// The bundled target-action policy as robot_node runs it by default and `tending eval`
/// evaluates it: the chosen box as a straight-line velocity (`plan::targets`) planned and
/// filtered by its pilot with the deployed margins (40 mm clearance, its make-room).
fn offline_targets(setup: Setup, seed: u64, steps: u32, path: &std::path::Path) -> Offline {
    let safety = Safety::filtered(FilterMargins::DEPLOYED);
    offline_piloted(setup, seed, steps, path, Outputs::Targets, safety)
}

/// matching-ORCA (`plan::MatchingOrca`, robot_node's `controller:=matching-orca`): every
/// robot always asks for the menu's "matched" entry, through the deployed ORCA filter.
fn offline_matching_orca(setup: Setup, seed: u64, steps: u32) -> Offline {
    offline_matching_orca_in(&ScenarioConfig::default(), setup, seed, steps)
}

fn offline_matching_orca_in(cfg: &ScenarioConfig, setup: Setup, seed: u64, steps: u32) -> Offline {
    let init = |env: &Env| {
        let fleet = learn::baselines::fleet_params(env.sizes(), env.config());
        let one = MatchingOrca::new(&fleet, FilterMargins::DEPLOYED).unwrap();
        (vec![one; env.n_robots()], Vec::new())
    };
    offline_episode_in(
        cfg,
        setup,
        seed,
        steps,
        init,
        |(robots, vels), batch, env| {
            vels.clear();
            vels.extend(
                robots
                    .iter_mut()
                    .enumerate()
                    .map(|(r, m)| m.velocity(Row::of(batch, r))),
            );
            env.step_velocities(vels).unwrap();
        },
    )
}

/// The bundled 5-move policy, a seed and what robot_node is told: the three ways of
/// running it that the fleet must reproduce.
fn moves_policy_reproduces(name: &str, seed: u64, offset: u16, safety: Safety, params: &[&str]) {
    let path = pretrained("smappo_moves_6.4_2.safetensors");
    let setup = Setup::new(6, 4, 2);
    let steps = 200;
    let off = offline_piloted(setup, seed, steps, &path, Outputs::Moves, safety);
    LockstepRun {
        policy: Some(&path),
        robot_params: params,
        ..LockstepRun::new(setup, seed, steps, test_domains::domain(offset))
    }
    .assert_reproduces(name, &off);
}

#[test]
fn greedy_orca_fleet_in_lockstep_reproduces_the_offline_episode() {
    let setup = Setup::new(6, 4, 2);
    let (seed, steps) = (3, 200);
    let off = offline_greedy_orca(setup, seed, steps);
    assert!(
        off.delivered > 0,
        "choose a seed where greedy-orca delivers"
    );
    LockstepRun {
        robot_params: &["controller:=greedy-orca"],
        ..LockstepRun::new(setup, seed, steps, test_domains::domain(0))
    }
    .assert_reproduces("greedy-orca", &off);
}

#[test]
fn shielded_policy_fleet_in_lockstep_reproduces_the_offline_episode() {
    let safety = Safety {
        shield: true,
        filter: None,
    };
    moves_policy_reproduces("policy+shield", 0, 1, safety, &["shield:=true"]);
}

#[test]
fn orca_filtered_policy_fleet_in_lockstep_reproduces_the_offline_episode() {
    let safety = Safety::filtered(FilterMargins::DEPLOYED);
    moves_policy_reproduces("policy+orca", 1, 2, safety, &["orca_filter:=true"]);
}

#[test]
fn bundled_target_policy_fleet_in_lockstep_reproduces_the_offline_episode() {
    let path = pretrained("smappo_6.4_2.safetensors");
    let setup = Setup::new(6, 4, 2);
    let (seed, steps) = (2, 200);
    let off = offline_targets(setup, seed, steps, &path);
    assert!(off.delivered > 0, "choose a seed where the policy delivers");
    // No parameters: the default (planner + 40 mm filter) is what is checked.
    LockstepRun {
        policy: Some(&path),
        ..LockstepRun::new(setup, seed, steps, test_domains::domain(3))
    }
    .assert_reproduces("target policy", &off);
}

#[test]
fn matching_orca_fleet_in_lockstep_reproduces_the_offline_episode() {
    let setup = Setup::new(6, 4, 2);
    let (seed, steps) = (4, 200);
    let off = offline_matching_orca(setup, seed, steps);
    assert!(
        off.delivered > 0,
        "choose a seed where matching-orca delivers"
    );
    LockstepRun {
        robot_params: &["controller:=matching-orca"],
        ..LockstepRun::new(setup, seed, steps, test_domains::domain(4))
    }
    .assert_reproduces("matching-orca", &off);
}

/// 12.8_4 on a grown floor (docs/adr/0037), every robot observing its 3 nearest of each kind.
fn grown_12_8_4_nearest_3() -> (Setup, ScenarioConfig) {
    let mut cfg = ScenarioConfig::default();
    cfg.world.floor = sim::Floor::Grown;
    cfg.observation = obs::Bound::nearest(3);
    (Setup::new(12, 8, 4), cfg)
}

/// On a grown floor (docs/adr/0037) with every robot observing only its 3 nearest
/// machines, storages and peers, robot_node applies the simulator's selection rule to what
/// it receives, in the room the bridge runs: the fleet reproduces the offline episode.
#[test]
fn a_bounded_observation_on_a_grown_floor_reproduces_the_offline_episode() {
    let (setup, cfg) = grown_12_8_4_nearest_3();
    let (seed, steps) = (2, 200);
    let off = offline_matching_orca_in(&cfg, setup, seed, steps);
    let unbounded = offline_matching_orca_in(
        &ScenarioConfig {
            observation: obs::Bound::EVERYTHING,
            ..cfg.clone()
        },
        setup,
        seed,
        steps,
    );
    assert!(off.delivered > 0, "choose a seed where it delivers");
    assert_ne!(
        (off.delivered, off.collisions),
        (unbounded.delivered, unbounded.collisions),
        "the bound changes nothing on this seed: the test would not see it ignored"
    );
    LockstepRun {
        robot_params: &["controller:=matching-orca"],
        scenario: Some(&cfg),
        ..LockstepRun::new(setup, seed, steps, test_domains::domain(5))
    }
    .assert_reproduces("matching-orca, grown floor, 3 nearest", &off);
}

/// The same floor read through cell topics (docs/adr/0038-cell-topics.md): each robot
/// subscribes to the cells of 1 m around its own (4 x 4 on this floor), never to a peer's,
/// machine's or storage's own topics, crosses cells as it drives and widens its window
/// while its 3 nearest of a kind may lie outside (3 of the 4 storages often need the whole
/// floor): the fleet still reproduces the offline episode exactly.
#[test]
fn cell_topics_on_a_grown_floor_reproduce_the_offline_episode() {
    let (setup, cfg) = grown_12_8_4_nearest_3();
    let (seed, steps) = (2, 200);
    let off = offline_matching_orca_in(&cfg, setup, seed, steps);
    let m = LockstepRun {
        robot_params: &["controller:=matching-orca", "cell_size:=1.0"],
        bridge_params: &["cell_size:=1.0"],
        scenario: Some(&cfg),
        ..LockstepRun::new(setup, seed, steps, test_domains::domain(6))
    }
    .run();
    lockstep_common::assert_same(
        "matching-orca, grown floor, 3 nearest, cells",
        &off,
        &m,
        steps,
    );
}
