//! The planner (crate `plan`) on the simulator: what a robot of an environment knows about
//! its fleet ([`fleet_params`]), greedy-ORCA for every robot of an environment
//! ([`GreedyOrcaFleet`]), and random actions.
//!
//! The scripted controllers themselves (greedy, greedy-ORCA, matching-ORCA) and the pilot
//! a learned policy drives through are `plan`'s, decentralized: each robot decides from its
//! own observation row (the same [`obs::ObsBatch`] a learned policy gets) plus these
//! parameters, so they run unchanged on a robot.

use obs::ObsBatch;
use plan::orca::{GreedyOrca, OrcaParams};
use plan::FleetParams;
use rand::Rng;
use sim::{Env, ScenarioConfig, SimError, Sizes, N_ACTIONS};

/// Uniformly random actions.
pub fn random_action<R: Rng>(rng: &mut R) -> u8 {
    rng.gen_range(0..N_ACTIONS as u8)
}

/// What a robot of an environment knows about its fleet: its body sizes, action speed,
/// control period, machine preparation time, room, reach and contact distance. The
/// planner's parameter sets come from it ([`FleetParams::greedy_params`],
/// [`FleetParams::orca_params`], [`FleetParams::shield_params`]).
pub fn fleet_params(sizes: &Sizes, cfg: &ScenarioConfig) -> FleetParams {
    FleetParams {
        robot_radius: sizes.robot_radius,
        machine_half: sizes.machine_half,
        storage_half: sizes.storage_half,
        k_speed: cfg.task.k_speed,
        dt: cfg.world.dt,
        prep_steps: cfg.task.prep_steps,
        room_size: cfg.world.room_size,
        reach: sizes.reach,
        collision_distance: cfg.task.collision_distance,
    }
}

/// One [`GreedyOrca`] per robot of an environment (each keeps what it saw last step).
#[derive(Debug, Clone)]
pub struct GreedyOrcaFleet {
    robots: Vec<GreedyOrca>,
}

impl GreedyOrcaFleet {
    /// Controllers for every robot of `env` as it is now.
    pub fn new(env: &Env) -> Result<Self, SimError> {
        Self::with_params(env, fleet_params(env.sizes(), env.config()).orca_params())
    }

    /// Greedy-ORCA with its peer clearance and obstacle horizon set
    /// (`plan::orca::GREEDY_ORCA_CLEARANCE` and `plan::orca::OBSTACLE_HORIZON` are
    /// [`Self::new`]'s).
    pub fn with_margins(
        env: &Env,
        clearance: f32,
        obstacle_horizon: f32,
    ) -> Result<Self, SimError> {
        Self::with_params(
            env,
            fleet_params(env.sizes(), env.config())
                .orca_params()
                .with_clearance(clearance)
                .with_obstacle_horizon(obstacle_horizon),
        )
    }

    /// Controllers with explicit parameters (e.g. greedy-ORCA's with `make_room` changed,
    /// for ablations); refused when [`OrcaParams::validate`] refuses them.
    pub fn with_params(env: &Env, p: OrcaParams) -> Result<Self, SimError> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use plan::greedy::GreedyParams;

    #[test]
    fn default_greedy_params_are_the_default_scenarios() {
        let cfg = ScenarioConfig::default();
        let sizes = sim::layout::sizes_for(sim::Setup::new(1, 1, 1), &cfg);
        assert_eq!(sizes.scale, 1.0);
        let f = fleet_params(&sizes, &cfg);
        assert_eq!(f.greedy_params(), GreedyParams::default());
        assert_eq!(
            f.collision_distance,
            plan::fleet::DEFAULT_COLLISION_DISTANCE
        );
    }
}
