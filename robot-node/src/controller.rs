//! Controllers: observation in, planar velocity (m/s, map frame) out.
//!
//! - [`PolicyController`]: the learned SMAPPO/MAPPO policy (crate `policy`, inference only:
//!   no simulator, no trainer), GRU state kept per robot, greedy argmax, driving through
//!   `plan`'s [`Pilot`] (target planner, ORCA filter or shield: the code `tending eval` and
//!   the trainer's rollouts run);
//! - [`GreedyController`]: the scripted baseline, the same function as the simulator's;
//! - [`GreedyOrcaController`]: greedy allocation + ORCA avoidance ([`plan::orca`], the same
//!   code as the simulator's `greedy-orca`), a continuous velocity;
//! - [`MatchingOrcaController`]: matching-ORCA ([`plan::MatchingOrca`], the same code as
//!   `tending eval --policy matching-orca`).

use obs::ObsBatch;
use plan::greedy::GreedyParams;
use plan::orca::{GreedyOrca, OrcaParams};
use plan::{FilterMargins, FleetParams, MatchingOrca, Outputs, Pilot, Row, Safety};

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
fn one_row<'a>(obs: &'a ObsBatch, who: &str) -> anyhow::Result<Row<'a>> {
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
fn skip_missed_steps(pilot: &mut Pilot, gap_s: f64) {
    if let Some(dt) = pilot.dt() {
        let steps = (gap_s / dt as f64).round();
        if steps >= 2.0 && steps.is_finite() {
            pilot.skip_steps((steps - 1.0).min(u32::MAX as f64) as u32);
        }
    }
}

