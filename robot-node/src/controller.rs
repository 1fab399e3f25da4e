//! Controllers: observation in, planar velocity (m/s, map frame) out.
//!
//! - [`PolicyController`]: the learned SMAPPO/MAPPO policy (crate `policy`, inference only:
//!   no simulator, no trainer), GRU state kept per robot, greedy argmax;
//! - [`GreedyController`]: the scripted baseline, the same function as the simulator's;
//! - [`GreedyOrcaController`]: greedy allocation + ORCA avoidance ([`obs::orca`], the same
//!   code as the simulator's `greedy-orca`), a continuous velocity.
//!
//! The policy can run behind the action shield ([`obs::shield`], the same code as
//! `tending eval --shield`).

use obs::greedy::GreedyParams;
use obs::orca::{GreedyOrca, OrcaParams};
use obs::shield::ShieldParams;
use obs::ObsBatch;

/// The paper's discrete actions (section III): holonomic velocity K_speed on one axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Action {
    Stay = 0,
    Left = 1,
    Right = 2,
    Down = 3,
    Up = 4,
    /// Diagonals (`obs::action`, policies trained with `diagonal_actions`).
    LeftDown = 5,
    RightDown = 6,
    LeftUp = 7,
    RightUp = 8,
}

impl Action {
    pub fn from_index(i: usize) -> Option<Self> {
        Some(match i {
            0 => Action::Stay,
            1 => Action::Left,
            2 => Action::Right,
            3 => Action::Down,
            4 => Action::Up,
            5 => Action::LeftDown,
            6 => Action::RightDown,
            7 => Action::LeftUp,
            8 => Action::RightUp,
            _ => return None,
        })
    }
}

/// Velocity (vx, vy) of an action: left = -x, right = +x, down = -y, up = +y, diagonals
/// at the same speed; the table the simulator steps with (`obs::action`).
pub fn action_velocity(a: Action, k_speed: f32) -> [f32; 2] {
    let m = obs::action::MOVES[a as usize];
    [m[0] * k_speed, m[1] * k_speed]
}

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

/// Scripted baseline: [`obs::greedy::greedy_action`], the very function the simulator's
/// offline greedy episodes run (`sim::baselines::greedy_action` wraps it), so a fleet of
/// greedy robot nodes on the sim bridge reproduces an offline episode step for step.
#[derive(Debug, Clone)]
pub struct GreedyController {
    pub params: GreedyParams,
}

impl GreedyController {
    pub fn new(params: GreedyParams) -> Self {
        Self { params }
    }

    /// The discrete action for row 0 of `obs`.
    pub fn action(&self, obs: &ObsBatch) -> anyhow::Result<Action> {
        anyhow::ensure!(
            obs.rows == 1,
            "greedy controller expects 1 row, got {}",
            obs.rows
        );
        obs.validate()?;
        let a = obs::greedy::greedy_action(
            obs.own_row(0),
            obs.machines_row(0),
            obs.storages_row(0),
            obs.peers_row(0),
            &self.params,
        );
        Action::from_index(a as usize).ok_or_else(|| anyhow::anyhow!("greedy gave action {a}"))
    }
}

impl Controller for GreedyController {
    fn reset(&mut self) {}
    fn act(&mut self, obs: &ObsBatch) -> anyhow::Result<[f32; 2]> {
        Ok(action_velocity(self.action(obs)?, self.params.k_speed))
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
        anyhow::ensure!(
            obs.rows == 1,
            "greedy-orca controller expects 1 row, got {}",
            obs.rows
        );
        obs.validate()?;
        Ok(self.inner.velocity(
            obs.own_row(0),
            obs.machines_row(0),
            obs.storages_row(0),
            obs.peers_row(0),
        ))
    }
    fn name(&self) -> &'static str {
        "greedy-orca"
    }
}

