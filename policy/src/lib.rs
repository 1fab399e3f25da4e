//! `policy`: SMAPPO and MAPPO networks with hand-written forward/backward passes,
//! on-robot inference and safetensors checkpoints.
//!
//! The layers are crate `nn`'s; training and the episode runner are crate `learn`'s, above
//! this one, so a robot's binary carries neither the simulator nor the trainer.
//!
//! - [`Actor`] / [`Critic`]: training networks (chunk forward/backward, PPO losses over
//!   [`Sequences`], rollout steps);
//! - [`Policy`]: what `robot_node` loads; [`checkpoint`]: safetensors files.

pub mod actor;
pub mod checkpoint;
pub mod choice;
pub mod config;
pub mod controller;
pub mod critic;
pub mod encoder;
pub mod error;
mod factored_cache;
pub mod factored_input;
pub mod head;
pub mod inference;
pub mod mlp_base;
pub mod sequences;

pub use actor::{Actor, ActorLossStats, PpoActorConfig};
pub use checkpoint::{CheckpointError, CheckpointMeta};
pub use choice::{choose, Choice};
pub use config::{ActionSpace, ArchConfig, FlatLayoutConfig, ModelKind};
pub use critic::{Critic, ValueLossConfig, ValueLossStats};
pub use error::PolicyError;
pub use inference::{ActMode, Policy, PolicyState};
pub use sequences::Sequences;

#[cfg(test)]
mod net_tests;
