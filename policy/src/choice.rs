//! The step from a network's logits to a robot's action, written once for robot_node and
//! the episode runner: the pilot's shield masks the logits (when it has one), then the
//! most probable action or a sample. (The trainer's rollout keeps its own step: it also
//! records the shield's bias and the log-probabilities PPO needs.)

use plan::{Pilot, Row};

/// How an action is picked from the (shielded) logits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Choice {
    /// The most probable action (deployment, evaluation by default).
    Argmax,
    /// A sample, from this uniform draw in [0, 1).
    Sample(f32),
}

/// The action of `row` from its `logits`, behind `pilot`'s shield when it has one;
/// `scratch` holds the masked copy (no allocation once warm).
pub fn choose(
    pilot: &Pilot,
    row: Row,
    logits: &[f32],
    choice: Choice,
    scratch: &mut Vec<f32>,
) -> u8 {
    let lg = if pilot.shielded() {
        scratch.clear();
        scratch.extend_from_slice(logits);
        pilot.shield_logits(row, scratch);
        &scratch[..]
    } else {
        logits
    };
    (match choice {
        Choice::Argmax => nn::categorical::argmax(lg),
        Choice::Sample(u) => nn::categorical::sample(lg, u),
    }) as u8
}