/// The learned policy (SMAPPO or MAPPO actor from a checkpoint) behind [`Controller`]:
/// keeps the GRU state, acts greedily (argmax) and resets the state on [`Controller::reset`]
/// (own data stale then back, sim time going backwards).
pub struct PolicyController {
    policy: policy::Policy,
    state: policy::PolicyState,
    pub k_speed: f32,
    /// Mask unsafe actions before the argmax (`-p shield:=true`).
    shield: Option<ShieldParams>,
    /// Pass the action's velocity through ORCA (`-p orca_filter:=true`).
    filter: Option<GreedyOrca>,
    /// For a policy with target actions (`obs::targets`): turns the chosen box into a
    /// straight-line velocity (the planner of greedy-ORCA, no filtering).
    planner: Option<GreedyOrca>,
}

impl PolicyController {
    /// Load a checkpoint. `k_speed` comes from the checkpoint's training metadata
    /// (`training.k_speed`, or `training.scenario.task.k_speed`) when present, else
    /// `default_k_speed`; the second value says which.
    pub fn load(path: &std::path::Path, default_k_speed: f32) -> anyhow::Result<(Self, bool)> {
        let policy = policy::Policy::load(path)
            .map_err(|e| anyhow::anyhow!("cannot load policy {}: {e}", path.display()))?;
        let meta_k = checkpoint_k_speed(&policy.meta().training);
        let state = policy.new_state();
        Ok((
            Self {
                policy,
                state,
                k_speed: meta_k.unwrap_or(default_k_speed),
                shield: None,
                filter: None,
                planner: None,
            },
            meta_k.is_some(),
        ))
    }

    pub fn from_policy(policy: policy::Policy, k_speed: f32) -> Self {
        let state = policy.new_state();
        Self {
            policy,
            state,
            k_speed,
            shield: None,
            filter: None,
            planner: None,
        }
    }

    /// Whether the policy picks target boxes (`obs::targets`) rather than velocity moves.
    pub fn has_target_actions(&self) -> bool {
        self.policy.actor().arch.actions == policy::ActionSpace::Targets
    }

    /// The planner a target-action policy needs ([`GreedyOrca::target_preferred`]); its
    /// k_speed is set to the policy's. Ignored by a move policy.
    pub fn with_target_planner(mut self, mut params: OrcaParams) -> anyhow::Result<Self> {
        params.greedy.k_speed = self.k_speed;
        self.planner = Some(GreedyOrca::new(params).map_err(|e| anyhow::anyhow!(e))?);
        Ok(self)
    }

    /// Whether the checkpoint was trained behind the ORCA filter (then it runs behind it
    /// unless `-p orca_filter:=false`).
    pub fn trained_with_orca_filter(&self) -> bool {
        self.policy.trained_with_orca_filter()
    }

    /// Pass the policy's velocity through ORCA as a safety filter ([`GreedyOrca::filter`],
    /// the code `tending eval --orca-filter` runs); its k_speed is set to the policy's.
    pub fn with_orca_filter(mut self, mut params: OrcaParams) -> anyhow::Result<Self> {
        params.greedy.k_speed = self.k_speed;
        self.filter = Some(GreedyOrca::new(params).map_err(|e| anyhow::anyhow!(e))?);
        Ok(self)
    }

    /// Put the policy behind the action shield (its k_speed is set to the controller's).
    /// The caller refuses this for a target-action policy ([`Self::has_target_actions`]).
    pub fn with_shield(mut self, mut shield: ShieldParams) -> Self {
        shield.k_speed = self.k_speed;
        self.shield = Some(shield);
        self
    }

    pub fn state(&self) -> &policy::PolicyState {
        &self.state
    }

    /// The discrete action for row 0 of `obs` (advances the recurrent state).
    pub fn action(&mut self, obs: &ObsBatch) -> anyhow::Result<Action> {
        let a = match &self.shield {
            None => self
                .policy
                .act(obs, &mut self.state, policy::ActMode::Greedy)?,
            Some(sp) => {
                let sp = *sp;
                let logits = self.policy.logits(obs, &mut self.state)?;
                let mut l = [0.0f32; 5];
                anyhow::ensure!(
                    logits.len() == l.len(),
                    "policy has {} actions, the shield knows 5",
                    logits.len()
                );
                l.copy_from_slice(logits);
                let safe = obs::shield::safe_actions(
                    obs.own_row(0),
                    obs.machines_row(0),
                    obs.storages_row(0),
                    obs.peers_row(0),
                    &sp,
                );
                obs::shield::mask_logits(&mut l, &safe);
                policy::nn::categorical::argmax(&l) as u8
            }
        };
        Action::from_index(a as usize).ok_or_else(|| anyhow::anyhow!("policy gave action {a}"))
    }
}

