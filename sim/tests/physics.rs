//! Physics invariants: contact pushes apart, no tunnelling, drag, velocity tracking.
mod common;
use common::*;

const FAR_M: [f32; 2] = [-0.9, -0.9];
const FAR_S: [f32; 2] = [0.9, -0.9];

#[test]
fn constant_command_converges_to_commanded_velocity() {
    let mut env = env_with("1.1_1", &[[-0.5, 0.5]], &[FAR_M], &[FAR_S]);
    for _ in 0..5 {
        env.step_velocities(&[[0.3, 0.0]]).unwrap();
    }
    let r = env.robots().next().unwrap();
    assert!((r.vel[0] - 0.3).abs() < 1e-4, "vel {:?}", r.vel);
    assert!(r.vel[1].abs() < 1e-6);
}

#[test]
fn commands_are_clamped_to_k_speed() {
    let mut env = env_with("1.1_1", &[[-0.5, 0.5]], &[FAR_M], &[FAR_S]);
    for _ in 0..20 {
        env.step_velocities(&[[30.0, 0.0]]).unwrap();
        let r = env.robots().next().unwrap();
        if r.pos[0] > 0.6 {
            break;
        }
    }
    let r = env.robots().next().unwrap();
    assert!(r.vel[0] <= 0.5 + 1e-4, "vel {:?}", r.vel);
}

#[test]
fn drag_slows_a_coasting_robot_by_a_quarter_per_step() {
    let mut env = env_with("1.1_1", &[[-0.5, 0.5]], &[FAR_M], &[FAR_S]);
    let id = env.robot_ids()[0];
    env.set_robot_state(id, [-0.5, 0.5], [0.4, 0.0]).unwrap();
    // A zero command asks the tracker to stop; with max_force small it mostly coasts.
    let mut cfg = env.config().clone();
    cfg.physics.max_force = 1e-9;
    let mut env = env_with_cfg(cfg, "1.1_1", &[[-0.5, 0.5]], &[FAR_M], &[FAR_S]);
    env.set_robot_state(id, [-0.5, 0.5], [0.4, 0.0]).unwrap();
    env.step_velocities(&[[0.0, 0.0]]).unwrap();
    let v = env.robots().next().unwrap().vel[0];
    assert!((v - 0.3).abs() < 1e-5, "v {v}");
}

#[test]
fn overlapping_robots_are_pushed_apart() {
    let r = 0.08;
    let mut env = env_with("2.1_1", &[[0.0, 0.0], [1.5 * r, 0.0]], &[FAR_M], &[FAR_S]);
    let d0 = 1.5 * r;
    env.step_velocities(&[[0.0, 0.0], [0.0, 0.0]]).unwrap();
    let p: Vec<_> = env.robots().map(|r| r.pos).collect();
    let d1 = p[1][0] - p[0][0];
    assert!(d1 > d0, "distance {d0} -> {d1}");
    // Symmetric: momentum conserved.
    let v: Vec<_> = env.robots().map(|r| r.vel).collect();
    assert!((v[0][0] + v[1][0]).abs() < 1e-5);
}

#[test]
fn robots_cannot_tunnel_through_walls_at_full_speed() {
    let mut env = env_with("1.1_1", &[[0.9, 0.0]], &[FAR_M], &[FAR_S]);
    let r = env.sizes().robot_radius;
    let mut max_x = f32::MIN;
    for _ in 0..100 {
        env.step_actions(&[2]).unwrap(); // right, into the wall
        max_x = max_x.max(env.robots().next().unwrap().pos[0]);
    }
    assert!(max_x < 1.15, "centre crossed the wall: {max_x}");
    assert!(max_x > 1.15 - r - 0.05, "never reached the wall: {max_x}");
    assert!(env.metrics().collisions_robot_wall > 0);
}

#[test]
fn robot_cannot_drive_through_a_machine() {
    let mut env = env_with("1.1_1", &[[-0.6, 0.0]], &[[0.0, 0.0]], &[FAR_S]);
    for _ in 0..80 {
        env.step_actions(&[2]).unwrap();
    }
    let x = env.robots().next().unwrap().pos[0];
    assert!(x < 0.0, "robot passed through the machine: x = {x}");
    assert!(env.metrics().collisions_robot_machine > 0);
}

#[test]
fn nan_and_wrong_count_commands_are_refused_without_moving() {
    let mut env = env_with("1.1_1", &[[0.0, 0.0]], &[FAR_M], &[FAR_S]);
    let e = env.step_velocities(&[[f32::NAN, 0.0]]).unwrap_err();
    assert!(e.to_string().contains("not finite"), "{e}");
    let e = env.step_velocities(&[[f32::INFINITY, 0.0]]).unwrap_err();
    assert!(matches!(e, sim::SimError::NonFiniteCommand { .. }));
    assert!(env.step_velocities(&[]).is_err());
    assert!(env.step_actions(&[9]).is_err());
    assert_eq!(env.steps(), 0);
    assert_eq!(env.robots().next().unwrap().pos, [0.0, 0.0]);
}
