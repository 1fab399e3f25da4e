//! The one action table: discrete actions as holonomic velocity commands, used by the
//! simulator, the shield, the trainer and robot_node alike.
//!
//! Actions 0-4 are the paper's (stay, -x, +x, -y, +y at K_speed). Actions 5-8 add the four
//! diagonals at the same speed, for policies trained with `diagonal_actions = true`:
//! with axis moves only, a robot covers |dx| + |dy| instead of the straight distance, on
//! average 4/pi = 1.27x longer, a handicap no scripted baseline with continuous velocities
//! (greedy-ORCA) has. A 5-action policy never outputs 5-8, so both share this table.

use std::f32::consts::FRAC_1_SQRT_2 as D;

/// The paper's action count: 0 stay, 1 left, 2 right, 3 down, 4 up.
pub const N_AXIS_ACTIONS: usize = 5;
/// With the diagonals: 5 left-down, 6 right-down, 7 left-up, 8 right-up.
pub const N_ACTIONS_WITH_DIAGONALS: usize = 9;

/// Unit direction of each action (stay is zero), indexed by action.
pub const MOVES: [[f32; 2]; N_ACTIONS_WITH_DIAGONALS] = [
    [0.0, 0.0],
    [-1.0, 0.0],
    [1.0, 0.0],
    [0.0, -1.0],
    [0.0, 1.0],
    [-D, -D],
    [D, -D],
    [-D, D],
    [D, D],
];

/// Velocity command (vx, vy) of action `a` at speed `k_speed`; None if `a` is not an
/// action of the table.
#[inline]
pub fn velocity(a: u8, k_speed: f32) -> Option<[f32; 2]> {
    MOVES
        .get(a as usize)
        .map(|m| [m[0] * k_speed, m[1] * k_speed])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axes_match_the_paper_and_diagonals_keep_the_speed() {
        assert_eq!(velocity(0, 0.5), Some([0.0, 0.0]));
        assert_eq!(velocity(1, 0.5), Some([-0.5, 0.0]));
        assert_eq!(velocity(4, 0.5), Some([0.0, 0.5]));
        for a in 5..9u8 {
            let v = velocity(a, 0.5).unwrap();
            assert!(((v[0] * v[0] + v[1] * v[1]).sqrt() - 0.5).abs() < 1e-6);
        }
        assert_eq!(
            velocity(8, 1.0).map(|v| v[0] > 0.0 && v[1] > 0.0),
            Some(true)
        );
        assert_eq!(velocity(9, 0.5), None);
    }
}
