//! `learn`: PPO training (MAPPO recipe) and the episode runner evaluation uses, on the
//! simulator; the networks are `policy`'s, the layers `nn`'s.
//!
//! - [`TrainConfig`]: every hyper-parameter, TOML-loadable, MAPPO defaults;
//! - [`Trainer`]: rollouts on [`sim::VecEnv`], GAE, value normalisation, recurrent PPO,
//!   curriculum stages or randomized setups ([`SetupRange`]), checkpoints with exact
//!   resume;
//! - [`eval`]: evaluation episodes of a learned actor or a scripted baseline;
//! - [`baselines`]: the planner's parameters from an environment, greedy-ORCA for a whole
//!   environment, random actions.

pub mod baselines;
pub mod config;
pub mod error;
pub mod eval;
pub mod gae;
pub mod randomize;
pub mod trainer;
pub mod valuenorm;

pub use config::TrainConfig;
pub use eval::{
    evaluate, run_episode, run_episode_timed, run_episode_watched, EpisodeTiming, Method,
};
pub use randomize::SetupRange;
pub use trainer::{format_curriculum, parse_curriculum, Stage, TrainError, Trainer, UpdateStats};
pub use valuenorm::ValueNorm;

#[cfg(test)]
mod tests;
