//! Scripted baselines a factory engineer would write first, and the action shield.
//!
//! All are decentralized: each robot decides from its own observation row (the same
//! [`obs::ObsBatch`] a learned policy gets) plus the fleet's known body sizes, so they run
//! unchanged on a robot.

use crate::{Env, ScenarioConfig, SimError, Sizes, N_ACTIONS};
use obs::greedy::GreedyParams;
use obs::orca::{GreedyOrca, OrcaParams};
use obs::shield::ShieldParams;
use obs::ObsBatch;
use rand::Rng;

/// Uniformly random actions.
pub fn random_action<R: Rng>(rng: &mut R) -> u8 {
    rng.gen_range(0..N_ACTIONS as u8)
}

/// Decentralized greedy: without a part, head for the nearest ready machine that no
/// nearer part-less peer is closer to; with a part, the nearest storage (the one
/// implementation, which `robot_node` runs too).
pub use obs::greedy::greedy_action;

/// What the greedy controller knows about an environment besides its observation: its
/// body sizes, action speed and control period.
pub fn greedy_params(sizes: &Sizes, cfg: &ScenarioConfig) -> GreedyParams {
    GreedyParams {
        robot_radius: sizes.robot_radius,
        machine_half: sizes.machine_half,
        storage_half: sizes.storage_half,
        k_speed: cfg.task.k_speed,
        dt: cfg.world.dt,
        prep_steps: cfg.task.prep_steps,
    }
}

/// Greedy-ORCA parameters of an environment (its sizes, speed, period and room).
pub fn orca_params(sizes: &Sizes, cfg: &ScenarioConfig) -> OrcaParams {
    OrcaParams::new(greedy_params(sizes, cfg), cfg.world.room_size, sizes.reach)
}

/// Shield parameters of an environment. The margin is the simulator's collision distance
/// plus 10 mm for the velocity tracker's lag behind a command.
pub fn shield_params(sizes: &Sizes, cfg: &ScenarioConfig) -> ShieldParams {
    let mut p = ShieldParams::new(
        sizes.robot_radius,
        sizes.machine_half,
        sizes.storage_half,
        cfg.task.k_speed,
        cfg.world.dt,
        cfg.world.room_size,
    );
    p.margin = cfg.task.collision_distance + 0.01;
    p
}

/// One [`GreedyOrca`] per robot of an environment (each keeps what it saw last step).
#[derive(Debug, Clone)]
pub struct GreedyOrcaFleet {
    robots: Vec<GreedyOrca>,
}

impl GreedyOrcaFleet {
    /// Controllers for every robot of `env` as it is now.
    pub fn new(env: &Env) -> Result<Self, SimError> {
        Self::with_params(env, orca_params(env.sizes(), env.config()))
    }

    /// Safety filters (and target planners) for every robot of `env`: greedy-ORCA's
    /// parameters as a learned policy runs behind them ([`obs::orca::OrcaParams::for_policy`]:
    /// the filter's peer clearance `filter_clearance`, `obs::orca::FILTER_CLEARANCE` by
    /// default, or None for a target policy's planner without the filter).
    pub fn new_filter(env: &Env, filter_clearance: Option<f32>) -> Result<Self, SimError> {
        let p = orca_params(env.sizes(), env.config()).for_policy(filter_clearance);
        Self::with_params(env, p)
    }

    /// [`Self::new_filter`] with the filter's full-speed and rest clearances and its
    /// obstacle horizon given ([`obs::orca::OrcaParams::for_policy_filter`]).
    pub fn new_filter_with(
        env: &Env,
        clearance: f32,
        rest: f32,
        obstacle_horizon: f32,
    ) -> Result<Self, SimError> {
        let p = orca_params(env.sizes(), env.config())
            .for_policy_filter(clearance, rest)
            .with_obstacle_horizon(obstacle_horizon);
        Self::with_params(env, p)
    }

    /// Greedy-ORCA with its peer clearance and obstacle horizon set
    /// (`obs::orca::GREEDY_ORCA_CLEARANCE` and `obs::orca::OBSTACLE_HORIZON` are
    /// [`Self::new`]'s).
    pub fn with_margins(
        env: &Env,
        clearance: f32,
        obstacle_horizon: f32,
    ) -> Result<Self, SimError> {
        Self::with_params(
            env,
            orca_params(env.sizes(), env.config())
                .with_clearance(clearance)
                .with_obstacle_horizon(obstacle_horizon),
        )
    }

