//! The planner on the simulator: what a robot's planner infers from its observation
//! matches the simulator's truth.

use sim::{Env, ScenarioConfig, Setup};

/// The planner's machine clock (`plan::machine_clock`), fed only the ready flags a robot
/// observes, knows every machine's timer exactly when it watches from the first step.
#[test]
fn machine_clock_from_ready_flags_equals_the_simulators_timers() {
    let cfg = ScenarioConfig::default();
    let mut env = Env::new(cfg, "6.4_2".parse::<Setup>().unwrap(), 3).unwrap();
    let mut fleet = learn::baselines::GreedyOrcaFleet::new(&env).unwrap();
    let mut clock = plan::machine_clock::MachineClock::new(env.config().task.prep_steps);
    let mut batch = obs::ObsBatch::default();
    let mut cmds = Vec::new();
    let mut busy_seen = 0;
    for _ in 0..200 {
        env.observe(&mut batch);
        clock.update(batch.own_row(1), batch.machines_row(1), obs::MACHINE_DIM);
        for (m, est) in env.machines().zip(clock.ready_in()) {
            let truth = if m.part_ready { 0 } else { m.timer };
            assert_eq!(*est, Some(truth), "machine {:?}", m.id);
            busy_seen += usize::from(!m.part_ready);
        }
        fleet.act(&batch, &mut cmds).unwrap();
        env.step_velocities(&cmds).unwrap();
    }
    assert!(
        busy_seen > 100,
        "machines were busy in {busy_seen} machine-steps"
    );
}
