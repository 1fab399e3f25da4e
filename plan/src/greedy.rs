//! The scripted greedy baseline, on the observation alone.
//!
//! It lives in the planner, below the simulator and `robot_node`, so the simulator (offline
//! episodes) and `robot_node` (on the robot, built from ROS topics) run one and the same
//! function: an
//! offline greedy episode and a fleet of greedy `robot_node`s on the sim bridge must agree
//! step for step.

/// What the greedy controller knows about the world besides its observation: the fleet's
/// body sizes, the action speed and the control period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GreedyParams {
    pub robot_radius: f32,
    /// Half extents of a machine box.
    pub machine_half: [f32; 2],
    /// Half extents of a storage box.
    pub storage_half: [f32; 2],
    /// Speed of one discrete action, m/s.
    pub k_speed: f32,
    /// Control period, s.
    pub dt: f32,
    /// Steps a machine takes to make a part after its last was picked
    /// ([`crate::machine_clock`]).
    pub prep_steps: u32,
}

impl Default for GreedyParams {
    /// The default scenario's at scale 1 (`obs::defaults`, the source of sim's defaults
    /// too).
    fn default() -> Self {
        use obs::defaults as d;
        Self {
            robot_radius: d::ROBOT_RADIUS,
            machine_half: d::MACHINE_HALF,
            storage_half: d::STORAGE_HALF,
            k_speed: d::K_SPEED,
            dt: d::DT,
            prep_steps: d::PREP_STEPS,
        }
    }
}

const MOVES: [[f32; 2]; 5] = [[0.0, 0.0], [-1.0, 0.0], [1.0, 0.0], [0.0, -1.0], [0.0, 1.0]];

/// The box a greedy robot heads for, relative to the robot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Target {
    /// Box centre relative to the robot.
    pub rel: [f32; 2],
    /// Half extents of the box.
    pub half: [f32; 2],
}

/// Greedy task allocation: without a part, the nearest ready machine that no nearer
/// part-less peer is closer to; with a part, the nearest storage. None: nothing to do.
/// Shared by [`greedy_action`] and [`crate::orca`], so both allocate tasks alike.
pub fn greedy_target(
    own: &[f32],
    machines: &[f32],
    storages: &[f32],
    peers: &[f32],
    p: &GreedyParams,
) -> Option<Target> {
    let has_part = own[2] > 0.5;
    let mut target = None;
    if has_part {
        let mut best = f32::INFINITY;
        for s in storages.chunks_exact(2) {
            let d = s[0] * s[0] + s[1] * s[1];
            if d < best {
                best = d;
                target = Some(Target {
                    rel: [s[0], s[1]],
                    half: p.storage_half,
                });
            }
        }
    } else {
        let mut best = f32::INFINITY;
        for m in machines.chunks_exact(3) {
            if m[2] < 0.5 {
                continue;
            }
            let mine = m[0] * m[0] + m[1] * m[1];
            if !claimed_by_a_nearer_peer(m, peers) && mine < best {
                best = mine;
                target = Some(Target {
                    rel: [m[0], m[1]],
                    half: p.machine_half,
                });
            }
        }
    }
    target
}

/// Whether a part-less peer is nearer than this robot to machine `m` (a machine row,
/// relative (dx, dy) first): greedy's claim rule, shared with the target menu.
pub fn claimed_by_a_nearer_peer(m: &[f32], peers: &[f32]) -> bool {
    let mine = m[0] * m[0] + m[1] * m[1];
    peers.chunks_exact(3).any(|q| {
        q[2] < 0.5 && {
            let (dx, dy) = (m[0] - q[0], m[1] - q[1]);
            dx * dx + dy * dy < mine
        }
    })
}

