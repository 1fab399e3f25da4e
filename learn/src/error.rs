//! What training and evaluation can fail with.

use policy::{CheckpointError, PolicyError};

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
