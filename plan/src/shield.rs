//! A one-step safety shield over the discrete actions (Alshiekh et al. 2018, "Safe
//! reinforcement learning via shielding", preemptive form): an action is masked when the
//! robot's position one period ahead, moving at K_speed on that axis, would come within
//! a margin of a body it observes (peer, machine, storage, wall) *and* closer to it than
//! now. "Stay" never approaches anything, so at least one action is always allowed.
//!
//! One implementation for every user: evaluation and training (the simulator's
//! observation) and robot_node (the same observation built from topics) call
//! [`safe_actions`] and [`mask_logits`] on the actor's logits.
//!
//! What it cannot see: peers' motion (the observation has no velocities), so a peer is
//! given a margin of `peer_step` extra, the distance it could close in one period; the
//! box the robot must touch to pick or place (a ready machine without a part, a storage
//! with one) is exempt, else a robot whose reach is shorter than one step could never
//! get there.

use crate::geom::{box_distance, norm};

/// The discrete moves as unit directions (the paper's 5, then 4 diagonals): the shield
/// judges all 9, a 5-action policy's logits take the first 5.
pub use obs::action::MOVES;

/// Logit given to a masked action: far below any real logit, finite so that softmax,
/// log-probabilities and entropy stay finite (exp underflows to exactly 0).
pub const MASKED_LOGIT: f32 = -1.0e9;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShieldParams {
    pub robot_radius: f32,
    pub machine_half: [f32; 2],
    pub storage_half: [f32; 2],
    /// Speed of one discrete action, m/s.
    pub k_speed: f32,
    /// Control period, s.
    pub dt: f32,
    /// Half the side of the square room, m.
    pub room_half: f32,
    /// Gap below which a body counts as touched, m (the simulator's collision distance
    /// plus a little for the velocity tracker's lag).
    pub margin: f32,
    /// Extra gap kept to peers for the distance they may close in one period, m.
    pub peer_step: f32,
}

impl ShieldParams {
    /// Defaults for a fleet: margin 15 mm (the simulator counts contact at 5 mm), peers
    /// assumed to close half a step each period (both robots shielded share the step).
    pub fn new(
        robot_radius: f32,
        machine_half: [f32; 2],
        storage_half: [f32; 2],
        k_speed: f32,
        dt: f32,
        room_size: f32,
    ) -> Self {
        Self {
            robot_radius,
            machine_half,
            storage_half,
            k_speed,
            dt,
            room_half: room_size / 2.0,
            margin: 0.015,
            peer_step: 0.5 * k_speed * dt,
        }
    }
}

/// Which of the 5 actions are safe for one observation row (layout of `ObsBatch`).
pub fn safe_actions(
    own: &[f32],
    machines: &[f32],
    storages: &[f32],
    peers: &[f32],
    p: &ShieldParams,
) -> [bool; obs::action::N_ACTIONS_WITH_DIAGONALS] {
    let r = p.robot_radius;
    let step = p.k_speed * p.dt;
    let has_part = own[2] > 0.5;
    let pos = [own[0], own[1]];
    let mut safe = [true; obs::action::N_ACTIONS_WITH_DIAGONALS];
    for (a, mv) in MOVES.iter().enumerate().skip(1) {
        let next = [mv[0] * step, mv[1] * step];
        // Unsafe: the gap after the move is below the limit and smaller than now.
        let closes = |now: f32, then: f32, limit: f32| then < limit && then < now;
        let peer_hit = peers.chunks_exact(3).any(|q| {
            let now = norm([q[0], q[1]]) - 2.0 * r;
            let then = norm([q[0] - next[0], q[1] - next[1]]) - 2.0 * r;
            closes(now, then, p.margin + p.peer_step)
        });
        let box_hit = |c: [f32; 2], half: [f32; 2]| {
            let now = box_distance(c, half, [0.0, 0.0]) - r;
            let then = box_distance(c, half, next) - r;
            closes(now, then, p.margin)
        };
        // A ready machine is a pick target for a robot without a part: exempt.
        let machine_hit = machines.chunks_exact(3).any(|m| {
            let target = m[2] > 0.5 && !has_part;
            !target && box_hit([m[0], m[1]], p.machine_half)
        });
        let storage_hit = !has_part
            && storages
                .chunks_exact(2)
                .any(|s| box_hit([s[0], s[1]], p.storage_half));
        let wall_hit = (0..2).any(|ax| {
            let now = p.room_half - pos[ax].abs() - r;
            let then = p.room_half - (pos[ax] + next[ax]).abs() - r;
            closes(now, then, p.margin)
        });
        safe[a] = !(peer_hit || machine_hit || storage_hit || wall_hit);
    }
    safe
}

