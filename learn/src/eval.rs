//! Evaluation episodes: a learned actor or a scripted baseline through one code path.
//!
//! A learned actor drives through `plan`'s pilot (shield, target planner, ORCA filter as
//! its [`Safety`] says), the same one the trainer's rollouts and robot_node use;
//! matching-ORCA is that pilot always asking for the menu's "matched" entry.

use super::trainer::TrainError;
use crate::baselines::{fleet_params, random_action, GreedyOrcaFleet};
use obs::ObsBatch;
use plan::greedy::{greedy_action, GreedyParams};
use plan::orca::{GREEDY_ORCA_CLEARANCE, OBSTACLE_HORIZON};
use plan::pilot::{self, FilterMargins, MatchingOrca, Outputs, Pilot, Row, Safety};
use policy::{Actor, Choice};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use sim::{episode_seed, Env, Metrics, ScenarioConfig, Setup};

/// What an offline episode runs: a scripted method or a checkpoint, described, not yet
/// running (`run_episode` builds one stateful pilot or planner per robot from it and steps
/// them over the whole batch: a learned actor's logits come batched). One robot at a time,
/// the same code runs behind `plan::Controller` (the scripts in `plan::controller`, the
/// policy in `policy::controller`), as robot_node runs it; the lockstep tests hold the two
/// equal step for step.
#[derive(Debug, Clone)]
pub enum Method {
    /// A trained actor (argmax actions unless `sample`) through its pilot, behind the
    /// one-step action shield, the ORCA filter or neither (`safety`).
    Learned {
        actor: Box<Actor>,
        sample: bool,
        safety: Safety,
    },
    Greedy,
    /// Greedy task allocation + ORCA avoidance (`plan::orca`), continuous velocities.
    GreedyOrca {
        /// Peer clearance, m (`plan::orca::GREEDY_ORCA_CLEARANCE` by default).
        clearance: f32,
        /// Horizon for boxes and walls, s (`plan::orca::OBSTACLE_HORIZON` by default).
        obstacle_horizon: f32,
    },
    /// matching-ORCA (docs/adr/0020): every robot always asks the target menu for its
    /// "matched" entry, through the pilot behind the ORCA filter with these margins.
    MatchingOrca {
        margins: FilterMargins,
    },
    Random,
}

impl Method {
    /// Greedy-ORCA at its own clearance and obstacle horizon
    /// (`plan::orca::GREEDY_ORCA_CLEARANCE`, `plan::orca::OBSTACLE_HORIZON`).
    pub fn greedy_orca() -> Self {
        Method::GreedyOrca {
            clearance: GREEDY_ORCA_CLEARANCE,
            obstacle_horizon: OBSTACLE_HORIZON,
        }
    }

    /// matching-ORCA behind the ORCA filter as it is deployed.
    pub fn matching_orca() -> Self {
        Method::MatchingOrca {
            margins: FilterMargins::DEPLOYED,
        }
    }

    /// `actor` as it is, no safety layer.
    pub fn learned(actor: Box<Actor>, sample: bool) -> Self {
        Method::Learned {
            actor,
            sample,
            safety: Safety::RAW,
        }
    }

    /// `actor` behind the one-step action shield (`plan::shield`).
    pub fn shielded(actor: Box<Actor>, sample: bool) -> Self {
        Method::Learned {
            actor,
            sample,
            safety: Safety {
                shield: true,
                filter: None,
            },
        }
    }

    /// `actor` behind the ORCA filter as it is deployed ([`FilterMargins::DEPLOYED`]).
    pub fn filtered(actor: Box<Actor>, sample: bool) -> Self {
        Method::Learned {
            actor,
            sample,
            safety: Safety::filtered(FilterMargins::DEPLOYED),
        }
    }

    /// What the analysis examples (`menu_use`, `contact_sites`, `machine_waits`) take as
    /// their first argument: "greedy-orca" or "matching-orca" for a script, else a
    /// checkpoint's actor behind the ORCA filter as deployed ([`Self::filtered`], argmax).
    pub fn script_or_filtered_checkpoint(
        arg: &str,
    ) -> Result<Self, policy::checkpoint::CheckpointError> {
        match arg {
            "greedy-orca" => return Ok(Self::greedy_orca()),
            "matching-orca" => return Ok(Self::matching_orca()),
            _ => {}
        }
        let pol = policy::Policy::load(arg)?;
        Ok(Self::filtered(Box::new(pol.actor().clone()), false))
    }
}

/// Environment seed of evaluation episode `episode` under `seed`.
pub fn eval_env_seed(seed: u64, episode: u64) -> u64 {
    episode_seed(seed, 0, episode)
}

/// One episode of `setup`, deterministic in (seed, episode).
pub fn run_episode(
    ctrl: &Method,
    cfg: &ScenarioConfig,
    setup: Setup,
    seed: u64,
    episode: u64,
) -> Result<Metrics, TrainError> {
    run_episode_watched(ctrl, cfg, setup, seed, episode, |_| {})
}