/// Greedy-ORCA's knowledge of the fleet: the greedy parameters, the room (the wire
/// contract's 2.3 m) and the reach.
pub fn orca_params(p: &crate::args::Params) -> OrcaParams {
    let g = crate::node::greedy_params(p);
    let reach = p.reach.unwrap_or(p.robot_radius) as f32;
    OrcaParams::new(g, 2.0 * msgs::validate::ROOM_HALF_EXTENT as f32, reach)
}

/// The shield's knowledge of the fleet (k_speed is set from the policy's own).
pub fn shield_params(p: &crate::args::Params) -> ShieldParams {
    let g = crate::node::greedy_params(p);
    ShieldParams::new(
        g.robot_radius,
        g.machine_half,
        g.storage_half,
        g.k_speed,
        g.dt,
        2.0 * msgs::validate::ROOM_HALF_EXTENT as f32,
    )
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
        if let Some(f) = &mut self.filter {
            f.reset();
        }
        if let Some(p) = &mut self.planner {
            p.reset();
        }
    }
    fn act(&mut self, obs: &ObsBatch) -> anyhow::Result<[f32; 2]> {
        let v = if self.has_target_actions() {
            let a = self
                .policy
                .act(obs, &mut self.state, policy::ActMode::Greedy)?;
            let planner = self
                .planner
                .as_mut()
                .ok_or_else(|| anyhow::anyhow!("target-action policy without its planner"))?;
            planner.target_preferred(
                a,
                obs.own_row(0),
                obs.machines_row(0),
                obs.storages_row(0),
                obs.peers_row(0),
            )
        } else {
            action_velocity(self.action(obs)?, self.k_speed)
        };
        Ok(match &mut self.filter {
            Some(f) => f.filter(
                obs.own_row(0),
                obs.machines_row(0),
                obs.storages_row(0),
                obs.peers_row(0),
                v,
            ),
            None => v,
        })
    }
    fn name(&self) -> &'static str {
        "policy"
    }
    /// The planner's machine clock counts control steps ([`GreedyOrca::skip_steps`]): a
    /// missed state would otherwise leave it a step behind until that machine's next pick.
    fn state_gap(&mut self, gap_s: f64) {
        if let Some(p) = &mut self.planner {
            let steps = (gap_s / p.params().greedy.dt as f64).round();
            if steps >= 2.0 && steps.is_finite() {
                p.skip_steps((steps - 1.0).min(u32::MAX as f64) as u32);
            }
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
        let g = GreedyController::new(params(0.5));
        let o = b(
            [0.0, 0.0],
            false,
            vec![([0.5, 0.2], false), ([0.0, -0.6], true), ([0.9, 0.9], true)],
            vec![[-1.0, 0.0]],
        );
        assert_eq!(g.action(&o).unwrap(), Action::Down);
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
        assert_eq!(g.action(&o).unwrap(), Action::Stay);
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
        assert_eq!(g.action(&o).unwrap(), Action::Up);
        let o = b([0.0, 0.0], true, vec![([0.6, 0.0], true)], vec![]);
        assert_eq!(g.action(&o).unwrap(), Action::Stay);
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

    #[test]
    fn action_mapping() {
        for (i, v) in [[0.0, 0.0], [-1.0, 0.0], [1.0, 0.0], [0.0, -1.0], [0.0, 1.0]]
            .iter()
            .enumerate()
        {
            assert_eq!(action_velocity(Action::from_index(i).unwrap(), 1.0), *v);
        }
        // diagonals (9-action policies) at the same speed, then nothing
        let d = std::f32::consts::FRAC_1_SQRT_2;
        assert_eq!(action_velocity(Action::from_index(8).unwrap(), 1.0), [d, d]);
        assert_eq!(
            action_velocity(Action::from_index(5).unwrap(), 1.0),
            [-d, -d]
        );
        assert!(Action::from_index(9).is_none());
    }

    fn tmp(name: &str) -> std::path::PathBuf {
        std::env::temp_dir().join(format!("robot_node_{}_{name}", std::process::id()))
    }

    #[test]
    fn policy_controller_loads_checkpoint_keeps_and_resets_state() {
        let mut arch = policy::ArchConfig::smappo();
        arch.d_model = 8;
        arch.heads = 2;
        arch.hidden = 8;
        let actor = policy::Actor::new(arch, 7);
        let path = tmp("ok.safetensors");
        policy::checkpoint::save_policy(
            &path,
            &actor,
            serde_json::json!({"setup": "6.4_2", "k_speed": 0.3}),
        )
        .unwrap();
        let (mut c, from_meta) = PolicyController::load(&path, 0.5).unwrap();
        assert!(from_meta);
        assert_eq!(c.k_speed, 0.3);
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
            assert_eq!(
                v,
                action_velocity(Action::from_index(a as usize).unwrap(), 0.3)
            );
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
        let mut arch = policy::ArchConfig::smappo();
        arch.d_model = 8;
        arch.heads = 2;
        arch.hidden = 8;
        let sp = ShieldParams::new(0.08, [0.12, 0.12], [0.15, 0.08], 0.5, 0.1, 2.3);
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
            let actor = policy::Actor::new(arch, seed);
            let pol = policy::Policy::from_actor(actor, serde_json::Value::Null);
            let mut free = PolicyController::from_policy(pol.clone(), 0.5);
            unshielded_moves += (free.action(&o).unwrap() != Action::Stay) as usize;
            let mut c = PolicyController::from_policy(pol, 0.5).with_shield(sp);
            assert_eq!(c.action(&o).unwrap(), Action::Stay, "seed {seed}");
        }
        // The check means something only if unshielded actors would have moved.
        assert!(unshielded_moves > 0);
    }

    #[test]
    fn orca_filter_keeps_free_moves_and_holds_back_near_peers() {
        let mut arch = policy::ArchConfig::smappo();
        arch.d_model = 8;
        arch.heads = 2;
        arch.hidden = 8;
        let op = OrcaParams::new(params(0.5), 2.3, 0.08);
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
        for seed in 0..4 {
            let pol =
                policy::Policy::from_actor(policy::Actor::new(arch, seed), Default::default());
            let mut plain = PolicyController::from_policy(pol.clone(), 0.5);
            let mut c = PolicyController::from_policy(pol, 0.5)
                .with_orca_filter(op)
                .unwrap();
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
    /// greedy entry: toward the ready machine at full speed), and refuses to run without
    /// its planner.
    #[test]
    fn target_policy_drives_to_the_chosen_box() {
        let mut arch = policy::ArchConfig::smappo();
        arch.d_model = 8;
        arch.heads = 2;
        arch.hidden = 8;
        arch.n_actions = obs::targets::N_TARGET_ACTIONS;
        arch.actions = policy::ActionSpace::Targets;
        let mut actor = policy::Actor::new(arch, 1);
        actor.add_action_bias(obs::targets::TargetAction::Greedy as usize, 1e4);
        let pol = policy::Policy::from_actor(actor, Default::default());
        let obs = b(
            [0.0, 0.0],
            false,
            vec![([0.9, 0.0], true)],
            vec![[-0.9, 0.9]],
        );
        let mut bare = PolicyController::from_policy(pol.clone(), 0.5);
        assert!(bare.has_target_actions());
        assert!(bare.act(&obs).unwrap_err().to_string().contains("planner"));
        let op = OrcaParams::new(params(0.5), 2.3, 0.08);
        let mut c = PolicyController::from_policy(pol, 0.5)
            .with_target_planner(op)
            .unwrap()
            .with_orca_filter(op.with_clearance(obs::orca::FILTER_CLEARANCE))
            .unwrap();
        let v = c.act(&obs).unwrap();
        assert!((v[0] - 0.5).abs() < 1e-3 && v[1].abs() < 1e-3, "{v:?}");
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
