//! The paper's 5 discrete actions as holonomic velocity commands.

/// Number of discrete actions: 0 stay, 1 left, 2 right, 3 down, 4 up.
pub const N_ACTIONS: usize = 5;

/// Velocity command (vx, vy) of action `a` at speed `k_speed`; None if `a` is not 0..5.
#[inline]
pub fn action_to_velocity(a: u8, k_speed: f32) -> Option<[f32; 2]> {
    Some(match a {
        0 => [0.0, 0.0],
        1 => [-k_speed, 0.0],
        2 => [k_speed, 0.0],
        3 => [0.0, -k_speed],
        4 => [0.0, k_speed],
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn axes_match_the_paper() {
        assert_eq!(super::action_to_velocity(1, 0.5), Some([-0.5, 0.0]));
        assert_eq!(super::action_to_velocity(4, 0.5), Some([0.0, 0.5]));
        assert_eq!(super::action_to_velocity(5, 0.5), None);
    }
}