/// [`run_episode`], showing `on_step` the environment at the start and after every step
/// (`tending sim --render` draws them).
pub fn run_episode_watched(
    ctrl: &Method,
    cfg: &ScenarioConfig,
    setup: Setup,
    seed: u64,
    episode: u64,
    on_step: impl FnMut(&Env),
) -> Result<Metrics, TrainError> {
    run_episode_hooked(ctrl, cfg, setup, seed, episode, on_step, |_, _| {})
}

/// [`run_episode_watched`], also showing `on_actions` each step's observation and the
/// discrete actions chosen on it (greedy, learned controllers and matching-ORCA, whose
/// actions are all "matched"; the random controller observes nothing, so its batch is
/// empty; greedy-ORCA chooses no discrete action and never calls it).
/// `policy/examples/menu_use.rs` counts menu entries with it.
pub fn run_episode_hooked(
    ctrl: &Method,
    cfg: &ScenarioConfig,
    setup: Setup,
    seed: u64,
    episode: u64,
    mut on_step: impl FnMut(&Env),
    mut on_actions: impl FnMut(&ObsBatch, &[u8]),
) -> Result<Metrics, TrainError> {
    let mut env = Env::new(cfg.clone(), setup, eval_env_seed(seed, episode))?;
    let mut rng = ChaCha8Rng::seed_from_u64(episode_seed(seed ^ 0x0005_EED0_FAC7, 1, episode));
    let mut driver = Driver::new(ctrl, &env)?;
    let mut obs = ObsBatch::default();
    while !env.is_done() {
        on_step(&env);
        driver.step(&mut env, &mut obs, &mut rng, &mut on_actions)?;
    }
    on_step(&env);
    Ok(*env.metrics())
}

/// Where an episode's time went, single-threaded: deciding (observation, network, planner,
/// filter: everything a robot computes) against stepping the physics.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EpisodeTiming {
    pub decide_secs: f64,
    pub physics_secs: f64,
    /// Robot-steps decided (robots x steps).
    pub robot_decisions: u64,
}

impl EpisodeTiming {
    /// Mean decision time per robot per step, microseconds.
    pub fn us_per_decision(&self) -> f64 {
        1e6 * self.decide_secs / self.robot_decisions.max(1) as f64
    }
}

/// [`run_episode`] with its time split into deciding and physics (docs/bench/scale.md).
pub fn run_episode_timed(
    ctrl: &Method,
    cfg: &ScenarioConfig,
    setup: Setup,
    seed: u64,
    episode: u64,
) -> Result<(Metrics, EpisodeTiming), TrainError> {
    let mut env = Env::new(cfg.clone(), setup, eval_env_seed(seed, episode))?;
    let mut rng = ChaCha8Rng::seed_from_u64(episode_seed(seed ^ 0x0005_EED0_FAC7, 1, episode));
    let mut driver = Driver::new(ctrl, &env)?;
    let mut obs = ObsBatch::default();
    let mut t = EpisodeTiming::default();
    while !env.is_done() {
        let start = std::time::Instant::now();
        let physics_before = driver.physics;
        t.robot_decisions += env.n_robots() as u64;
        driver.step(&mut env, &mut obs, &mut rng, &mut |_, _| {})?;
        let physics = (driver.physics - physics_before).as_secs_f64();
        t.physics_secs += physics;
        t.decide_secs += start.elapsed().as_secs_f64() - physics;
    }
    Ok((*env.metrics(), t))
}

/// A learned actor's state during an episode.
struct ActorRun {
    actor: Actor,
    sample: bool,
    /// GRU states, rows x hidden.
    h: Vec<f32>,
    masks: Vec<f32>,
    /// Scratch: one row's logits behind the shield.
    shielded: Vec<f32>,
}

/// Who decides what the pilots drive to.
enum Decider {
    Actor(Box<ActorRun>),
    /// Always this action (matching-ORCA's "matched" entry).
    Entry(u8),
}

/// A controller's per-episode state, and the time its physics steps took.
struct Driver {
    kind: DriverKind,
    physics: std::time::Duration,
}

/// One step's commands: discrete actions or velocities.
enum Command {
    Actions(Vec<u8>),
    Velocities(Vec<[f32; 2]>),
}

/// What a controller steps the environment with.
enum DriverKind {
    Random,
    Greedy(GreedyParams),
    GreedyOrca(GreedyOrcaFleet),
    Piloted {
        decider: Decider,
        pilots: Vec<Pilot>,
    },
}

