//! Training hyper-parameters (TOML, every field optional, unknown fields refused).

use serde::{Deserialize, Serialize};

/// All PPO hyper-parameters. Defaults are MAPPO's (marlbenchmark/on-policy `config.py`)
/// except where a field says otherwise and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// Parallel environments per update (MAPPO `n_rollout_threads`, default there 32).
    /// Here 4: every update collects exactly one 200-step episode per env, so n_envs is
    /// the number of episodes per update; with 32, a 2,000-episode run (the paper's
    /// budget) would make only 62 updates, with 4 it makes 500 (4,800 agent-steps each on
    /// 6.4_2). The cost per agent-step is about the same either way.
    pub n_envs: usize,
    /// PPO epochs over each batch (MAPPO default 15, 10 for some MPE tasks). Here 10:
    /// measured on the 2-core machine (docs/bench/train.md), 6.4_2 trains at ~2,500
    /// agent-steps/s with 10 epochs (actor and critic on the two cores), so 2,000 episodes
    /// (2.4 M agent-steps) take ~16 min on a quiet machine and ~26 min with the load of
    /// the other engineers' jobs; 15 epochs would add half again.
    pub ppo_epoch: usize,
    /// Mini-batches per epoch (MAPPO default 1).
    pub num_mini_batch: usize,
    /// BPTT chunk length (MAPPO `data_chunk_length` 10); must divide the episode length.
    pub data_chunk_length: usize,
    pub gamma: f32,
    pub gae_lambda: f32,
    /// PPO ratio clip (MAPPO `clip_param`).
    pub clip_param: f32,
    pub entropy_coef: f32,
    pub value_loss_coef: f32,
    /// Huber delta of the value loss.
    pub huber_delta: f32,
    pub max_grad_norm: f32,
    /// Adam learning rate, actor and critic (MAPPO `lr`, `critic_lr`).
    pub lr: f32,
    pub critic_lr: f32,
    /// Adam epsilon (MAPPO `opti_eps`).
    pub opti_eps: f32,
    /// MAPPO ValueNorm running-statistics decay.
    pub valuenorm_beta: f64,
    pub use_valuenorm: bool,
    /// Normalise advantages over the batch (MAPPO does).
    pub advantage_norm: bool,
    /// Multiply every reward by this before learning (1 = the simulator's rewards).
    pub reward_scale: f32,
    /// Share of each robot's learning reward that is its environment's mean robot reward
    /// this step: 0 = its own (the paper), 1 = the team's. The simulator's rewards are per
    /// robot, so a move that pays only others (an idle robot making room at a storage
    /// area, ADR 0014) earns the mover nothing at 0.
    pub team_reward: f32,
    /// MAPPO only: observation padding (actor and critic). Defaults cover the paper's
    /// largest zero-shot setup 42.28_14, so a MAPPO trained on 6.4_2 can be evaluated on
    /// every Table III setup.
    pub mappo_max_robots: usize,
    pub mappo_max_machines: usize,
    pub mappo_max_storages: usize,
    /// MAPPO only: width of its MLP layers and GRU (actor and critic; the reference's
    /// hidden_size, 64). A tuning knob of issue 47; SMAPPO keeps the paper's 64.
    pub mappo_hidden: usize,
    /// Save checkpoints every this many updates (and at the end / on Ctrl-C).
    pub save_every: usize,
    /// Sample rollout actions behind the one-step action shield (`plan::shield`, the one
    /// `tending eval --shield` and robot_node `shield:=true` use) and score them under the
    /// same masked distribution in the update. Off by default (the paper's training).
    pub shield: bool,
    /// Pass every rollout action, as a velocity, through the ORCA safety filter
    /// (`plan::orca::GreedyOrca::filter`, the code `tending eval --orca-filter` and
    /// robot_node `orca_filter:=true` run) before the simulator steps: the policy learns
    /// with the filter as part of its world. PPO still scores the discrete action.
    pub orca_filter: bool,
    /// Peer clearance of that filter at full speed, m (`plan::orca::FILTER_CLEARANCE`; runs
    /// before it existed used greedy-ORCA's 0.025); at rest the smaller of this and
    /// `plan::orca::FILTER_REST_CLEARANCE` (ADR 0017, 0019: 35 mm until 0019; runs before 0017 kept it fixed).
    pub orca_filter_clearance: f32,
    /// Constrained PPO (PPO-Lagrangian, Ray et al. 2019, as reward shaping): hold the
    /// contact rate (bodies touched per robot-step, all kinds) at this budget with a
    /// Lagrange multiplier that is subtracted per contact from each robot's reward and
    /// adapted by dual ascent after every rollout. Absent: no multiplier.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub collision_budget: Option<f32>,
    /// Dual ascent step: the multiplier grows by `lagrange_lr x (rate - budget)` per update
    /// (reward units per contact, per unit of contact rate).
    pub lagrange_lr: f32,
    /// Multiplier at the start of training.
    pub lagrange_init: f32,
    /// Updates at the start of the run during which only the critic learns (the actor is
    /// frozen): for a run that starts from a trained actor (`tending train --init-actor`)
    /// with a fresh critic, whose first advantages would be noise.
    pub critic_warmup_updates: usize,
    /// 9 actions instead of the paper's 5: the 4 diagonals at the same speed
    /// (`obs::action`). Axis moves only make a robot travel |dx| + |dy|, 1.27x the straight
    /// distance on average, which the continuous-velocity baseline does not pay.
    pub diagonal_actions: bool,
    /// Target actions (`plan::targets`) instead of velocity moves: the policy picks which
    /// box to drive to from a fixed menu, the robot drives there straight; rollouts step
    /// the simulator with that velocity (through the ORCA filter when `orca_filter`).
    pub target_actions: bool,
    /// Added to the initial logit of the "greedy" target action, so that a fresh policy
    /// starts close to greedy-ORCA's choices instead of uniform over the menu (0: uniform).
    pub target_greedy_bias: f32,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            n_envs: 4,
            ppo_epoch: 10,
            num_mini_batch: 1,
            data_chunk_length: 10,
            gamma: 0.99,
            gae_lambda: 0.95,
            clip_param: 0.2,
            entropy_coef: 0.01,
            value_loss_coef: 1.0,
            huber_delta: 10.0,
            max_grad_norm: 10.0,
            lr: 5e-4,
            critic_lr: 5e-4,
            opti_eps: 1e-5,
            valuenorm_beta: 0.99999,
            use_valuenorm: true,
            advantage_norm: true,
            reward_scale: 1.0,
            team_reward: 0.0,
            mappo_max_robots: 42,
            mappo_max_machines: 28,
            mappo_max_storages: 14,
            mappo_hidden: 64,
            save_every: 5,
            shield: false,
            orca_filter: false,
            orca_filter_clearance: plan::orca::FILTER_CLEARANCE,
            collision_budget: None,
            lagrange_lr: 2.0,
            lagrange_init: 0.0,
            critic_warmup_updates: 0,
            diagonal_actions: false,
            target_actions: false,
            target_greedy_bias: 0.0,
        }
    }
}

