//! The PPO trainer (MAPPO recipe) for SMAPPO and MAPPO actor/critic pairs.
//!
//! One update = one rollout of `episode_steps` steps in `n_envs` fresh environments (so
//! exactly `n_envs` episodes), GAE per robot on per-robot rewards, then `ppo_epoch`
//! epochs of recurrent PPO over 10-step chunks (hidden state at each chunk start taken
//! from the rollout), actor and critic gradients computed on the two cores at once.
//!
//! Determinism and exact resume: every random stream of update `u` (environment seeds,
//! action sampling, chunk shuffling) derives from (seed, u) only, and updates start from
//! freshly reset environments, so the trainer state between updates is just the networks,
//! Adam moments, the value normaliser and counters; [`Trainer::save_state`] stores all of
//! them bit-exactly.
//!
//! Randomized setups ([`Trainer::new_randomized`]): instead of a schedule of fixed setups,
//! every update draws its robot/machine/storage counts from a [`SetupRange`] (per update:
//! all `n_envs` envs of the rollout share them), from a generator seeded by (seed, update)
//! like every other stream, so the draws survive save/resume exactly.
//!
//! Where things are: the trainer and its update step here; [`curriculum`] stages,
//! [`rollout`] collection and GAE, [`ppo_update`] (mini-batches and the PPO epochs),
//! [`memory`] (the memory estimate and mini-batch part size), [`state`] (checkpoints,
//! resume and schedule changes).

mod curriculum;
mod memory;
mod ppo_update;
mod rollout;
mod state;

pub use curriculum::{format_curriculum, parse_curriculum, Stage};
pub use memory::estimate_train_bytes;

use super::config::TrainConfig;
use super::randomize::SetupRange;
use super::valuenorm::ValueNorm;
pub use crate::error::TrainError;
use memory::{mem_available, PART_ROWS};
use obs::FlatLayout;
use policy::config::{ArchConfig, ModelKind};
use policy::{Actor, Critic};
use ppo_update::MiniBatch;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rollout::Rollout;
use serde::Serialize;
use sim::{ScenarioConfig, Setup};
use std::time::Instant;

/// What one update did.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct UpdateStats {
    /// 1-based index of this update.
    pub update: u64,
    /// Totals after this update.
    pub episodes: u64,
    pub agent_steps: u64,
    pub stage: usize,
    pub setup: String,
    /// True when this update was the first of a new curriculum stage.
    pub stage_start: bool,
    /// Means over this update's episodes.
    pub team_reward: f64,
    pub parts_delivered: f64,
    pub collisions: f64,
    pub mu: f64,
    /// Means over the mini-batch steps of this update.
    pub policy_loss: f32,
    pub value_loss: f32,
    pub entropy: f32,
    pub approx_kl: f32,
    pub clip_frac: f32,
    pub actor_grad_norm: f32,
    pub critic_grad_norm: f32,
    pub rollout_secs: f64,
    pub train_secs: f64,
    /// Bodies touched per robot-step in this update's rollout (all kinds).
    pub contact_rate: f64,
    /// Lagrange multiplier the rollout's rewards were shaped with (0 without a budget).
    pub lambda: f32,
}

pub struct Trainer {
    pub kind: ModelKind,
    pub cfg: TrainConfig,
    pub scenario: ScenarioConfig,
    pub schedule: Vec<Stage>,
    pub seed: u64,
    pub actor: Actor,
    pub critic: Critic,
    pub vnorm: ValueNorm,
    /// Updates done so far.
    pub update: u64,
    pub episodes: u64,
    pub agent_steps: u64,
    pub stage: usize,
    pub stage_episodes: u64,
    /// Randomized run: each update draws its setup from this range (see
    /// [`Trainer::setup_for_update`]); `schedule` then holds one stage whose setup is the
    /// range's largest (`hi`), which sizes the MAPPO critic, and the episode budget.
    pub randomize: Option<SetupRange>,
    /// Most rows of a mini-batch that go through the networks at once (see
    /// `Trainer::ppo`); a memory bound, not a hyper-parameter: splitting changes results
    /// only by summation order.
    pub part_rows: usize,
    /// Lagrange multiplier on the contact rate (`TrainConfig::collision_budget`).
    pub lambda: f32,
    /// Checkpoint the actor started from (`Trainer::init_actor`), recorded in the policy's
    /// metadata.
    pub init_actor_from: Option<String>,
    /// Contact rate of the last rollout (bodies touched per robot-step).
    last_contact_rate: f64,
    buf: Rollout,
    mb: MiniBatch,
}