/// Set the logits of unsafe actions to [`MASKED_LOGIT`]; returns how many were masked.
pub fn mask_logits(logits: &mut [f32], safe: &[bool]) -> usize {
    let mut n = 0;
    for (l, ok) in logits.iter_mut().zip(safe) {
        if !ok {
            *l = MASKED_LOGIT;
            n += 1;
        }
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> ShieldParams {
        ShieldParams::new(0.08, [0.12, 0.12], [0.15, 0.08], 0.5, 0.1, 2.3)
    }

    #[test]
    fn masks_moves_into_a_close_peer_only() {
        // A peer 0.2 m to the right (gap 0.04): moving right closes it to -0.01.
        let s = safe_actions(&[0.0, 0.0, 0.0], &[], &[0.9, 0.9], &[0.2, 0.0, 0.0], &p());
        // right, and the two diagonals with a rightward part, are masked
        assert_eq!(s, [true, true, false, true, true, true, false, true, false]);
        // Far peer: nothing masked.
        let s = safe_actions(&[0.0, 0.0, 0.0], &[], &[0.9, 0.9], &[0.6, 0.0, 0.0], &p());
        assert_eq!(s, [true; 9]);
    }

    #[test]
    fn walls_and_non_target_boxes_are_masked_targets_are_not() {
        // Near the left wall: left masked.
        let s = safe_actions(&[-1.05, 0.0, 0.0], &[], &[2.0, 0.9], &[], &p());
        assert!(!s[1] && s[2]);
        // A not-ready machine just below (gap 0.02): down masked.
        let m = [0.0, -0.22, 0.0];
        let s = safe_actions(&[0.0, 0.0, 0.0], &m, &[2.0, 0.9], &[], &p());
        assert!(!s[3], "{s:?}");
        // The same machine ready and no part: it is the pick target, allowed.
        let m = [0.0, -0.22, 1.0];
        let s = safe_actions(&[0.0, 0.0, 0.0], &m, &[2.0, 0.9], &[], &p());
        assert!(s[3], "{s:?}");
        // Carrying a part: a storage just above is the place target, allowed.
        let s = safe_actions(&[0.0, 0.0, 1.0], &[], &[0.0, 0.18], &[], &p());
        assert!(s[4], "{s:?}");
    }

    #[test]
    fn stay_is_always_safe_and_masking_keeps_logits_finite() {
        let peers = [
            0.17, 0.0, 0.0, -0.17, 0.0, 0.0, 0.0, 0.17, 0.0, 0.0, -0.17, 0.0,
        ];
        let s = safe_actions(&[0.0, 0.0, 0.0], &[], &[0.9, 0.9], &peers, &p());
        assert_eq!(
            s,
            [true, false, false, false, false, false, false, false, false]
        );
        // a 5-action policy's logits take the first 5 verdicts
        let mut l = [0.1, 3.0, 2.0, 1.0, 0.5];
        assert_eq!(mask_logits(&mut l, &s), 4);
        assert!(l.iter().all(|x| x.is_finite()));
        assert_eq!(
            l.iter()
                .enumerate()
                .max_by(|a, b| a.1.total_cmp(b.1))
                .unwrap()
                .0,
            0
        );
    }
}
