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

use super::config::TrainConfig;
use super::gae::gae;
use super::randomize::SetupRange;
use super::valuenorm::{ValueNorm, ValueNormBits};
use crate::checkpoint::{load_trainer_state, save_policy, save_trainer_state, CheckpointError};
use crate::config::{ArchConfig, ModelKind};
use crate::nn::categorical;
use crate::{Actor, Critic, PolicyError, PpoActorConfig, ValueLossConfig};
use obs::{FlatLayout, ObsBatch};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use sim::{Metrics, ScenarioConfig, Setup, VecEnv};
use std::path::Path;
use std::time::Instant;

#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    #[error(transparent)]
    Policy(#[from] PolicyError),
    #[error(transparent)]
    Sim(#[from] sim::SimError),
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    #[error("training config: {0}")]
    Config(String),
}

/// One curriculum stage: train on `setup` for `episodes` episodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stage {
    pub setup: Setup,
    pub episodes: u64,
}

/// Parse `6.4_2:2000,12.8_4:100` (setup:episodes, comma separated).
pub fn parse_curriculum(s: &str) -> Result<Vec<Stage>, TrainError> {
    let bad = |m: String| TrainError::Config(format!("curriculum `{s}`: {m}"));
    let mut out = vec![];
    for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (name, eps) = part
            .split_once(':')
            .ok_or_else(|| bad(format!("`{part}` is not setup:episodes")))?;
        let setup: Setup = name.parse()?;
        let episodes: u64 = eps
            .trim()
            .parse()
            .map_err(|_| bad(format!("`{eps}` is not an episode count")))?;
        if episodes == 0 {
            return Err(bad(format!("stage {name} has 0 episodes")));
        }
        out.push(Stage { setup, episodes });
    }
    if out.is_empty() {
        return Err(bad("no stage".into()));
    }
    Ok(out)
}

pub fn format_curriculum(stages: &[Stage]) -> String {
    stages
        .iter()
        .map(|s| format!("{}:{}", s.setup, s.episodes))
        .collect::<Vec<_>>()
        .join(",")
}

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

/// Rollout storage, step-major: entry `t * B + e * n + i`.
#[derive(Debug, Default)]
struct Rollout {
    obs: ObsBatch,
    masks: Vec<f32>,
    dones: Vec<bool>,
    actions: Vec<u8>,
    logp: Vec<f32>,
    /// Shield logit bias, n_actions per entry (empty when the shield is off).
    shield: Vec<f32>,
    /// critic outputs (normalised when ValueNorm is on)
    values: Vec<f32>,
    rewards: Vec<f32>,
    /// hidden states at chunk starts: (chunk, B, H)
    ha: Vec<f32>,
    hc: Vec<f32>,
    adv: Vec<f32>,
    ret: Vec<f32>,
}

