//! Evaluation episodes: a learned actor or a scripted baseline through one code path.

use super::trainer::TrainError;
use crate::nn::categorical;
use crate::Actor;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use sim::baselines::{
    greedy_action, greedy_params, random_action, shield_logits, shield_params, GreedyOrcaFleet,
};
use sim::{action_to_velocity, episode_seed, Env, Metrics, ScenarioConfig, Setup};

/// Who picks the actions.
#[derive(Debug, Clone)]
pub enum Controller {
    /// A trained actor; argmax actions unless `sample`.
    Learned {
        actor: Box<Actor>,
        sample: bool,
    },
    /// The learned actor behind the one-step action shield (`obs::shield`).
    Shielded {
        actor: Box<Actor>,
        sample: bool,
    },
    /// The learned actor's action, as a velocity, through ORCA as a safety filter
    /// (`obs::orca::GreedyOrca::filter`): continuous velocities.
    Filtered {
        actor: Box<Actor>,
        sample: bool,
        /// ORCA peer clearance at full speed, m (`obs::orca::FILTER_CLEARANCE` by default).
        clearance: f32,
        /// ORCA peer clearance at rest, m, at most `clearance`
        /// (`obs::orca::FILTER_REST_CLEARANCE` by default).
        rest_clearance: f32,
        /// ORCA horizon for boxes and walls, s (`obs::orca::FILTER_OBSTACLE_HORIZON` by
        /// default).
        obstacle_horizon: f32,
    },
    Greedy,
    /// Greedy task allocation + ORCA avoidance (`obs::orca`), continuous velocities.
    GreedyOrca {
        /// Peer clearance, m (`obs::orca::GREEDY_ORCA_CLEARANCE` by default).
        clearance: f32,
        /// Horizon for boxes and walls, s (`obs::orca::OBSTACLE_HORIZON` by default).
        obstacle_horizon: f32,
    },
    Random,
}

impl Controller {
    /// Greedy-ORCA at its own clearance and obstacle horizon
    /// (`obs::orca::GREEDY_ORCA_CLEARANCE`, `obs::orca::OBSTACLE_HORIZON`).
    pub fn greedy_orca() -> Self {
        Controller::GreedyOrca {
            clearance: obs::orca::GREEDY_ORCA_CLEARANCE,
            obstacle_horizon: obs::orca::OBSTACLE_HORIZON,
        }
    }

    /// What the analysis examples (`menu_use`, `contact_sites`, `machine_waits`) take as
    /// their first argument: "greedy-orca" for the script, else a checkpoint's actor behind
    /// the ORCA filter as deployed ([`Self::filtered`], argmax).
    pub fn script_or_filtered_checkpoint(
        arg: &str,
    ) -> Result<Self, crate::checkpoint::CheckpointError> {
        if arg == "greedy-orca" {
            return Ok(Self::greedy_orca());
        }
        let pol = crate::Policy::load(arg)?;
        Ok(Self::filtered(Box::new(pol.actor().clone()), false))
    }

    /// `actor` behind the ORCA filter as it is deployed (`obs::orca::FILTER_CLEARANCE`,
    /// `obs::orca::FILTER_REST_CLEARANCE`, `obs::orca::FILTER_OBSTACLE_HORIZON`).
    pub fn filtered(actor: Box<Actor>, sample: bool) -> Self {
        Controller::Filtered {
            actor,
            sample,
            clearance: obs::orca::FILTER_CLEARANCE,
            rest_clearance: obs::orca::FILTER_REST_CLEARANCE,
            obstacle_horizon: obs::orca::FILTER_OBSTACLE_HORIZON,
        }
    }
}

/// Environment seed of evaluation episode `episode` under `seed`.
pub fn eval_env_seed(seed: u64, episode: u64) -> u64 {
    episode_seed(seed, 0, episode)
}

/// One episode of `setup`, deterministic in (seed, episode).
pub fn run_episode(
    ctrl: &Controller,
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
    ctrl: &Controller,
    cfg: &ScenarioConfig,
    setup: Setup,
    seed: u64,
    episode: u64,
    on_step: impl FnMut(&Env),
) -> Result<Metrics, TrainError> {
    run_episode_hooked(ctrl, cfg, setup, seed, episode, on_step, |_, _| {})
}

