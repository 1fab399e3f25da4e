//! `policy`: SMAPPO and MAPPO networks with hand-written forward/backward passes,
//! on-robot inference and safetensors checkpoints.

pub mod nn;