impl TrainConfig {
    /// The training config file at `path`; errors name it and say whether it is missing,
    /// unreadable or malformed (crate `inputs`).
    pub fn load(path: &std::path::Path) -> Result<Self, inputs::InputError> {
        inputs::parse_text("training config", path, Self::from_toml)
    }

    pub fn from_toml(text: &str) -> Result<Self, String> {
        let c: Self = toml::from_str(text).map_err(|e| e.to_string())?;
        c.validate()?;
        Ok(c)
    }

    pub fn validate(&self) -> Result<(), String> {
        let pos = [
            ("n_envs", self.n_envs),
            ("ppo_epoch", self.ppo_epoch),
            ("num_mini_batch", self.num_mini_batch),
            ("data_chunk_length", self.data_chunk_length),
            ("save_every", self.save_every),
            ("mappo_hidden", self.mappo_hidden),
        ];
        for (name, v) in pos {
            if v == 0 {
                return Err(format!("{name} must be >= 1"));
            }
        }
        if !(0.0..=1.0).contains(&self.gamma) || !(0.0..=1.0).contains(&self.gae_lambda) {
            return Err("gamma and gae_lambda must lie in [0, 1]".into());
        }
        if !(self.valuenorm_beta > 0.0 && self.valuenorm_beta < 1.0) {
            return Err("valuenorm_beta must lie in (0, 1)".into());
        }
        if !(self.lr > 0.0 && self.critic_lr > 0.0) {
            return Err("learning rates must be > 0".into());
        }
        if let Some(b) = self.collision_budget {
            if !(b.is_finite() && b >= 0.0) {
                return Err(format!("collision_budget must be >= 0, got {b}"));
            }
        }
        if !(self.lagrange_lr.is_finite() && self.lagrange_lr >= 0.0) {
            return Err(format!(
                "lagrange_lr must be >= 0, got {}",
                self.lagrange_lr
            ));
        }
        if !(self.lagrange_init.is_finite() && self.lagrange_init >= 0.0) {
            return Err(format!(
                "lagrange_init must be >= 0, got {}",
                self.lagrange_init
            ));
        }
        if self.target_actions && (self.diagonal_actions || self.shield) {
            return Err(
                "target_actions cannot be combined with diagonal_actions or shield (those \
                 act on velocity moves)"
                    .into(),
            );
        }
        if !(0.0..=1.0).contains(&self.team_reward) {
            return Err(format!(
                "team_reward must lie in [0, 1], got {}",
                self.team_reward
            ));
        }
        if !self.target_greedy_bias.is_finite() {
            return Err(format!(
                "target_greedy_bias must be finite, got {}",
                self.target_greedy_bias
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::TrainConfig;

    #[test]
    fn team_reward_is_a_share_in_0_to_1() {
        assert_eq!(TrainConfig::default().team_reward, 0.0);
        let c = TrainConfig::from_toml("team_reward = 0.5").unwrap();
        assert_eq!(c.team_reward, 0.5);
        for bad in [
            "team_reward = 1.5",
            "team_reward = -0.1",
            "team_reward = nan",
        ] {
            let e = TrainConfig::from_toml(bad).unwrap_err();
            assert!(e.contains("team_reward"), "{bad}: {e}");
        }
    }
}
