//! The paper's three metrics (section IV-E), kept correct while bodies come and go.

use serde::{Deserialize, Serialize};

/// Collisions are counted per robot per step: a robot touching k bodies in a step adds k
/// (so a robot-robot contact adds 2, one for each robot: "cumulative collisions across all
/// agents").
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Parts placed at a storage area.
    pub parts_delivered: u32,
    /// Parts picked from machines (P_c).
    pub parts_collected: u32,
    pub collisions: u32,
    pub collisions_robot_robot: u32,
    pub collisions_robot_machine: u32,
    pub collisions_robot_storage: u32,
    pub collisions_robot_wall: u32,
    /// Collision events: steps on which a robot went from touching nothing to touching
    /// something (summed over robots). A push held for 30 steps is 30 contact steps but
    /// one event. Absent in records written before it existed (read as 0).
    #[serde(default)]
    pub collision_events: u32,
    /// P_max: parts all machines could have made had they never waited, summed over each
    /// machine's lifetime in the episode: ceil(alive_steps / prep_steps).
    pub p_max: u32,
    /// Sum of all robots' rewards so far.
    pub total_reward: f64,
    pub steps: u32,
}

impl Metrics {
    /// Machine utilization MU = P_c / P_max (0 when no machine has existed).
    pub fn utilization(&self) -> f64 {
        if self.p_max == 0 {
            0.0
        } else {
            self.parts_collected as f64 / self.p_max as f64
        }
    }
}