/// [`run_episode_watched`], also showing `on_actions` each step's observation and the
/// discrete actions chosen on it (greedy and learned controllers; the random controller
/// observes nothing, so its batch is empty; greedy-ORCA chooses no discrete action and
/// never calls it). `policy/examples/menu_use.rs` counts menu entries with it.
pub fn run_episode_hooked(
    ctrl: &Controller,
    cfg: &ScenarioConfig,
    setup: Setup,
    seed: u64,
    episode: u64,
    mut on_step: impl FnMut(&Env),
    mut on_actions: impl FnMut(&obs::ObsBatch, &[u8]),
) -> Result<Metrics, TrainError> {
    let mut env = Env::new(cfg.clone(), setup, eval_env_seed(seed, episode))?;
    let mut rng = ChaCha8Rng::seed_from_u64(episode_seed(seed ^ 0x0005_EED0_FAC7, 1, episode));
    let n = env.n_robots();
    let params = greedy_params(env.sizes(), cfg);
    let mut actor = match ctrl {
        Controller::Learned { actor, .. }
        | Controller::Shielded { actor, .. }
        | Controller::Filtered { actor, .. } => Some(actor.as_ref().clone()),
        _ => None,
    };
    let shield = shield_params(env.sizes(), cfg);
    // Target actions (`obs::targets`) are velocities only through the planner.
    let targets = actor
        .as_ref()
        .is_some_and(|a| a.arch.actions == crate::ActionSpace::Targets);
    if targets && matches!(ctrl, Controller::Shielded { .. }) {
        return Err(TrainError::Config(
            "the action shield acts on velocity moves; this policy has target actions".into(),
        ));
    }
    let mut orca = match ctrl {
        Controller::GreedyOrca {
            clearance,
            obstacle_horizon,
        } => Some(GreedyOrcaFleet::with_margins(
            &env,
            *clearance,
            *obstacle_horizon,
        )?),
        Controller::Filtered {
            clearance,
            rest_clearance,
            obstacle_horizon,
            ..
        } => Some(GreedyOrcaFleet::new_filter_with(
            &env,
            *clearance,
            *rest_clearance,
            *obstacle_horizon,
        )?),
        // Without the filter a target policy still plans with the policy's parameters.
        Controller::Learned { .. } if targets => Some(GreedyOrcaFleet::new_filter(&env, None)?),
        _ => None,
    };
    let mut vels = Vec::with_capacity(n);
    let mut shielded = Vec::new();
    let mut prefs = Vec::with_capacity(n);
    let hidden = actor.as_ref().map(|a| a.hidden()).unwrap_or(0);
    let mut h = vec![0.0f32; n * hidden];
    let masks = vec![1.0f32; n];
    let mut obs = obs::ObsBatch::default();
    let mut actions = vec![0u8; n];
    while !env.is_done() {
        on_step(&env);
        match ctrl {
            Controller::Random => {
                for a in actions.iter_mut() {
                    *a = random_action(&mut rng);
                }
            }
            Controller::Greedy => {
                env.observe(&mut obs);
                for (r, a) in actions.iter_mut().enumerate() {
                    *a = greedy_action(
                        obs.own_row(r),
                        obs.machines_row(r),
                        obs.storages_row(r),
                        obs.peers_row(r),
                        &params,
                    );
                }
            }
            Controller::GreedyOrca { .. } => {
                env.observe(&mut obs);
                let orca = orca.as_mut().expect("greedy-orca controller has its fleet");
                orca.act(&obs, &mut vels)?;
                env.step_velocities(&vels)?;
                continue;
            }
            Controller::Learned { sample, .. }
            | Controller::Shielded { sample, .. }
            | Controller::Filtered { sample, .. } => {
                env.observe(&mut obs);
                let actor = actor.as_mut().expect("learned controller has an actor");
                let k = actor.arch.n_actions;
                let mut logits = actor.forward_step(&obs, &mut h, &masks)?;
                if matches!(ctrl, Controller::Shielded { .. }) {
                    shielded.clear();
                    shielded.extend_from_slice(logits);
                    shield_logits(&obs, &mut shielded, &shield);
                    logits = &shielded;
                }
                for (r, a) in actions.iter_mut().enumerate() {
                    let lg = &logits[r * k..(r + 1) * k];
                    *a = if *sample {
                        categorical::sample(lg, rng.gen::<f32>())
                    } else {
                        categorical::argmax(lg)
                    } as u8;
                }
            }
        }
        on_actions(&obs, &actions);
        if let Some(orca) = orca.as_mut().filter(|_| targets) {
            orca.target_velocities(&obs, &actions, &mut prefs)?;
            if matches!(ctrl, Controller::Filtered { .. }) {
                orca.filter(&obs, &prefs, &mut vels)?;
                env.step_velocities(&vels)?;
            } else {
                env.step_velocities(&prefs)?;
            }
            continue;
        }
        if let (Controller::Filtered { .. }, Some(orca)) = (ctrl, orca.as_mut()) {
            let k = cfg.task.k_speed;
            prefs.clear();
            prefs.extend(
                actions
                    .iter()
                    .map(|&a| action_to_velocity(a, k).unwrap_or([0.0; 2])),
            );
            orca.filter(&obs, &prefs, &mut vels)?;
            env.step_velocities(&vels)?;
            continue;
        }
        env.step_actions(&actions)?;
    }
    on_step(&env);
    Ok(*env.metrics())
}

/// Episodes `0..episodes` of `setup` under `seed`, in parallel; results in episode order
/// (identical whatever the thread count).
pub fn evaluate(
    ctrl: &Controller,
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