/// Decentralized greedy: heads for [`greedy_target`]. Moves on one axis
/// at a time (the 5-action set), preferring the axis with the larger gap, and avoids a
/// move that would bring it into contact with a peer or a box other than its target.
pub fn greedy_action(
    own: &[f32],
    machines: &[f32],
    storages: &[f32],
    peers: &[f32],
    p: &GreedyParams,
) -> u8 {
    let has_part = own[2] > 0.5;
    let r = p.robot_radius;
    let Some(Target { rel: t, .. }) = greedy_target(own, machines, storages, peers, p) else {
        return 0;
    };
    let step = p.k_speed * p.dt;
    // Candidate moves: the axis with the larger gap first, then the other axis, then the
    // two sideways moves (to slide around an obstacle).
    let (ax, ay) = (t[0].abs(), t[1].abs());
    let sx = if t[0] < 0.0 { 1u8 } else { 2 };
    let sy = if t[1] < 0.0 { 3u8 } else { 4 };
    let (first, second) = if ax >= ay { (sx, sy) } else { (sy, sx) };
    let side = if ax >= ay { [3u8, 4] } else { [1u8, 2] };
    let candidates = [first, second, side[0], side[1]];
    let min_gap = 0.5 * step;
    for &a in &candidates {
        let mv = MOVES[a as usize];
        // Skip a move along an axis where the target is already aligned within a step
        // (it would overshoot and oscillate), unless it is a sideways escape.
        let along = [t[0], t[1]][if mv[0] != 0.0 { 0 } else { 1 }];
        if (a == first || a == second) && along.abs() < step * 0.5 {
            continue;
        }
        let next = [mv[0] * step, mv[1] * step];
        let peer_ok = peers.chunks_exact(3).all(|q| {
            let (dx, dy) = (q[0] - next[0], q[1] - next[1]);
            let now = q[0] * q[0] + q[1] * q[1];
            let then = dx * dx + dy * dy;
            // Allow moves that increase distance even when already close.
            then >= (2.0 * r + min_gap).powi(2) || then > now
        });
        let box_ok = |c: &[f32], half: [f32; 2], is_target: bool| {
            if is_target {
                return true;
            }
            let gx = (c[0] - next[0]).abs() - half[0] - r;
            let gy = (c[1] - next[1]).abs() - half[1] - r;
            gx.max(gy) >= min_gap
        };
        let machines_ok = machines
            .chunks_exact(3)
            .all(|m| box_ok(m, p.machine_half, !has_part && m[0] == t[0] && m[1] == t[1]));
        let storages_ok = storages
            .chunks_exact(2)
            .all(|s| box_ok(s, p.storage_half, has_part && s[0] == t[0] && s[1] == t[1]));
        if peer_ok && machines_ok && storages_ok {
            return a;
        }
    }
    0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> GreedyParams {
        GreedyParams::default()
    }

    #[test]
    fn goes_to_ready_machine_then_storage() {
        let p = params();
        // Ready machine to the right, a not-ready one closer on the left.
        let machines = [1.0, 0.0, 1.0, -0.5, 0.0, 0.0];
        let storages = [0.0, 1.0];
        assert_eq!(
            greedy_action(&[0.0, 0.0, 0.0], &machines, &storages, &[], &p),
            2
        );
        // With a part it heads up to the storage.
        assert_eq!(
            greedy_action(&[0.0, 0.0, 1.0], &machines, &storages, &[], &p),
            4
        );
    }

    #[test]
    fn leaves_a_machine_to_a_nearer_peer() {
        let p = params();
        let machines = [1.0, 0.0, 1.0, 0.0, -1.0, 1.0];
        // A part-less peer right next to the first machine.
        let peers = [0.9, 0.3, 0.0];
        let a = greedy_action(&[0.0, 0.0, 0.0], &machines, &[0.5, 0.5], &peers, &p);
        assert_eq!(a, 3, "should go down to the unclaimed machine");
    }

    #[test]
    fn sidesteps_a_peer_in_the_way() {
        let p = params();
        let machines = [1.0, 0.0, 1.0];
        let peers = [0.18, 0.0, 1.0]; // blocking to the right, carrying a part
        let a = greedy_action(&[0.0, 0.0, 0.0], &machines, &[0.5, 0.5], &peers, &p);
        assert!(a == 3 || a == 4, "got {a}");
    }
}
