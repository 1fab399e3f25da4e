//! Evaluation episodes: a learned actor or a scripted baseline through one code path.
//!
//! A learned actor drives through `plan`'s pilot (shield, target planner, ORCA filter as
//! its [`Safety`] says), the same one the trainer's rollouts and robot_node use;
//! matching-ORCA is that pilot always asking for the menu's "matched" entry.

use super::trainer::TrainError;
use crate::baselines::{fleet_params, random_action, GreedyOrcaFleet};
use nn::categorical;
use obs::ObsBatch;
use plan::greedy::{greedy_action, GreedyParams};
use plan::orca::{GREEDY_ORCA_CLEARANCE, OBSTACLE_HORIZON};
use plan::pilot::{self, FilterMargins, MatchingOrca, Outputs, Pilot, Row, Safety};
use policy::Actor;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use sim::{episode_seed, Env, Metrics, ScenarioConfig, Setup};

/// What an offline episode runs: a scripted method or a checkpoint, described, not yet
/// running (`run_episode` builds one stateful pilot or planner per robot from it). On the
/// robot, robot_node's `Controller` trait is the running counterpart, one per robot.
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

/// A controller's per-episode state: what it steps the environment with.
enum Driver {
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
        Ok(match ctrl {
            Method::Random => Driver::Random,
            Method::Greedy => Driver::Greedy(fleet.greedy_params()),
            Method::GreedyOrca {
                clearance,
                obstacle_horizon,
            } => Driver::GreedyOrca(GreedyOrcaFleet::with_margins(
                env,
                *clearance,
                *obstacle_horizon,
            )?),
            Method::MatchingOrca { margins } => Driver::Piloted {
                decider: Decider::Entry(MatchingOrca::ENTRY as u8),
                pilots: pilots(Outputs::Targets, Safety::filtered(*margins))?,
            },
            Method::Learned {
                actor,
                sample,
                safety,
            } => Driver::Piloted {
                pilots: pilots(actor.arch.actions.outputs(), *safety)?,
                decider: Decider::Actor(Box::new(ActorRun {
                    h: vec![0.0; n * actor.hidden()],
                    masks: vec![1.0; n],
                    shielded: Vec::with_capacity(actor.arch.n_actions),
                    actor: actor.as_ref().clone(),
                    sample: *sample,
                })),
            },
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
        match self {
            Driver::Random => {
                let actions: Vec<u8> = (0..n).map(|_| random_action(rng)).collect();
                on_actions(obs, &actions);
                env.step_actions(&actions)?;
            }
            Driver::Greedy(params) => {
                env.observe(obs);
                let actions: Vec<u8> = (0..n)
                    .map(|r| {
                        let row = Row::of(obs, r);
                        greedy_action(row.own, row.machines, row.storages, row.peers, params)
                    })
                    .collect();
                on_actions(obs, &actions);
                env.step_actions(&actions)?;
            }
            Driver::GreedyOrca(fleet) => {
                env.observe(obs);
                let mut vels = Vec::with_capacity(n);
                fleet.act(obs, &mut vels)?;
                env.step_velocities(&vels)?;
            }
            Driver::Piloted { decider, pilots } => {
                env.observe(obs);
                let actions = match decider {
                    Decider::Entry(a) => vec![*a; n],
                    Decider::Actor(run) => run.decide(obs, pilots, rng)?,
                };
                on_actions(obs, &actions);
                let mut vels = Vec::with_capacity(n);
                pilot::commands(pilots, obs, &actions, &mut vels);
                env.step_velocities(&vels)?;
            }
        }
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
            let mut lg = &logits[r * k..(r + 1) * k];
            if pilot.shielded() {
                self.shielded.clear();
                self.shielded.extend_from_slice(lg);
                pilot.shield_logits(Row::of(obs, r), &mut self.shielded);
                lg = &self.shielded;
            }
            actions.push(if self.sample {
                categorical::sample(lg, rng.gen::<f32>())
            } else {
                categorical::argmax(lg)
            } as u8);
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
