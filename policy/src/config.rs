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
            flat: Some(flat.into()),
            max_robots: Some(max_robots),
        }
    }
}
