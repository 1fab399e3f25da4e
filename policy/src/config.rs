//! Architecture configuration stored in checkpoints.

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ModelKind {
    Smappo,
    Mappo,
}

impl std::fmt::Display for ModelKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            ModelKind::Smappo => "smappo",
            ModelKind::Mappo => "mappo",
        })
    }
}

/// Serializable mirror of [`obs::FlatLayout`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct FlatLayoutConfig {
    pub max_machines: usize,
    pub max_storages: usize,
    pub max_peers: usize,
}

impl From<FlatLayoutConfig> for obs::FlatLayout {
    fn from(c: FlatLayoutConfig) -> Self {
        obs::FlatLayout {
            max_machines: c.max_machines,
            max_storages: c.max_storages,
            max_peers: c.max_peers,
        }
    }
}

impl From<obs::FlatLayout> for FlatLayoutConfig {
    fn from(c: obs::FlatLayout) -> Self {
        Self {
            max_machines: c.max_machines,
            max_storages: c.max_storages,
            max_peers: c.max_peers,
        }
    }
}

/// What the actor's outputs mean (`obs::action`, `plan::targets`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ActionSpace {
    /// Velocity moves of `obs::action::MOVES`: the paper's 5 axis moves, or 9 with the
    /// diagonals. Checkpoints from before this field are moves.
    #[default]
    Moves,
    /// `plan::targets`: which box to drive to; the robot drives there straight.
    Targets,
}

impl ActionSpace {
    /// Whether `n` outputs make sense for this space.
    pub fn allows(self, n: usize) -> bool {
        match self {
            ActionSpace::Moves => {
                n == obs::action::N_AXIS_ACTIONS || n == obs::action::N_ACTIONS_WITH_DIAGONALS
            }
            ActionSpace::Targets => plan::targets::menu_size_ok(n),
        }
    }

    /// The same, as the pilot that turns an action into a velocity knows it.
    pub fn outputs(self) -> plan::Outputs {
        match self {
            ActionSpace::Moves => plan::Outputs::Moves,
            ActionSpace::Targets => plan::Outputs::Targets,
        }
    }
}

/// Dimensions of an actor/critic pair.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ArchConfig {
    pub kind: ModelKind,
    /// Entity embedding / attention width (SMAPPO).
    pub d_model: usize,
    /// Attention heads (SMAPPO).
    pub heads: usize,
    /// MLP / GRU width.
    pub hidden: usize,
    pub n_actions: usize,
    /// What the `n_actions` outputs mean.
    #[serde(default)]
    pub actions: ActionSpace,
    /// MAPPO: padded observation layout (required for MAPPO, absent for SMAPPO).
    pub flat: Option<FlatLayoutConfig>,
    /// MAPPO critic: robots per environment the centralized input is padded to.
    pub max_robots: Option<usize>,
}

impl ArchConfig {
    /// The paper's SMAPPO: d 64, 4 heads, GRU 64, 5 actions.
    pub fn smappo() -> Self {
        Self {
            kind: ModelKind::Smappo,
            d_model: 64,
            heads: 4,
            hidden: 64,
            n_actions: 5,
            actions: ActionSpace::Moves,
            flat: None,
            max_robots: None,
        }
    }

    /// MAPPO baseline with MAPPO's defaults (hidden 64).
    pub fn mappo(flat: obs::FlatLayout, max_robots: usize) -> Self {
        Self {
            kind: ModelKind::Mappo,
            d_model: 64,
            heads: 4,
            hidden: 64,
            n_actions: 5,
            actions: ActionSpace::Moves,
            flat: Some(flat.into()),
            max_robots: Some(max_robots),
        }
    }
}