/// A mini-batch of chunks, rows `t * B' + k * n + i`.
#[derive(Debug, Default)]
struct MiniBatch {
    obs: ObsBatch,
    masks: Vec<f32>,
    ha: Vec<f32>,
    hc: Vec<f32>,
    actions: Vec<u8>,
    logp: Vec<f32>,
    shield: Vec<f32>,
    adv: Vec<f32>,
    values: Vec<f32>,
    ret: Vec<f32>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
struct StateExtra {
    kind: ModelKind,
    config: TrainConfig,
    scenario_toml: String,
    schedule: String,
    seed: u64,
    update: u64,
    episodes: u64,
    agent_steps: u64,
    stage: usize,
    stage_episodes: u64,
    valuenorm: ValueNormBits,
    /// Setup range of a randomized run (absent in states saved before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    randomize: Option<String>,
    /// Lagrange multiplier (0 in states saved before constrained training existed).
    #[serde(default)]
    lambda: f32,
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

/// Default [`Trainer::part_rows`].
const PART_ROWS: usize = 16_384;

/// Activation memory one mini-batch part may take (actor + critic), which caps the part's
/// rows where a row is large (the MAPPO critic's input grows with robots squared). A
/// constant, not the machine's free memory, so results never depend on the machine.
const PART_BYTES: usize = 1 << 30;

/// Bytes of training state per row, measured in floats from the caches the networks keep
/// for backward (attention per group: ~1,600 floats plus 4 per entity; encoder, GRU head
/// ~2,100), for actor plus critic. Calibrated against the peak RSS of `train_bench
/// 100.16_2 8 1 1` (1.16 GB measured, 1.2 GB estimated).
fn part_row_bytes(kind: ModelKind, setup: Setup, cfg: &TrainConfig) -> usize {
    let ents = setup.machines + setup.storages + setup.robots.saturating_sub(1);
    let floats = match kind {
        ModelKind::Smappo => 2 * (7_000 + 12 * ents),
        ModelKind::Mappo => {
            let fd = obs::SELF_DIM
                + cfg.mappo_max_machines * obs::MACHINE_DIM
                + cfg.mappo_max_storages * obs::STORAGE_DIM
                + cfg.mappo_max_robots.saturating_sub(1) * obs::PEER_DIM;
            // actor: input, its LayerNorm output and their gradients; critic: the same
            // over [own ++ every robot's flat obs], plus both heads
            4 * fd + 4 * fd * (1 + setup.robots) + 4_000
        }
    };
    4 * floats
}

/// Obs floats per row of `setup`.
fn obs_floats(setup: Setup) -> usize {
    obs::SELF_DIM
        + setup.machines * obs::MACHINE_DIM
        + setup.storages * obs::STORAGE_DIM
        + setup.robots.saturating_sub(1) * obs::PEER_DIM
}

/// Rows of one mini-batch part for `setup`: `part_rows`, lowered so a part's activations
/// stay within [`PART_BYTES`].
fn part_rows_for(kind: ModelKind, setup: Setup, cfg: &TrainConfig, part_rows: usize) -> usize {
    part_rows.min(PART_BYTES / part_row_bytes(kind, setup, cfg).max(1))
}

/// Estimated peak memory of training `setup` (bytes): the rollout (observations and
/// per-row scalars of `n_envs` x robots x steps rows), one mini-batch part's activations
/// and its gathered copies, and the row index of a whole mini-batch.
pub fn estimate_train_bytes(
    kind: ModelKind,
    setup: Setup,
    cfg: &TrainConfig,
    episode_steps: usize,
    part_rows: usize,
) -> usize {
    let rows = cfg.n_envs * setup.robots * episode_steps;
    let of = obs_floats(setup);
    let rollout = rows * 4 * (of + 10) + rows * 4 * 2 * 64 / cfg.data_chunk_length.max(1);
    let chunk = setup.robots * cfg.data_chunk_length;
    let part = part_rows_for(kind, setup, cfg, part_rows).max(chunk);
    let mb_rows = rows.div_ceil(cfg.num_mini_batch.max(1));
    let part = part.min(mb_rows);
    rollout + part * (part_row_bytes(kind, setup, cfg) + 3 * 4 * of) + mb_rows * 8
}

/// MemAvailable of /proc/meminfo in bytes (None where there is none).
fn mem_available() -> Option<usize> {
    let s = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = s.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: usize = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Rollout rows of chunk units `units` in mini-batch order: `t * B' + k * n + i` <- source
/// `(c * l + t) * b + env * n + i`.
fn chunk_rows(
    units: &[usize],
    n: usize,
    n_chunks: usize,
    l: usize,
    b: usize,
    rows: &mut Vec<usize>,
) {
    rows.clear();
    for t in 0..l {
        for &u in units {
            let (env, c) = (u / n_chunks, u % n_chunks);
            for i in 0..n {
                rows.push((c * l + t) * b + env * n + i);
            }
        }
    }
}

/// Copy rows `rows` of `src` (in order) into `dst`.
pub(crate) fn gather_rows(src: &ObsBatch, rows: &[usize], dst: &mut ObsBatch) {
    let c = src.counts;
    dst.resize(rows.len(), c);
    let ws = [
        obs::SELF_DIM,
        c.machines * obs::MACHINE_DIM,
        c.storages * obs::STORAGE_DIM,
        c.peers * obs::PEER_DIM,
    ];
    let srcs = [&src.own, &src.machines, &src.storages, &src.peers];
    let dsts = [
        &mut dst.own,
        &mut dst.machines,
        &mut dst.storages,
        &mut dst.peers,
    ];
    for ((w, s), d) in ws.into_iter().zip(srcs).zip(dsts) {
        if w == 0 {
            continue;
        }
        for (k, &r) in rows.iter().enumerate() {
            d[k * w..(k + 1) * w].copy_from_slice(&s[r * w..(r + 1) * w]);
        }
    }
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
                obs::targets::TargetAction::Greedy as usize,
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
                (
                    ArchConfig::mappo(flat, cfg.mappo_max_robots),
                    ArchConfig::mappo(flat, max_robots),
                )
            }
        };
        if cfg.diagonal_actions {
            actor.n_actions = obs::action::N_ACTIONS_WITH_DIAGONALS;
        }
        if cfg.target_actions {
            actor.n_actions = obs::targets::N_TARGET_ACTIONS;
            actor.actions = crate::ActionSpace::Targets;
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

    fn rollout(&mut self, setup: Setup) -> Result<Vec<Metrics>, TrainError> {
        let cfg = &self.cfg;
        let (e, n) = (cfg.n_envs, setup.robots);
        let b = e * n;
        let t_len = self.scenario.world.episode_steps as usize;
        let l = cfg.data_chunk_length;
        let h = self.actor.hidden();
        let hc_dim = self.critic.arch.hidden;
        let mut venv = VecEnv::new(
            self.scenario.clone(),
            setup,
            e,
            mix(self.seed, self.update, 1),
        )?;
        let mut rng = ChaCha8Rng::seed_from_u64(mix(self.seed, self.update, 2));
        let buf = &mut self.buf;
        buf.obs = ObsBatch::default();
        buf.obs.rows = 0;
        for v in [
            &mut buf.masks,
            &mut buf.logp,
            &mut buf.shield,
            &mut buf.values,
            &mut buf.rewards,
            &mut buf.ha,
            &mut buf.hc,
        ] {
            v.clear();
        }
        buf.dones.clear();
        buf.actions.clear();
        let mut ha = vec![0.0f32; b * h];
        let mut hc = vec![0.0f32; b * hc_dim];
        let mut masks = vec![0.0f32; b];
        let mut step_obs = ObsBatch::default();
        let mut lp = vec![0.0f32; self.actor.arch.n_actions];
        let mut acts = vec![0u8; b];
        let mut finished = vec![];
        let shield = cfg
            .shield
            .then(|| sim::baselines::shield_params(venv.envs()[0].sizes(), &self.scenario));
        let mut bias = vec![0.0f32; self.actor.arch.n_actions];
        // One ORCA filter per robot (it keeps the positions it saw last step); rebuilt per
        // rollout because every rollout starts fresh episodes.
        // Target actions need the planner for their velocity even without the filter.
        let mut filters: Vec<obs::orca::GreedyOrca> = if cfg.orca_filter || cfg.target_actions {
            let p = sim::baselines::orca_params(venv.envs()[0].sizes(), &self.scenario)
                .with_clearance(cfg.orca_filter_clearance);
            let one = obs::orca::GreedyOrca::new(p).map_err(|reason| {
                TrainError::Config(format!("orca_filter: ORCA parameters: {reason}"))
            })?;
            vec![one; b]
        } else {
            Vec::new()
        };
        let mut vels = vec![[0.0f32; 2]; b];
        let lambda = if cfg.collision_budget.is_some() {
            self.lambda
        } else {
            0.0
        };
        let mut contacts_total = 0u64;
        for t in 0..t_len {
            venv.observe(&mut step_obs);
            if t % l == 0 {
                buf.ha.extend_from_slice(&ha);
                buf.hc.extend_from_slice(&hc);
            }
            buf.obs
                .extend_from(&step_obs)
                .map_err(|e| TrainError::Policy(PolicyError::Obs(e)))?;
            buf.masks.extend_from_slice(&masks);
            let (actor, critic) = (&mut self.actor, &mut self.critic);
            let (ra, rc) = rayon::join(
                || {
                    actor
                        .forward_step(&step_obs, &mut ha, &masks)
                        .map(|x| x.to_vec())
                },
                || {
                    critic
                        .forward_step(&step_obs, n, &mut hc, &masks)
                        .map(|x| x.to_vec())
                },
            );
            let (mut logits, values) = (ra?, rc?);
            let k = lp.len();
            for r in 0..b {
                let lg = &mut logits[r * k..(r + 1) * k];
                if let Some(sp) = &shield {
                    let safe = obs::shield::safe_actions(
                        step_obs.own_row(r),
                        step_obs.machines_row(r),
                        step_obs.storages_row(r),
                        step_obs.peers_row(r),
                        sp,
                    );
                    bias.iter_mut().for_each(|x| *x = 0.0);
                    obs::shield::mask_logits(&mut bias, &safe);
                    lg.iter_mut().zip(&bias).for_each(|(l, b)| *l += b);
                    buf.shield.extend_from_slice(&bias);
                }
                let lg = &*lg;
                categorical::log_softmax(lg, &mut lp);
                let a = categorical::sample(lg, rng.gen::<f32>());
                acts[r] = a as u8;
                buf.logp.push(lp[a]);
            }
            buf.actions.extend_from_slice(&acts);
            buf.values.extend_from_slice(&values);
            if filters.is_empty() {
                venv.step_actions(&acts)?;
            } else {
                let k_speed = self.scenario.task.k_speed;
                for (r, f) in filters.iter_mut().enumerate() {
                    let (own, m, s, p) = (
                        step_obs.own_row(r),
                        step_obs.machines_row(r),
                        step_obs.storages_row(r),
                        step_obs.peers_row(r),
                    );
                    let pref = if cfg.target_actions {
                        f.target_preferred(acts[r], own, m, s, p)
                    } else {
                        sim::action_to_velocity(acts[r], k_speed).unwrap_or([0.0, 0.0])
                    };
                    vels[r] = if cfg.orca_filter {
                        f.filter(own, m, s, p, pref)
                    } else {
                        pref
                    };
                }
                venv.step_velocities(&vels)?;
            }
            contacts_total += venv.contacts().iter().map(|&c| c as u64).sum::<u64>();
            buf.rewards.extend(
                venv.rewards()
                    .iter()
                    .zip(venv.contacts())
                    .map(|(r, &c)| (r - lambda * c as f32) * cfg.reward_scale),
            );
            for (ei, &d) in venv.done().iter().enumerate() {
                for i in 0..n {
                    buf.dones.push(d);
                    masks[ei * n + i] = if d { 0.0 } else { 1.0 };
                }
            }
            finished.extend(venv.finished().iter().flatten().copied());
        }
        self.last_contact_rate = contacts_total as f64 / (t_len * b).max(1) as f64;
        // bootstrap values of the state after the last step (masked by done in GAE)
        venv.observe(&mut step_obs);
        let last_raw = self
            .critic
            .forward_step(&step_obs, n, &mut hc, &masks)?
            .to_vec();
        let last: Vec<f32> = last_raw.iter().map(|&v| self.denorm(v)).collect();
        let values: Vec<f32> = self.buf.values.iter().map(|&v| self.denorm(v)).collect();
        let buf = &mut self.buf;
        buf.adv.resize(t_len * b, 0.0);
        buf.ret.resize(t_len * b, 0.0);
        gae(
            &buf.rewards,
            &values,
            &buf.dones,
            &last,
            t_len,
            b,
            cfg.gamma,
            cfg.gae_lambda,
            &mut buf.adv,
            &mut buf.ret,
        );
        if cfg.advantage_norm {
            let m = buf.adv.iter().map(|&x| x as f64).sum::<f64>() / buf.adv.len() as f64;
            let var = buf
                .adv
                .iter()
                .map(|&x| (x as f64 - m) * (x as f64 - m))
                .sum::<f64>()
                / buf.adv.len() as f64;
            let s = var.sqrt() + 1e-5;
            for a in &mut buf.adv {
                *a = ((*a as f64 - m) / s) as f32;
            }
        }
        Ok(finished)
    }

    fn ppo(&mut self, setup: Setup) -> Result<UpdateStats, TrainError> {
        let n = setup.robots;
        let cfg = self.cfg.clone();
        let e = cfg.n_envs;
        let b = e * n;
        let l = cfg.data_chunk_length;
        let t_len = self.scenario.world.episode_steps as usize;
        let n_chunks = t_len / l;
        let units = e * n_chunks;
        let per_mb = units.div_ceil(cfg.num_mini_batch);
        let (ha_dim, hc_dim) = (self.actor.hidden(), self.critic.arch.hidden);
        let mut rng = ChaCha8Rng::seed_from_u64(mix(self.seed, self.update, 3));
        let mut perm: Vec<usize> = (0..units).collect();
        let pcfg = PpoActorConfig {
            clip: cfg.clip_param,
            ent_coef: cfg.entropy_coef,
        };
        let vcfg = ValueLossConfig {
            clip: cfg.clip_param,
            huber_delta: cfg.huber_delta,
            coef: cfg.value_loss_coef,
        };
        let mut st = UpdateStats::default();
        let mut count = 0f32;
        let mut rows = vec![];
        let part_rows = part_rows_for(self.kind, setup, &cfg, self.part_rows);
        // Critic warm-up (`critic_warmup_updates`): the actor neither computes gradients
        // nor steps, so a trained actor is not pushed around by a fresh critic's noise.
        let train_actor = self.update >= cfg.critic_warmup_updates as u64;
        for _ in 0..cfg.ppo_epoch {
            perm.shuffle(&mut rng);
            for mb_units in perm.chunks(per_mb) {
                let mb_rows = mb_units.len() * n * l;
                // ValueNorm sees the whole mini-batch's returns first, as before splitting
                if cfg.use_valuenorm {
                    chunk_rows(mb_units, n, n_chunks, l, b, &mut rows);
                    let buf = &self.buf;
                    self.mb.ret.clear();
                    self.mb.ret.extend(rows.iter().map(|&r| buf.ret[r]));
                    self.vnorm.update(&self.mb.ret);
                }
                // Parts of at most PART_ROWS rows (whole chunks, so whole envs) go through
                // the networks one after the other, gradients accumulating: activation
                // memory is bounded by one part, not by the mini-batch (100 robots x 8 envs
                // is 160,000 rows). One part (every bundled config) is the unsplit step.
                for part in mb_units.chunks((part_rows / (n * l)).max(1)) {
                    let bu = part.len() * n;
                    chunk_rows(part, n, n_chunks, l, b, &mut rows);
                    let buf = &self.buf;
                    let mb = &mut self.mb;
                    gather_rows(&buf.obs, &rows, &mut mb.obs);
                    mb.masks.clear();
                    mb.masks.extend(rows.iter().map(|&r| buf.masks[r]));
                    mb.actions.clear();
                    mb.actions.extend(rows.iter().map(|&r| buf.actions[r]));
                    mb.logp.clear();
                    mb.logp.extend(rows.iter().map(|&r| buf.logp[r]));
                    mb.shield.clear();
                    if !buf.shield.is_empty() {
                        let k = self.actor.arch.n_actions;
                        for &r in &rows {
                            mb.shield.extend_from_slice(&buf.shield[r * k..(r + 1) * k]);
                        }
                    }
                    mb.adv.clear();
                    mb.adv.extend(rows.iter().map(|&r| buf.adv[r]));
                    mb.values.clear();
                    mb.values.extend(rows.iter().map(|&r| buf.values[r]));
                    mb.ret.clear();
                    mb.ret.extend(rows.iter().map(|&r| buf.ret[r]));
                    mb.ha.clear();
                    mb.hc.clear();
                    for &u in part {
                        let (env, c) = (u / n_chunks, u % n_chunks);
                        let r0 = c * b + env * n;
                        mb.ha
                            .extend_from_slice(&buf.ha[r0 * ha_dim..(r0 + n) * ha_dim]);
                        mb.hc
                            .extend_from_slice(&buf.hc[r0 * hc_dim..(r0 + n) * hc_dim]);
                    }
                    if cfg.use_valuenorm {
                        let vn = &self.vnorm;
                        mb.ret.iter_mut().for_each(|r| *r = vn.normalize(*r));
                    }
                    let (actor, critic, mb) = (&mut self.actor, &mut self.critic, &self.mb);
                    let (ra, rc) = rayon::join(
                        || {
                            if !train_actor {
                                return Ok(None);
                            }
                            actor
                                .ppo_grads_part_biased(
                                    &mb.obs,
                                    l,
                                    bu,
                                    &mb.ha,
                                    &mb.masks,
                                    &mb.actions,
                                    &mb.logp,
                                    &mb.adv,
                                    &mb.shield,
                                    pcfg,
                                    mb_rows,
                                )
                                .map(Some)
                        },
                        || {
                            critic.value_grads_part(
                                &mb.obs, l, bu, n, &mb.hc, &mb.masks, &mb.values, &mb.ret, vcfg,
                                mb_rows,
                            )
                        },
                    );
                    let (sa, sc) = (ra?, rc?);
                    if let Some(sa) = sa {
                        st.policy_loss += sa.policy_loss;
                        st.entropy += sa.entropy;
                        st.approx_kl += sa.approx_kl;
                        st.clip_frac += sa.clip_frac;
                    }
                    st.value_loss += sc.value_loss;
                }
                if train_actor {
                    st.actor_grad_norm += self.actor.step(cfg.max_grad_norm);
                }
                st.critic_grad_norm += self.critic.step(cfg.max_grad_norm);
                count += 1.0;
            }
        }
        for v in [
            &mut st.actor_grad_norm,
            &mut st.critic_grad_norm,
            &mut st.policy_loss,
            &mut st.entropy,
            &mut st.approx_kl,
            &mut st.clip_frac,
            &mut st.value_loss,
        ] {
            *v /= count.max(1.0);
        }
        Ok(st)
    }

    /// Free-form training metadata stored in the policy checkpoint.
    pub fn training_meta(&self) -> serde_json::Value {
        serde_json::json!({
            "model": self.kind,
            "setup": match self.randomize {
                Some(r) => r.to_string(),
                None => self.current_setup().to_string(),
            },
            "schedule": self.schedule_string(),
            "randomize": self.randomize.map(|r| r.to_string()),
            "episodes": self.episodes,
            "updates": self.update,
            "agent_steps": self.agent_steps,
            "seed": self.seed,
            "init_actor": self.init_actor_from,
            "lambda": self.lambda,
            "k_speed": self.scenario.task.k_speed,
            "scenario": serde_json::to_value(&self.scenario).unwrap_or(serde_json::Value::Null),
            "train_config": serde_json::to_value(&self.cfg).unwrap_or(serde_json::Value::Null),
        })
    }

    /// Start from a trained actor (e.g. fine-tuning the bundled policy behind a safety
    /// filter): its weights replace the fresh ones, with a fresh Adam. Refused unless its
    /// architecture is exactly this run's.
    pub fn init_actor(&mut self, actor: &Actor) -> Result<(), TrainError> {
        if actor.arch != self.actor.arch {
            return Err(TrainError::Config(format!(
                "the initial actor's architecture {:?} differs from this run's {:?}",
                actor.arch, self.actor.arch
            )));
        }
        let mut a = actor.clone();
        a.opt = self.actor.opt.clone();
        self.actor = a;
        Ok(())
    }

    pub fn save_policy(&self, path: &Path) -> Result<(), TrainError> {
        save_policy(path, &self.actor, self.training_meta())?;
        Ok(())
    }

    /// Everything needed to continue bit-exactly.
    pub fn save_state(&self, path: &Path) -> Result<(), TrainError> {
        let extra = StateExtra {
            kind: self.kind,
            config: self.cfg.clone(),
            scenario_toml: self.scenario.to_toml(),
            schedule: format_curriculum(&self.schedule),
            seed: self.seed,
            update: self.update,
            episodes: self.episodes,
            agent_steps: self.agent_steps,
            stage: self.stage,
            stage_episodes: self.stage_episodes,
            valuenorm: self.vnorm.to_bits(),
            randomize: self.randomize.map(|r| r.to_string()),
            lambda: self.lambda,
        };
        let v = serde_json::to_value(&extra).map_err(|e| TrainError::Config(e.to_string()))?;
        save_trainer_state(path, &self.actor, &self.critic, v)?;
        Ok(())
    }

    /// Continue from a saved state. `schedule`, when given, replaces the saved schedule
    /// (e.g. to extend a run); stage and episode counters are kept.
    pub fn resume(path: &Path, schedule: Option<Vec<Stage>>) -> Result<Self, TrainError> {
        let meta = crate::checkpoint::read_trainer_extra(path)?;
        let extra: StateExtra = serde_json::from_value(meta)
            .map_err(|e| TrainError::Config(format!("trainer state extra: {e}")))?;
        let scenario = ScenarioConfig::from_toml(&extra.scenario_toml, "trainer state")?;
        let saved = parse_curriculum(&extra.schedule)?;
        let mut t = Self::new(
            extra.kind,
            extra.config.clone(),
            scenario,
            saved.clone(),
            extra.seed,
        )?;
        load_trainer_state(path, &mut t.actor, &mut t.critic)?;
        t.update = extra.update;
        t.episodes = extra.episodes;
        t.agent_steps = extra.agent_steps;
        t.stage = extra.stage;
        t.stage_episodes = extra.stage_episodes;
        t.vnorm = ValueNorm::from_bits(extra.valuenorm);
        t.lambda = extra.lambda;
        if let Some(r) = &extra.randomize {
            let range: SetupRange = r.parse()?;
            Self::check_range(t.kind, &t.cfg, &t.scenario, range)?;
            t.randomize = Some(range);
        }
        if let Some(s) = schedule {
            if s != saved {
                t.set_schedule(s)?;
            }
        }
        Ok(t)
    }

    /// Replace the schedule (e.g. to extend a resumed run): the stage is re-derived from
    /// the episodes trained so far; refused when it would change the network shapes.
    /// A randomized run becomes a fixed-setup one (see [`Trainer::set_randomize`]).
    pub fn set_schedule(&mut self, s: Vec<Stage>) -> Result<(), TrainError> {
        if s.is_empty() {
            return Err(TrainError::Config("empty schedule".into()));
        }
        let (a, c) = Self::archs(self.kind, &self.cfg, &s)?;
        if a != self.actor.arch || c != self.critic.arch {
            return Err(TrainError::Config(
                "the new schedule changes the network shapes (MAPPO critic padding)".into(),
            ));
        }
        self.randomize = None;
        self.schedule = s;
        let mut left = self.episodes;
        self.stage = 0;
        self.stage_episodes = 0;
        for st in &self.schedule {
            if left >= st.episodes {
                left -= st.episodes;
                self.stage += 1;
            } else {
                self.stage_episodes = left;
                break;
            }
        }
        Ok(())
    }

    /// Train on setups drawn from `range` until `episodes` episodes in total (counted
    /// from the start of the run), e.g. to switch a resumed run to, or extend, a
    /// randomized schedule. Same refusals as [`Trainer::new_randomized`] and
    /// [`Trainer::set_schedule`].
    pub fn set_randomize(&mut self, range: SetupRange, episodes: u64) -> Result<(), TrainError> {
        Self::check_range(self.kind, &self.cfg, &self.scenario, range)?;
        if episodes == 0 {
            return Err(TrainError::Config(format!(
                "setup range {range}: 0 episodes to train"
            )));
        }
        self.set_schedule(vec![Stage {
            setup: range.hi,
            episodes,
        }])?;
        self.randomize = Some(range);
        Ok(())
    }

    /// A new total episode budget: the last stage (the only one of a randomized run)
    /// absorbs the difference; refused when it would end before the last stage starts.
    pub fn set_total_episodes(&mut self, total: u64) -> Result<(), TrainError> {
        let before: u64 = self.schedule[..self.schedule.len() - 1]
            .iter()
            .map(|x| x.episodes)
            .sum();
        if total <= before {
            return Err(TrainError::Config(format!(
                "{total} episodes end before the last curriculum stage (which starts at \
                 episode {before})"
            )));
        }
        match self.randomize {
            Some(r) => self.set_randomize(r, total),
            None => {
                let mut s = self.schedule.clone();
                s.last_mut().expect("non-empty").episodes = total - before;
                self.set_schedule(s)
            }
        }
    }
}
