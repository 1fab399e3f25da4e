//! The learned policy behind `plan::controller::Controller`, the trait every controller
//! of a robot implements (issue 45): a checkpoint's actor, its recurrent state, argmax
//! actions through its [`Pilot`] (target planner, ORCA filter or shield), as robot_node
//! runs it and `tending eval` evaluates it.

use obs::ObsBatch;
use plan::controller::{skip_missed_steps, Controller};
use plan::{FleetParams, Outputs, Pilot, Row, Safety};

/// The learned policy (SMAPPO or MAPPO actor from a checkpoint) behind [`Controller`]:
/// keeps the GRU state, acts greedily (argmax) through its [`Pilot`] and resets both on
/// [`Controller::reset`] (own data stale then back, sim time going backwards).
pub struct PolicyController {
    policy: crate::Policy,
    state: crate::PolicyState,
    pub k_speed: f32,
    /// Shield, target planner and ORCA filter as [`Self::with_pilot`] set them.
    pilot: Option<Pilot>,
    /// Scratch: the logits behind the shield.
    shielded: Vec<f32>,
}

impl PolicyController {
    /// Load a checkpoint. `k_speed` comes from the checkpoint's training metadata
    /// (`training.k_speed`, or `training.scenario.task.k_speed`) when present, else
    /// `default_k_speed`; the second value says which. It acts once it has its pilot
    /// ([`Self::with_pilot`]).
    pub fn load(path: &std::path::Path, default_k_speed: f32) -> anyhow::Result<(Self, bool)> {
        let policy = crate::Policy::load(path)
            .map_err(|e| anyhow::anyhow!("cannot load policy {}: {e}", path.display()))?;
        let meta_k = checkpoint_k_speed(&policy.meta().training);
        let k = meta_k.unwrap_or(default_k_speed);
        Ok((Self::from_policy(policy, k), meta_k.is_some()))
    }

    pub fn from_policy(policy: crate::Policy, k_speed: f32) -> Self {
        let state = policy.new_state();
        Self {
            policy,
            state,
            k_speed,
            pilot: None,
            shielded: Vec::new(),
        }
    }

    /// What the policy's outputs mean: target boxes (`plan::targets`) or velocity moves.
    pub fn outputs(&self) -> Outputs {
        self.policy.actor().arch.actions.outputs()
    }

    /// Whether the checkpoint was trained behind the ORCA filter.
    pub fn trained_with_orca_filter(&self) -> bool {
        self.policy.trained_with_orca_filter()
    }

    /// Drive through a [`Pilot`] for `fleet` behind `safety` (the planner's, filter's and
    /// shield's k_speed set to the policy's). Refused: the shield for a target-action
    /// policy, ORCA parameters ORCA cannot work with.
    pub fn with_pilot(mut self, mut fleet: FleetParams, safety: Safety) -> anyhow::Result<Self> {
        fleet.k_speed = self.k_speed;
        let pilot = Pilot::new(&fleet, self.outputs(), safety).map_err(|e| anyhow::anyhow!(e))?;
        self.pilot = Some(pilot);
        Ok(self)
    }

    /// Whether the commands pass through the ORCA filter.
    pub fn filtered(&self) -> bool {
        self.pilot.as_ref().is_some_and(Pilot::filtered)
    }

    pub fn state(&self) -> &crate::PolicyState {
        &self.state
    }

    /// The action index for row 0 of `obs` (advances the recurrent state): argmax of the
    /// logits, behind the shield when the pilot has one.
    pub fn action(&mut self, obs: &ObsBatch) -> anyhow::Result<u8> {
        let pilot = self
            .pilot
            .as_ref()
            .ok_or_else(|| anyhow::anyhow!("policy controller without its pilot"))?;
        let logits = self.policy.logits(obs, &mut self.state)?;
        let row = Row::of(obs, 0);
        Ok(crate::choose(
            pilot,
            row,
            logits,
            crate::Choice::Argmax,
            &mut self.shielded,
        ))
    }
}

/// `k_speed` from a checkpoint's free-form training metadata, if it holds a positive one.
pub fn checkpoint_k_speed(training: &serde_json::Value) -> Option<f32> {
    [
        training.get("k_speed"),
        training.pointer("/scenario/task/k_speed"),
        training.pointer("/config/task/k_speed"),
    ]
    .into_iter()
    .flatten()
    .find_map(|v| v.as_f64())
    .filter(|k| k.is_finite() && *k > 0.0)
    .map(|k| k as f32)
}

impl Controller for PolicyController {
    fn reset(&mut self) {
        self.state.reset();
        if let Some(p) = &mut self.pilot {
            p.reset();
        }
    }
    fn act(&mut self, obs: &ObsBatch) -> anyhow::Result<[f32; 2]> {
        let a = self.action(obs)?;
        let pilot = self.pilot.as_mut().expect("checked by action()");
        Ok(pilot.command(a, Row::of(obs, 0)))
    }
    fn name(&self) -> &'static str {
        "policy"
    }
    fn state_gap(&mut self, gap_s: f64) {
        if let Some(p) = self
            .pilot
            .as_mut()
            .filter(|p| p.outputs() == Outputs::Targets)
        {
            skip_missed_steps(p, gap_s);
        }
    }
}
