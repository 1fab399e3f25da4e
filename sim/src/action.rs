//! Discrete actions as holonomic velocity commands: the one table lives in `obs::action`
//! (shared with every controller above); this names it as the simulator uses it.

/// The paper's action count (0 stay, 1 left, 2 right, 3 down, 4 up): the random baseline
/// draws from these. Policies trained with diagonals use `obs::action` 5-8 as well.
pub const N_ACTIONS: usize = obs::action::N_AXIS_ACTIONS;

/// Velocity command (vx, vy) of action `a` at speed `k_speed`; None if `a` is not in the
/// table (0..9).
#[inline]
pub fn action_to_velocity(a: u8, k_speed: f32) -> Option<[f32; 2]> {
    obs::action::velocity(a, k_speed)
}

#[cfg(test)]
mod tests {
    #[test]
    fn axes_match_the_paper() {
        assert_eq!(super::action_to_velocity(1, 0.5), Some([-0.5, 0.0]));
        assert_eq!(super::action_to_velocity(4, 0.5), Some([0.0, 0.5]));
        assert_eq!(super::action_to_velocity(9, 0.5), None);
    }
}