/// splitmix64 of (seed, update, stream): independent seeds per update and purpose.
fn mix(seed: u64, update: u64, stream: u64) -> u64 {
    let mut z = seed
        .wrapping_add(update.wrapping_mul(0x9E37_79B9_7F4A_7C15))
        .wrapping_add(stream.wrapping_mul(0xD1B5_4A32_D192_ED03));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl Trainer {
    /// Fresh networks for `kind`, seeded by `seed`.
    pub fn new(
        kind: ModelKind,
        cfg: TrainConfig,
        scenario: ScenarioConfig,
        schedule: Vec<Stage>,
        seed: u64,
    ) -> Result<Self, TrainError> {
        cfg.validate().map_err(TrainError::Config)?;
        if schedule.is_empty() {
            return Err(TrainError::Config("empty schedule".into()));
        }
        let steps = scenario.world.episode_steps as usize;
        if !steps.is_multiple_of(cfg.data_chunk_length) {
            return Err(TrainError::Config(format!(
                "data_chunk_length {} must divide the episode length {steps}",
                cfg.data_chunk_length
            )));
        }
        let (actor_arch, critic_arch) = Self::archs(kind, &cfg, &schedule)?;
        // refuse up front what the machine cannot hold, instead of being OOM-killed
        if let Some(avail) = mem_available() {
            for st in &schedule {
                let need = estimate_train_bytes(kind, st.setup, &cfg, steps, PART_ROWS);
                if need > avail {
                    return Err(TrainError::Config(format!(
                        "training {kind} on {} with {} envs needs about {:.1} GB (rollout of \
                         {} rows plus one mini-batch part), this machine has {:.1} GB \
                         available: use fewer envs (n_envs) or more mini-batches",
                        st.setup,
                        cfg.n_envs,
                        need as f64 / 1e9,
                        cfg.n_envs * st.setup.robots * steps,
                        avail as f64 / 1e9
                    )));
                }
            }
        }
        let mut actor = Actor::new(actor_arch, mix(seed, u64::MAX, 10));
        if cfg.target_actions {
            actor.add_action_bias(
                plan::targets::TargetAction::Greedy as usize,
                cfg.target_greedy_bias,
            );
        }
        let mut critic = Critic::new(critic_arch, mix(seed, u64::MAX, 11));
        actor.opt.cfg.lr = cfg.lr;
        actor.opt.cfg.eps = cfg.opti_eps;
        critic.opt.cfg.lr = cfg.critic_lr;
        critic.opt.cfg.eps = cfg.opti_eps;
        let lambda = if cfg.collision_budget.is_some() {
            cfg.lagrange_init
        } else {
            0.0
        };
        Ok(Self {
            kind,
            vnorm: ValueNorm::new(cfg.valuenorm_beta),
            cfg,
            scenario,
            schedule,
            seed,
            actor,
            critic,
            update: 0,
            episodes: 0,
            agent_steps: 0,
            stage: 0,
            stage_episodes: 0,
            randomize: None,
            part_rows: PART_ROWS,
            lambda,
            last_contact_rate: 0.0,
            init_actor_from: None,
            buf: Rollout::default(),
            mb: MiniBatch::default(),
        })
    }

    /// Fresh networks trained on setups drawn from `range`, one draw per update (all
    /// `n_envs` envs of a rollout share it), for `episodes` episodes. Refused before any
    /// training when the range holds a setup the layout generator cannot place, or (MAPPO)
    /// when its upper bounds exceed the config's `mappo_max_*` padding. MAPPO's actor is
    /// padded to `mappo_max_*` as usual, its critic to the range's most robots.
    pub fn new_randomized(
        kind: ModelKind,
        cfg: TrainConfig,
        scenario: ScenarioConfig,
        range: SetupRange,
        episodes: u64,
        seed: u64,
    ) -> Result<Self, TrainError> {
        Self::check_range(kind, &cfg, &scenario, range)?;
        if episodes == 0 {
            return Err(TrainError::Config(format!(
                "setup range {range}: 0 episodes to train"
            )));
        }
        let stage = Stage {
            setup: range.hi,
            episodes,
        };
        let mut t = Self::new(kind, cfg, scenario, vec![stage], seed)?;
        t.randomize = Some(range);
        Ok(t)
    }

    fn check_range(
        kind: ModelKind,
        cfg: &TrainConfig,
        scenario: &ScenarioConfig,
        range: SetupRange,
    ) -> Result<(), TrainError> {
        range
            .check_padding(kind, cfg)
            .and_then(|()| range.check_fits(scenario))
            .map_err(|e| TrainError::Config(format!("setup range {range}: {e}")))
    }

    /// The setup update `update` (0-based) trains on: in a randomized run, the draw of
    /// the generator seeded by (seed, update), a pure function of both; otherwise the
    /// current stage's setup.
    pub fn setup_for_update(&self, update: u64) -> Setup {
        match self.randomize {
            Some(r) => r.draw(&mut ChaCha8Rng::seed_from_u64(mix(self.seed, update, 4))),
            None => self.schedule[self.stage.min(self.schedule.len() - 1)].setup,
        }
    }

    /// `6.4_2:2000,12.8_4:100`, or `2..12.2..8_1..4:400` for a randomized run.
    pub fn schedule_string(&self) -> String {
        match self.randomize {
            Some(r) => format!("{r}:{}", self.total_episodes()),
            None => format_curriculum(&self.schedule),
        }
    }

    fn archs(
        kind: ModelKind,
        cfg: &TrainConfig,
        schedule: &[Stage],
    ) -> Result<(ArchConfig, ArchConfig), TrainError> {
        let (mut actor, critic) = match kind {
            ModelKind::Smappo => (ArchConfig::smappo(), ArchConfig::smappo()),
            ModelKind::Mappo => {
                let flat = FlatLayout {
                    max_machines: cfg.mappo_max_machines,
                    max_storages: cfg.mappo_max_storages,
                    max_peers: cfg.mappo_max_robots.saturating_sub(1),
                };
                let max_robots = schedule.iter().map(|s| s.setup.robots).max().unwrap_or(1);
                for s in schedule {
                    if s.setup.robots > cfg.mappo_max_robots
                        || s.setup.machines > cfg.mappo_max_machines
                        || s.setup.storages > cfg.mappo_max_storages
                    {
                        return Err(TrainError::Config(format!(
                            "setup {} exceeds the MAPPO padding ({} robots, {} machines, {} \
                             storages): raise mappo_max_*",
                            s.setup,
                            cfg.mappo_max_robots,
                            cfg.mappo_max_machines,
                            cfg.mappo_max_storages
                        )));
                    }
                }
                // The actor is padded to the configured maxima (zero-shot evaluation);
                // the critic only needs the robots it is trained with.
                let sized = |mut a: ArchConfig| {
                    a.hidden = cfg.mappo_hidden;
                    a
                };
                (
                    sized(ArchConfig::mappo(flat, cfg.mappo_max_robots)),
                    sized(ArchConfig::mappo(flat, max_robots)),
                )
            }
        };
        if cfg.diagonal_actions {
            actor.n_actions = obs::action::N_ACTIONS_WITH_DIAGONALS;
        }
        if cfg.target_actions {
            actor.n_actions = plan::targets::N_TARGET_ACTIONS;
            actor.actions = policy::ActionSpace::Targets;
        }
        Ok((actor, critic))
    }

    pub fn total_episodes(&self) -> u64 {
        self.schedule.iter().map(|s| s.episodes).sum()
    }

    pub fn finished(&self) -> bool {
        self.stage >= self.schedule.len()
    }

    /// Setup of the stage being trained (the last one when finished); in a randomized
    /// run, the setup the next update draws.
    pub fn current_setup(&self) -> Setup {
        self.setup_for_update(self.update)
    }

    /// Collect one rollout and run the PPO epochs.
    pub fn step(&mut self) -> Result<UpdateStats, TrainError> {
        if self.finished() {
            return Err(TrainError::Config("the schedule is finished".into()));
        }
        let setup = self.current_setup();
        let stage_start = self.stage_episodes == 0;
        let t0 = Instant::now();
        let metrics = self.rollout(setup).map_err(|e| match (self.randomize, e) {
            (Some(r), TrainError::Sim(e)) => TrainError::Config(format!(
                "update {}: setup {setup} drawn from {r}: {e}",
                self.update + 1
            )),
            (_, e) => e,
        })?;
        let rollout_secs = t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        let mut st = self.ppo(setup)?;
        st.train_secs = t1.elapsed().as_secs_f64();
        st.rollout_secs = rollout_secs;
        st.contact_rate = self.last_contact_rate;
        st.lambda = self.lambda;
        // Dual ascent on the multiplier after the rollout that used it (PPO-Lagrangian).
        if let Some(budget) = self.cfg.collision_budget {
            let err = self.last_contact_rate as f32 - budget;
            self.lambda = (self.lambda + self.cfg.lagrange_lr * err).max(0.0);
        }

        let e = self.cfg.n_envs as u64;
        self.update += 1;
        self.episodes += e;
        self.agent_steps += e * self.scenario.world.episode_steps as u64 * setup.robots as u64;
        self.stage_episodes += e;
        st.stage = self.stage;
        if self.stage_episodes >= self.schedule[self.stage].episodes {
            self.stage += 1;
            self.stage_episodes = 0;
        }
        st.update = self.update;
        st.episodes = self.episodes;
        st.agent_steps = self.agent_steps;
        st.setup = setup.to_string();
        st.stage_start = stage_start;
        let k = metrics.len().max(1) as f64;
        st.team_reward = metrics.iter().map(|m| m.total_reward).sum::<f64>() / k;
        st.parts_delivered = metrics
            .iter()
            .map(|m| m.parts_delivered as f64)
            .sum::<f64>()
            / k;
        st.collisions = metrics.iter().map(|m| m.collisions as f64).sum::<f64>() / k;
        st.mu = metrics.iter().map(|m| m.utilization()).sum::<f64>() / k;
        Ok(st)
    }

    fn denorm(&self, v: f32) -> f32 {
        if self.cfg.use_valuenorm {
            self.vnorm.denormalize(v)
        } else {
            v
        }
    }
}
