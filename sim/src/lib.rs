//! The tending simulator (paper sections III, IV-C, IV-D, IV-E).
//!
//! N robots (discs), M machines and K storage areas (static boxes) in a walled square room.
//! VMAS-style physics: forces, drag once per step, soft-plus contact forces, semi-implicit
//! Euler. The native input is a holonomic velocity command per robot; the paper's 5
//! discrete actions map onto it ([`action_to_velocity`]).
//!
//! - [`ScenarioConfig`]: every constant, from TOML.
//! - [`Setup`]: `N.M_K` names.
//! - [`Env`]: one environment: step, pick/place, rewards, metrics, live add/remove.
//! - [`VecEnv`]: many environments stepped together ([`fork`]: one run of envs per thread,
//!   the caller included), deterministic whatever the thread count.
//! - [`parts_bound`]: the most parts any controller can deliver from an episode's layout.

// Struct-of-arrays bodies are indexed in lockstep; iterator zips of 5+ arrays read worse.
#![allow(clippy::needless_range_loop)]

mod action;
#[cfg(feature = "clap")]
pub mod args;
mod bound;
mod config;
mod entities;
mod env;
mod error;
pub mod fork;
mod grid;
pub mod layout;
mod metrics;
mod setup;
mod vec_env;

pub use action::{action_to_velocity, N_ACTIONS};
pub use bound::{parts_bound, PartsBound};
pub use config::{
    Floor, PhysicsConfig, RewardConfig, ScenarioConfig, SizeConfig, TaskConfig, WorldConfig,
};
pub use entities::{MachineId, RobotId, Sizes, StorageId};
pub use env::{Env, MachineView, RobotEvents, RobotView, StorageView};
pub use error::SimError;
pub use metrics::Metrics;
pub use setup::Setup;
pub use vec_env::{episode_seed, VecEnv};
