//! Controllers: observation in, planar velocity (m/s, map frame) out.
//!
//! The learned SMAPPO policy (crate `policy`, not integrated yet) will sit behind the same
//! [`Controller`] trait: `Policy::load(path)`, `new_state()` on [`Controller::reset`], and
//! `act(&ObsBatch, &mut state, mode)` giving an action index that [`action_velocity`]
//! turns into a velocity. Until then [`GreedyController`] drives the robot.

use obs::{ObsBatch, MACHINE_DIM, STORAGE_DIM};

/// The paper's discrete actions (section III): holonomic velocity K_speed on one axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Action {
    Stay = 0,
    Left = 1,
    Right = 2,
    Down = 3,
    Up = 4,
}

impl Action {
    pub fn from_index(i: usize) -> Option<Self> {
        Some(match i {
            0 => Action::Stay,
            1 => Action::Left,
            2 => Action::Right,
            3 => Action::Down,
            4 => Action::Up,
            _ => return None,
        })
    }
}

/// Velocity (vx, vy) of an action: left = -x, right = +x, down = -y, up = +y.
pub fn action_velocity(a: Action, k_speed: f32) -> [f32; 2] {
    match a {
        Action::Stay => [0.0, 0.0],
        Action::Left => [-k_speed, 0.0],
        Action::Right => [k_speed, 0.0],
        Action::Down => [0.0, -k_speed],
        Action::Up => [0.0, k_speed],
    }
}

/// Something that turns one robot's observation (a single-row batch) into a velocity.
pub trait Controller: Send {
    /// Forget internal state (recurrent state of a policy); called when the robot's
    /// own inputs come back after being stale and when sim time jumps backwards.
    fn reset(&mut self);
    /// Velocity command (vx, vy) in m/s, map frame.
    fn act(&mut self, obs: &ObsBatch) -> anyhow::Result<[f32; 2]>;
    fn name(&self) -> &'static str;
}

/// Scripted baseline: without a part, go to the nearest machine whose part is ready
/// (or, if none is ready, the nearest machine, to wait there); with a part, go to the
/// nearest storage. Moves along the axis with the larger offset at K_speed (the 5-action
/// space of the policy); stays when within `deadband` metres on both axes.
#[derive(Debug, Clone)]
pub struct GreedyController {
    pub k_speed: f32,
    pub deadband: f32,
}

impl GreedyController {
    pub fn new(k_speed: f32) -> Self {
        Self {
            k_speed,
            deadband: 0.02,
        }
    }

    /// The discrete action for row 0 of `obs`.
    pub fn action(&self, obs: &ObsBatch) -> anyhow::Result<Action> {
        anyhow::ensure!(
            obs.rows == 1,
            "greedy controller expects 1 row, got {}",
            obs.rows
        );
        obs.validate()?;
        let has_part = obs.own_row(0)[2] == 1.0;
        let target = if has_part {
            nearest(
                obs.storages_row(0)
                    .chunks_exact(STORAGE_DIM)
                    .map(|c| [c[0], c[1]]),
            )
        } else {
            let machines: Vec<([f32; 2], bool)> = obs
                .machines_row(0)
                .chunks_exact(MACHINE_DIM)
                .map(|c| ([c[0], c[1]], c[2] == 1.0))
                .collect();
            nearest(machines.iter().filter(|m| m.1).map(|m| m.0))
                .or_else(|| nearest(machines.iter().map(|m| m.0)))
        };
        let Some([dx, dy]) = target else {
            return Ok(Action::Stay);
        };
        Ok(if dx.abs() <= self.deadband && dy.abs() <= self.deadband {
            Action::Stay
        } else if dx.abs() >= dy.abs() {
            if dx > 0.0 {
                Action::Right
            } else {
                Action::Left
            }
        } else if dy > 0.0 {
            Action::Up
        } else {
            Action::Down
        })
    }
}

fn nearest(rel: impl Iterator<Item = [f32; 2]>) -> Option<[f32; 2]> {
    rel.min_by(|a, b| {
        let da = a[0] * a[0] + a[1] * a[1];
        let db = b[0] * b[0] + b[1] * b[1];
        da.total_cmp(&db)
    })
}

impl Controller for GreedyController {
    fn reset(&mut self) {}
    fn act(&mut self, obs: &ObsBatch) -> anyhow::Result<[f32; 2]> {
        Ok(action_velocity(self.action(obs)?, self.k_speed))
    }
    fn name(&self) -> &'static str {
        "greedy"
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use obs::ObsBuilder;

    fn b(own: [f32; 2], has_part: bool, m: Vec<([f32; 2], bool)>, s: Vec<[f32; 2]>) -> ObsBatch {
        ObsBuilder {
            own_pos: own,
            has_part,
            machines: m,
            storages: s,
            peers: vec![],
        }
        .build()
        .unwrap()
    }

    #[test]
    fn goes_to_nearest_ready_machine() {
        let g = GreedyController::new(0.5);
        let o = b(
            [0.0, 0.0],
            false,
            vec![([0.2, 0.0], false), ([0.0, -0.6], true), ([0.9, 0.9], true)],
            vec![[-1.0, 0.0]],
        );
        assert_eq!(g.action(&o).unwrap(), Action::Down);
        let mut g2 = g.clone();
        assert_eq!(g2.act(&o).unwrap(), [0.0, -0.5]);
    }

    #[test]
    fn waits_at_nearest_machine_when_none_ready() {
        let g = GreedyController::new(0.5);
        let o = b(
            [0.0, 0.0],
            false,
            vec![([-0.4, 0.1], false), ([0.9, 0.9], false)],
            vec![],
        );
        assert_eq!(g.action(&o).unwrap(), Action::Left);
        let o = b([0.0, 0.0], false, vec![([0.01, 0.0], false)], vec![]);
        assert_eq!(g.action(&o).unwrap(), Action::Stay);
    }

    #[test]
    fn with_part_goes_to_storage() {
        let g = GreedyController::new(0.3);
        let o = b(
            [0.0, 0.0],
            true,
            vec![([0.1, 0.0], true)],
            vec![[0.2, 0.7], [1.0, 1.0]],
        );
        assert_eq!(g.action(&o).unwrap(), Action::Up);
        let o = b([0.0, 0.0], true, vec![([0.1, 0.0], true)], vec![]);
        assert_eq!(g.action(&o).unwrap(), Action::Stay);
    }

    #[test]
    fn refuses_invalid_batches() {
        let g = GreedyController::new(0.5);
        let mut o = b([0.0, 0.0], false, vec![([0.5, 0.0], true)], vec![]);
        o.machines[0] = f32::NAN;
        assert!(g.action(&o).is_err());
        let o2 = ObsBatch::zeros(2, Default::default());
        assert!(g.action(&o2).is_err());
    }

    #[test]
    fn action_mapping() {
        for (i, v) in [[0.0, 0.0], [-1.0, 0.0], [1.0, 0.0], [0.0, -1.0], [0.0, 1.0]]
            .iter()
            .enumerate()
        {
            assert_eq!(action_velocity(Action::from_index(i).unwrap(), 1.0), *v);
        }
        assert!(Action::from_index(5).is_none());
    }
}
