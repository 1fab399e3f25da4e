//! The scenario flags every command that runs the simulator shares (`tending sim`, `eval`,
//! `train`, `bound`, `fleet`): the TOML file, and the two settings a scale study changes
//! most, the floor and the observation bound, as flags over the file's values. Behind the
//! `clap` feature: the simulator itself needs no command line.

use crate::{Floor, ScenarioConfig, SimError};
use std::path::PathBuf;

#[derive(clap::Args, Debug, Clone, Default)]
pub struct ScenarioArgs {
    /// Scenario config (TOML); default: the simulator's defaults (sim/src/config.rs).
    #[arg(long, alias = "config")]
    pub scenario: Option<PathBuf>,
    /// The floor: `paper` (one room of world.room_size for every setup; bodies shrink as
    /// counts grow) or `grown` (the room grows with the fleet at 6.4_2's density, bodies
    /// keep their size; docs/adr/0037). Overrides the scenario's world.floor.
    #[arg(long, value_enum)]
    pub floor: Option<FloorArg>,
    /// Each robot observes only the K nearest machines, storages and other robots
    /// (overrides the scenario's [observation]; default: everything, the paper's).
    #[arg(long, value_name = "K")]
    pub nearest: Option<usize>,
}

#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum FloorArg {
    Paper,
    Grown,
}

impl ScenarioArgs {
    /// The scenario file (or the defaults) with the flags applied.
    pub fn load(&self) -> Result<ScenarioConfig, SimError> {
        let mut cfg = match &self.scenario {
            Some(p) => ScenarioConfig::load(p)?,
            None => ScenarioConfig::default(),
        };
        if let Some(f) = self.floor {
            cfg.world.floor = match f {
                FloorArg::Paper => Floor::Paper,
                FloorArg::Grown => Floor::Grown,
            };
        }
        if let Some(k) = self.nearest {
            if k < 1 {
                return Err(SimError::BadConfig {
                    field: "--nearest".into(),
                    reason: format!("must be at least 1, got {k}"),
                });
            }
            cfg.observation = obs::Bound::nearest(k);
        }
        cfg.validate()?;
        Ok(cfg)
    }
}