impl Driver {
    fn new(ctrl: &Method, env: &Env) -> Result<Self, TrainError> {
        let fleet = fleet_params(env.sizes(), env.config());
        let n = env.n_robots();
        let pilots = |outputs, safety| -> Result<Vec<Pilot>, TrainError> {
            let one = Pilot::new(&fleet, outputs, safety).map_err(TrainError::Config)?;
            Ok(vec![one; n])
        };
        let kind = match ctrl {
            Method::Random => DriverKind::Random,
            Method::Greedy => DriverKind::Greedy(fleet.greedy_params()),
            Method::GreedyOrca {
                clearance,
                obstacle_horizon,
            } => DriverKind::GreedyOrca(GreedyOrcaFleet::with_margins(
                env,
                *clearance,
                *obstacle_horizon,
            )?),
            Method::MatchingOrca { margins } => DriverKind::Piloted {
                decider: Decider::Entry(MatchingOrca::ENTRY as u8),
                pilots: pilots(Outputs::Targets, Safety::filtered(*margins))?,
            },
            Method::Learned {
                actor,
                sample,
                safety,
            } => DriverKind::Piloted {
                pilots: pilots(actor.arch.actions.outputs(), *safety)?,
                decider: Decider::Actor(Box::new(ActorRun {
                    h: vec![0.0; n * actor.hidden()],
                    masks: vec![1.0; n],
                    shielded: Vec::with_capacity(actor.arch.n_actions),
                    actor: actor.as_ref().clone(),
                    sample: *sample,
                })),
            },
        };
        Ok(Self {
            kind,
            physics: std::time::Duration::ZERO,
        })
    }

    /// One control step of `env`.
    fn step(
        &mut self,
        env: &mut Env,
        obs: &mut ObsBatch,
        rng: &mut ChaCha8Rng,
        on_actions: &mut impl FnMut(&ObsBatch, &[u8]),
    ) -> Result<(), TrainError> {
        let n = env.n_robots();
        // Each arm decides and returns what the physics steps with, so that the physics
        // step is timed apart from the decision (run_episode_timed).
        let cmd = match &mut self.kind {
            DriverKind::Random => {
                let actions: Vec<u8> = (0..n).map(|_| random_action(rng)).collect();
                on_actions(obs, &actions);
                Command::Actions(actions)
            }
            DriverKind::Greedy(params) => {
                env.observe(obs);
                let actions: Vec<u8> = (0..n)
                    .map(|r| {
                        let row = Row::of(obs, r);
                        greedy_action(row.own, row.machines, row.storages, row.peers, params)
                    })
                    .collect();
                on_actions(obs, &actions);
                Command::Actions(actions)
            }
            DriverKind::GreedyOrca(fleet) => {
                env.observe(obs);
                let mut vels = Vec::with_capacity(n);
                fleet.act(obs, &mut vels)?;
                Command::Velocities(vels)
            }
            DriverKind::Piloted { decider, pilots } => {
                env.observe(obs);
                let actions = match decider {
                    Decider::Entry(a) => vec![*a; n],
                    Decider::Actor(run) => run.decide(obs, pilots, rng)?,
                };
                on_actions(obs, &actions);
                let mut vels = Vec::with_capacity(n);
                pilot::commands(pilots, obs, &actions, &mut vels);
                Command::Velocities(vels)
            }
        };
        let start = std::time::Instant::now();
        match cmd {
            Command::Actions(a) => env.step_actions(&a)?,
            Command::Velocities(v) => env.step_velocities(&v)?,
        }
        self.physics += start.elapsed();
        Ok(())
    }
}

impl ActorRun {
    /// Every robot's action on `obs`: the actor's logits, masked by each robot's shield
    /// when its pilot has one, then argmax or a sample (one draw per row, in row order).
    fn decide(
        &mut self,
        obs: &ObsBatch,
        pilots: &[Pilot],
        rng: &mut ChaCha8Rng,
    ) -> Result<Vec<u8>, TrainError> {
        let k = self.actor.arch.n_actions;
        let logits = self.actor.forward_step(obs, &mut self.h, &self.masks)?;
        let mut actions = Vec::with_capacity(obs.rows);
        for (r, pilot) in pilots.iter().enumerate() {
            let choice = if self.sample {
                Choice::Sample(rng.gen::<f32>())
            } else {
                Choice::Argmax
            };
            let lg = &logits[r * k..(r + 1) * k];
            actions.push(policy::choose(
                pilot,
                Row::of(obs, r),
                lg,
                choice,
                &mut self.shielded,
            ));
        }
        Ok(actions)
    }
}

/// Episodes `0..episodes` of `setup` under `seed`, in parallel; results in episode order
/// (identical whatever the thread count).
pub fn evaluate(
    ctrl: &Method,
    cfg: &ScenarioConfig,
    setup: Setup,
    seed: u64,
    episodes: u64,
) -> Result<Vec<Metrics>, TrainError> {
    (0..episodes)
        .into_par_iter()
        .map(|ep| run_episode(ctrl, cfg, setup, seed, ep))
        .collect()
}
