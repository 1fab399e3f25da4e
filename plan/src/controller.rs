//! One controller concept (issue 45): observation in, planar velocity (m/s, map frame)
//! out, one robot at a time, with the state it carries. The scripted controllers are here,
//! beside the planner they call; the learned policy implements the same trait in
//! `policy::controller`. robot_node runs any of them per robot; `learn::eval` describes an
//! offline method (`learn::eval::Method`) and runs the same planner code in batches.
//!
//! - [`GreedyController`]: the scripted baseline, the same function as the simulator's;
//! - [`GreedyOrcaController`]: greedy allocation + ORCA avoidance ([`crate::orca`], the
//!   same code as `tending eval --policy greedy-orca`), a continuous velocity;
//! - [`MatchingOrcaController`]: matching-ORCA ([`crate::MatchingOrca`], the same code as
//!   `tending eval --policy matching-orca`).
//!
//! Errors are `anyhow`: the trait is the seam between a robot's runtime and controllers
//! whose failures differ in kind (a malformed batch, a network's shape, a planner's input).

use obs::ObsBatch;

use crate::greedy::GreedyParams;
use crate::orca::{GreedyOrca, OrcaParams};
use crate::{FilterMargins, FleetParams, MatchingOrca, Pilot, Row};

/// Something that turns one robot's observation (a single-row batch) into a velocity.
pub trait Controller: Send {
    /// Forget internal state (recurrent state of a policy); called when the robot's
    /// own inputs come back after being stale and when sim time jumps backwards.
    fn reset(&mut self);
    /// Velocity command (vx, vy) in m/s, map frame.
    fn act(&mut self, obs: &ObsBatch) -> anyhow::Result<[f32; 2]>;
    fn name(&self) -> &'static str;
    /// Real time: the state the next [`Self::act`] answers came `gap_s` seconds after the
    /// one the last command answered (more than one control step when states were
    /// missed). Only a controller that counts steps needs it.
    fn state_gap(&mut self, _gap_s: f64) {}
}

/// Row 0 of a one-row batch, checked.
pub fn one_row<'a>(obs: &'a ObsBatch, who: &str) -> anyhow::Result<Row<'a>> {
    anyhow::ensure!(
        obs.rows == 1,
        "{who} controller expects 1 row, got {}",
        obs.rows
    );
    obs.validate()?;
    Ok(Row::of(obs, 0))
}

/// A pilot's planner counts control steps ([`Pilot::skip_steps`]): after a gap of
/// `gap_s` seconds, the steps missed, so that its machine clock does not stay a step
/// behind until that machine's next pick.
pub fn skip_missed_steps(pilot: &mut Pilot, gap_s: f64) {
    if let Some(dt) = pilot.dt() {
        let steps = (gap_s / dt as f64).round();
        if steps >= 2.0 && steps.is_finite() {
            pilot.skip_steps((steps - 1.0).min(u32::MAX as f64) as u32);
        }
    }
}

/// Scripted baseline: [`crate::greedy::greedy_action`], the very function the simulator's
/// offline greedy episodes run, so a fleet of greedy robot nodes on the sim bridge
/// reproduces an offline episode step for step.
#[derive(Debug, Clone)]
pub struct GreedyController {
    pub params: GreedyParams,
}

impl GreedyController {
    pub fn new(params: GreedyParams) -> Self {
        Self { params }
    }

    /// The discrete action (`obs::action::MOVES` index) for row 0 of `obs`.
    pub fn action(&self, obs: &ObsBatch) -> anyhow::Result<u8> {
        let row = one_row(obs, "greedy")?;
        Ok(crate::greedy::greedy_action(
            row.own,
            row.machines,
            row.storages,
            row.peers,
            &self.params,
        ))
    }
}

impl Controller for GreedyController {
    fn reset(&mut self) {}
    fn act(&mut self, obs: &ObsBatch) -> anyhow::Result<[f32; 2]> {
        let a = self.action(obs)?;
        obs::action::velocity(a, self.params.k_speed)
            .ok_or_else(|| anyhow::anyhow!("greedy gave action {a}"))
    }
    fn name(&self) -> &'static str {
        "greedy"
    }
}

/// Greedy-ORCA behind [`Controller`]: keeps the previous observation to estimate
/// velocities, forgets it on [`Controller::reset`].
#[derive(Debug, Clone)]
pub struct GreedyOrcaController {
    inner: GreedyOrca,
}

impl GreedyOrcaController {
    pub fn new(params: OrcaParams) -> anyhow::Result<Self> {
        Ok(Self {
            inner: GreedyOrca::new(params).map_err(|e| anyhow::anyhow!(e))?,
        })
    }
}

impl Controller for GreedyOrcaController {
    fn reset(&mut self) {
        self.inner.reset();
    }
    fn act(&mut self, obs: &ObsBatch) -> anyhow::Result<[f32; 2]> {
        let row = one_row(obs, "greedy-orca")?;
        Ok(self
            .inner
            .velocity(row.own, row.machines, row.storages, row.peers))
    }
    fn name(&self) -> &'static str {
        "greedy-orca"
    }
}

/// matching-ORCA behind [`Controller`] (docs/adr/0020): always the target menu's
/// "matched" entry, through the ORCA filter.
#[derive(Debug, Clone)]
pub struct MatchingOrcaController {
    inner: MatchingOrca,
}

impl MatchingOrcaController {
    pub fn new(fleet: &FleetParams, margins: FilterMargins) -> anyhow::Result<Self> {
        Ok(Self {
            inner: MatchingOrca::new(fleet, margins).map_err(|e| anyhow::anyhow!(e))?,
        })
    }
}

impl Controller for MatchingOrcaController {
    fn reset(&mut self) {
        self.inner.pilot_mut().reset();
    }
    fn act(&mut self, obs: &ObsBatch) -> anyhow::Result<[f32; 2]> {
        let row = one_row(obs, "matching-orca")?;
        Ok(self.inner.velocity(row))
    }
    fn name(&self) -> &'static str {
        "matching-orca"
    }
    fn state_gap(&mut self, gap_s: f64) {
        skip_missed_steps(self.inner.pilot_mut(), gap_s);
    }
}