/// Scripted baseline: [`plan::greedy::greedy_action`], the very function the simulator's
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
        Ok(plan::greedy::greedy_action(
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

/// The learned policy (SMAPPO or MAPPO actor from a checkpoint) behind [`Controller`]:
/// keeps the GRU state, acts greedily (argmax) through its [`Pilot`] and resets both on
/// [`Controller::reset`] (own data stale then back, sim time going backwards).
pub struct PolicyController {
    policy: policy::Policy,
    state: policy::PolicyState,
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
        let policy = policy::Policy::load(path)
            .map_err(|e| anyhow::anyhow!("cannot load policy {}: {e}", path.display()))?;
        let meta_k = checkpoint_k_speed(&policy.meta().training);
        let k = meta_k.unwrap_or(default_k_speed);
        Ok((Self::from_policy(policy, k), meta_k.is_some()))
    }

    pub fn from_policy(policy: policy::Policy, k_speed: f32) -> Self {
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

    pub fn state(&self) -> &policy::PolicyState {
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
        Ok(policy::choose(
            pilot,
            row,
            logits,
            policy::Choice::Argmax,
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

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use obs::ObsBuilder;

    /// Greedy parameters of the default scenario (also used by the tick and fan-out tests).
    pub(crate) fn params(k: f32) -> GreedyParams {
        GreedyParams {
            k_speed: k,
            ..GreedyParams::default()
        }
    }

    /// The default fleet (robot_node's default parameters: `node` tests they agree).
    pub(crate) fn fleet() -> FleetParams {
        let g = params(0.5);
        FleetParams::from_greedy(&g, 2.3)
    }

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

    // `obs::action::MOVES` indices the greedy tests expect
    const STAY: u8 = 0;
    const DOWN: u8 = 3;
    const UP: u8 = 4;

    #[test]
    fn goes_to_nearest_ready_machine() {
        let g = GreedyController::new(params(0.5));
        let o = b(
            [0.0, 0.0],
            false,
            vec![([0.5, 0.2], false), ([0.0, -0.6], true), ([0.9, 0.9], true)],
            vec![[-1.0, 0.0]],
        );
        assert_eq!(g.action(&o).unwrap(), DOWN);
        let mut g2 = g.clone();
        assert_eq!(g2.act(&o).unwrap(), [0.0, -0.5]);
    }

    #[test]
    fn stays_when_no_machine_is_ready() {
        let g = GreedyController::new(params(0.5));
        let o = b(
            [0.0, 0.0],
            false,
            vec![([-0.4, 0.1], false), ([0.9, 0.9], false)],
            vec![[1.0, -1.0]],
        );
        assert_eq!(g.action(&o).unwrap(), STAY);
    }

    #[test]
    fn with_part_goes_to_storage() {
        let g = GreedyController::new(params(0.3));
        let o = b(
            [0.0, 0.0],
            true,
            vec![([0.6, -0.6], true)],
            vec![[0.2, 0.7], [1.0, 1.0]],
        );
        assert_eq!(g.action(&o).unwrap(), UP);
        let o = b([0.0, 0.0], true, vec![([0.6, 0.0], true)], vec![]);
        assert_eq!(g.action(&o).unwrap(), STAY);
    }

    #[test]
    fn refuses_invalid_batches() {
        let g = GreedyController::new(params(0.5));
        let mut o = b([0.0, 0.0], false, vec![([0.5, 0.0], true)], vec![]);
        o.machines[0] = f32::NAN;
        assert!(g.action(&o).is_err());
        let o2 = ObsBatch::zeros(2, Default::default());
        assert!(g.action(&o2).is_err());
    }

    fn tmp(name: &str) -> std::path::PathBuf {
        std::env::temp_dir().join(format!("robot_node_{}_{name}", std::process::id()))
    }

    fn small_arch() -> policy::ArchConfig {
        let mut arch = policy::ArchConfig::smappo();
        arch.d_model = 8;
        arch.heads = 2;
        arch.hidden = 8;
        arch
    }

    #[test]
    fn policy_controller_loads_checkpoint_keeps_and_resets_state() {
        let actor = policy::Actor::new(small_arch(), 7);
        let path = tmp("ok.safetensors");
        policy::checkpoint::save_policy(
            &path,
            &actor,
            serde_json::json!({"setup": "6.4_2", "k_speed": 0.3}),
        )
        .unwrap();
        let (c, from_meta) = PolicyController::load(&path, 0.5).unwrap();
        assert!(from_meta);
        assert_eq!(c.k_speed, 0.3);
        let mut c = c.with_pilot(fleet(), Safety::RAW).unwrap();
        let o = b(
            [0.1, -0.2],
            false,
            vec![([0.5, 0.5], true), ([-0.5, 0.5], false)],
            vec![[0.0, -0.9]],
        );
        // same decisions as the policy crate's own inference from a zero state
        let mut reference = policy::Policy::load(&path).unwrap();
        let mut st = reference.new_state();
        for _ in 0..3 {
            let a = reference.act(&o, &mut st, policy::ActMode::Greedy).unwrap();
            let v = c.act(&o).unwrap();
            assert_eq!(Some(v), obs::action::velocity(a, 0.3));
        }
        assert!(c.state().h.iter().any(|v| *v != 0.0));
        assert_eq!(c.state().h, st.h);
        c.reset();
        assert!(c.state().h.iter().all(|v| *v == 0.0));
        std::fs::remove_file(&path).ok();
    }

    #[test]
    fn policy_controller_refuses_bad_files_with_clear_errors() {
        let missing = tmp("missing.safetensors");
        let e = PolicyController::load(&missing, 0.5).err().unwrap();
        assert!(format!("{e:#}").contains("cannot load policy"), "{e:#}");
        let junk = tmp("junk.safetensors");
        std::fs::write(&junk, b"this is not a checkpoint").unwrap();
        let e = PolicyController::load(&junk, 0.5).err().unwrap();
        let msg = format!("{e:#}");
        assert!(
            msg.contains("junk.safetensors") && msg.contains("corrupt"),
            "{msg}"
        );
        std::fs::remove_file(&junk).ok();
    }

    #[test]
    fn greedy_orca_heads_for_the_machine_and_refuses_bad_batches() {
        let p = OrcaParams::new(params(0.5), 2.3, 0.08);
        let mut c = GreedyOrcaController::new(p).unwrap();
        let o = b(
            [0.0, 0.0],
            false,
            vec![([0.8, 0.0], true)],
            vec![[-0.8, 0.8]],
        );
        let v = c.act(&o).unwrap();
        assert!(v[0] > 0.4 && v[1].abs() < 0.05, "{v:?}");
        c.reset();
        assert!(c.act(&ObsBatch::zeros(2, Default::default())).is_err());
        let mut bad = p;
        bad.greedy.dt = f32::NAN;
        assert!(GreedyOrcaController::new(bad).is_err());
    }

    #[test]
    fn shielded_policy_only_takes_safe_actions() {
        let shield = Safety {
            shield: true,
            filter: None,
        };
        // Peers touching-close on all four sides: only "stay" is safe.
        let peers = [[0.17, 0.0], [-0.17, 0.0], [0.0, 0.17], [0.0, -0.17]];
        let o = ObsBuilder {
            own_pos: [0.0, 0.0],
            has_part: false,
            machines: vec![([0.8, 0.8], true)],
            storages: vec![[-0.8, 0.8]],
            peers: peers.iter().map(|p| (*p, false)).collect(),
        }
        .build()
        .unwrap();
        let mut unshielded_moves = 0;
        for seed in 0..8 {
            let actor = policy::Actor::new(small_arch(), seed);
            let pol = policy::Policy::from_actor(actor, serde_json::Value::Null);
            let mut free = PolicyController::from_policy(pol.clone(), 0.5)
                .with_pilot(fleet(), Safety::RAW)
                .unwrap();
            unshielded_moves += (free.action(&o).unwrap() != STAY) as usize;
            let mut c = PolicyController::from_policy(pol, 0.5)
                .with_pilot(fleet(), shield)
                .unwrap();
            assert_eq!(c.action(&o).unwrap(), STAY, "seed {seed}");
        }
        // The check means something only if unshielded actors would have moved.
        assert!(unshielded_moves > 0);
    }

    #[test]
    fn orca_filter_keeps_free_moves_and_holds_back_near_peers() {
        let free = b(
            [0.0, 0.0],
            false,
            vec![([0.9, 0.9], true)],
            vec![[-0.9, 0.9]],
        );
        let peers = [[0.17, 0.0], [-0.17, 0.0], [0.0, 0.17], [0.0, -0.17]];
        let boxed = ObsBuilder {
            own_pos: [0.0, 0.0],
            has_part: false,
            machines: vec![([0.9, 0.9], true)],
            storages: vec![[-0.9, 0.9]],
            peers: peers.iter().map(|p| (*p, false)).collect(),
        }
        .build()
        .unwrap();
        // greedy-ORCA's own clearance, fixed
        let margins = FilterMargins {
            clearance: plan::orca::GREEDY_ORCA_CLEARANCE,
            rest_clearance: plan::orca::GREEDY_ORCA_CLEARANCE,
            obstacle_horizon: plan::orca::OBSTACLE_HORIZON,
        };
        for seed in 0..4 {
            let pol = policy::Policy::from_actor(
                policy::Actor::new(small_arch(), seed),
                Default::default(),
            );
            let mut plain = PolicyController::from_policy(pol.clone(), 0.5)
                .with_pilot(fleet(), Safety::RAW)
                .unwrap();
            let mut c = PolicyController::from_policy(pol, 0.5)
                .with_pilot(fleet(), Safety::filtered(margins))
                .unwrap();
            assert!(c.filtered() && !plain.filtered());
            // Nothing near: ORCA leaves the policy's move as it is.
            let (v, w) = (plain.act(&free).unwrap(), c.act(&free).unwrap());
            assert!(
                (v[0] - w[0]).abs() < 1e-4 && (v[1] - w[1]).abs() < 1e-4,
                "{v:?} {w:?}"
            );
            // Peers 1 cm away on every side: no move at speed toward any of them.
            c.reset();
            let w = c.act(&boxed).unwrap();
            assert!(w[0].abs() < 0.25 && w[1].abs() < 0.25, "{w:?}");
        }
    }

    /// A target-action policy drives straight for the box it picks (here always the
    /// greedy entry: toward the ready machine at full speed); it refuses to act without its
    /// pilot and the shield; matching-ORCA heads for the same machine, alone.
    #[test]
    fn target_policy_drives_to_the_chosen_box() {
        let mut arch = small_arch();
        arch.n_actions = plan::targets::N_TARGET_ACTIONS;
        arch.actions = policy::ActionSpace::Targets;
        let mut actor = policy::Actor::new(arch, 1);
        actor.add_action_bias(plan::targets::TargetAction::Greedy as usize, 1e4);
        let pol = policy::Policy::from_actor(actor, Default::default());
        let obs = b(
            [0.0, 0.0],
            false,
            vec![([0.9, 0.0], true)],
            vec![[-0.9, 0.9]],
        );
        let mut bare = PolicyController::from_policy(pol.clone(), 0.5);
        assert_eq!(bare.outputs(), Outputs::Targets);
        assert!(bare.act(&obs).unwrap_err().to_string().contains("pilot"));
        let shield = Safety {
            shield: true,
            filter: None,
        };
        let e = PolicyController::from_policy(pol.clone(), 0.5)
            .with_pilot(fleet(), shield)
            .err()
            .unwrap();
        assert!(e.to_string().contains("target actions"), "{e}");
        let mut c = PolicyController::from_policy(pol, 0.5)
            .with_pilot(fleet(), Safety::filtered(FilterMargins::DEPLOYED))
            .unwrap();
        let v = c.act(&obs).unwrap();
        assert!((v[0] - 0.5).abs() < 1e-3 && v[1].abs() < 1e-3, "{v:?}");
        let mut m = MatchingOrcaController::new(&fleet(), FilterMargins::DEPLOYED).unwrap();
        let w = m.act(&obs).unwrap();
        assert!((w[0] - 0.5).abs() < 1e-3 && w[1].abs() < 1e-3, "{w:?}");
        assert!(m.act(&ObsBatch::zeros(2, Default::default())).is_err());
    }

    #[test]
    fn k_speed_metadata_forms() {
        use serde_json::json;
        assert_eq!(checkpoint_k_speed(&json!({"k_speed": 0.4})), Some(0.4));
        assert_eq!(
            checkpoint_k_speed(&json!({"scenario": {"task": {"k_speed": 0.2}}})),
            Some(0.2)
        );
        assert_eq!(checkpoint_k_speed(&json!({"k_speed": -1.0})), None);
        assert_eq!(checkpoint_k_speed(&serde_json::Value::Null), None);
    }
}
