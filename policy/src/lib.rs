//! `policy`: SMAPPO and MAPPO networks with hand-written forward/backward passes,
//! on-robot inference and safetensors checkpoints.
//!
//! - [`nn`]: layers (Linear, LayerNorm, Tanh, ReLU, one-query multi-head attention, GRU,
//!   categorical head, Adam, gradient clipping) over a flat [`nn::ParamStore`];
//! - [`Actor`] / [`Critic`]: training networks (chunk forward/backward, PPO losses over
//!   [`Sequences`], rollout steps);
//! - [`Policy`]: what `robot_node` loads; [`checkpoint`]: safetensors files.

pub mod actor;
pub mod checkpoint;
pub mod config;
pub mod critic;
pub mod encoder;
pub mod error;
pub mod factored_input;
pub mod head;
pub mod inference;
pub mod mlp_base;
pub mod nn;
pub mod sequences;
#[cfg(feature = "train")]
pub mod train;

pub use actor::{Actor, ActorLossStats, PpoActorConfig};
pub use checkpoint::{CheckpointError, CheckpointMeta};
pub use config::{ActionSpace, ArchConfig, FlatLayoutConfig, ModelKind};
pub use critic::{Critic, ValueLossConfig, ValueLossStats};
pub use error::PolicyError;
pub use inference::{ActMode, Policy, PolicyState};
pub use sequences::Sequences;

#[cfg(test)]
mod net_tests;