    /// Controllers with explicit parameters (e.g. `orca_params` with `make_room` changed,
    /// for ablations); refused when [`obs::orca::OrcaParams::validate`] refuses them.
    pub fn with_params(env: &Env, p: obs::orca::OrcaParams) -> Result<Self, SimError> {
        let one = GreedyOrca::new(p).map_err(|reason| SimError::BadConfig {
            field: "greedy-orca".into(),
            reason,
        })?;
        Ok(Self {
            robots: vec![one; env.n_robots()],
        })
    }

    /// Velocity commands for every row of `obs` (rows = robots, in robot order).
    pub fn act(&mut self, obs: &ObsBatch, out: &mut Vec<[f32; 2]>) -> Result<(), SimError> {
        if obs.rows != self.robots.len() {
            return Err(SimError::WrongCommandCount {
                expected: self.robots.len(),
                got: obs.rows,
            });
        }
        out.clear();
        out.extend(self.robots.iter_mut().enumerate().map(|(r, c)| {
            c.velocity(
                obs.own_row(r),
                obs.machines_row(r),
                obs.storages_row(r),
                obs.peers_row(r),
            )
        }));
        Ok(())
    }
}

impl GreedyOrcaFleet {
    /// Preferred velocities of target actions (`obs::targets`), one per row of `obs`:
    /// straight for the box each action names, before any filter.
    pub fn target_velocities(
        &mut self,
        obs: &ObsBatch,
        actions: &[u8],
        out: &mut Vec<[f32; 2]>,
    ) -> Result<(), SimError> {
        if obs.rows != self.robots.len() || actions.len() != obs.rows {
            return Err(SimError::WrongCommandCount {
                expected: self.robots.len(),
                got: obs.rows.min(actions.len()),
            });
        }
        out.clear();
        out.extend(self.robots.iter_mut().enumerate().map(|(r, c)| {
            c.target_preferred(
                actions[r],
                obs.own_row(r),
                obs.machines_row(r),
                obs.storages_row(r),
                obs.peers_row(r),
            )
        }));
        Ok(())
    }

    /// ORCA as a safety filter: for every row of `obs`, the velocity nearest to `prefs[r]`
    /// (m/s; e.g. a learned policy's action as a velocity) that avoids what it observes.
    pub fn filter(
        &mut self,
        obs: &ObsBatch,
        prefs: &[[f32; 2]],
        out: &mut Vec<[f32; 2]>,
    ) -> Result<(), SimError> {
        if obs.rows != self.robots.len() || prefs.len() != obs.rows {
            return Err(SimError::WrongCommandCount {
                expected: self.robots.len(),
                got: obs.rows.min(prefs.len()),
            });
        }
        out.clear();
        out.extend(self.robots.iter_mut().enumerate().map(|(r, c)| {
            c.filter(
                obs.own_row(r),
                obs.machines_row(r),
                obs.storages_row(r),
                obs.peers_row(r),
                prefs[r],
            )
        }));
        Ok(())
    }
}

/// Apply the shield to every row of `logits` (rows x actions: 5, or 9 with diagonals)
/// from the rows of `obs`.
pub fn shield_logits(obs: &ObsBatch, logits: &mut [f32], p: &ShieldParams) {
    let k = logits.len() / obs.rows.max(1);
    for (r, row) in logits.chunks_exact_mut(k.max(1)).enumerate().take(obs.rows) {
        let safe = obs::shield::safe_actions(
            obs.own_row(r),
            obs.machines_row(r),
            obs.storages_row(r),
            obs.peers_row(r),
            p,
        );
        obs::shield::mask_logits(row, &safe);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> GreedyParams {
        GreedyParams::default()
    }

    #[test]
    fn default_greedy_params_are_the_default_scenarios() {
        let cfg = ScenarioConfig::default();
        let sizes = crate::layout::sizes_for(crate::Setup::new(1, 1, 1), &cfg);
        assert_eq!(sizes.scale, 1.0);
        assert_eq!(greedy_params(&sizes, &cfg), GreedyParams::default());
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
