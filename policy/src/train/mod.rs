//! PPO training (MAPPO recipe) and evaluation; behind the `train` feature because it
//! needs the simulator.
//!
//! - [`TrainConfig`]: every hyper-parameter, TOML-loadable, MAPPO defaults;
//! - [`Trainer`]: rollouts on [`sim::VecEnv`], GAE, value normalisation, recurrent PPO,
//!   curriculum stages or randomized setups ([`SetupRange`]), checkpoints with exact
//!   resume;
//! - [`eval`]: evaluation episodes of a learned actor or a scripted baseline.

pub mod config;
pub mod eval;
pub mod gae;
pub mod randomize;
pub mod trainer;
pub mod valuenorm;

pub use config::TrainConfig;
pub use eval::{evaluate, run_episode, run_episode_watched, Method};
pub use randomize::SetupRange;
pub use trainer::{format_curriculum, parse_curriculum, Stage, TrainError, Trainer, UpdateStats};
pub use valuenorm::ValueNorm;

#[cfg(test)]
mod tests;
