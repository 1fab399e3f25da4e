//! A method's safety margins as a named TOML file (`configs/margins/*.toml`), read by
//! `tending eval`, `tending sim` and `tending fleet` (`--margins FILE`; the fleet hands the
//! filter's margins to every robot_node in its parameters file). One file holds both the
//! ORCA filter's margins (behind a learned policy, and in matching-ORCA) and greedy-ORCA's
//! own, so the setting behind a results row is a file rather than a set of flags.
//!
//! ```toml
//! [filter]            # behind a learned policy and in matching-ORCA
//! clearance = 0.04        # peer clearance at full speed, m
//! rest_clearance = 0.03   # at rest, m (the smaller of the two is used)
//! obstacle_horizon = 0.15 # boxes and walls, s
//! [greedy_orca]       # greedy-ORCA's own
//! clearance = 0.025
//! obstacle_horizon = 0.3
//! ```
//! A key left out keeps its deployed value; an unknown key is an error.

use std::path::Path;

use serde::Deserialize;

use crate::orca::{GREEDY_ORCA_CLEARANCE, OBSTACLE_HORIZON};
use crate::pilot::FilterMargins;

/// Everything a margins file sets.
#[derive(Debug, Clone, Copy, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Margins {
    /// The ORCA filter behind a learned policy and in matching-ORCA.
    pub filter: FilterMargins,
    /// greedy-ORCA's own.
    pub greedy_orca: ScriptMargins,
}

/// greedy-ORCA's margins: peer clearance, m, and horizon for boxes and walls, s.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ScriptMargins {
    pub clearance: f32,
    pub obstacle_horizon: f32,
}

impl Default for ScriptMargins {
    fn default() -> Self {
        Self {
            clearance: GREEDY_ORCA_CLEARANCE,
            obstacle_horizon: OBSTACLE_HORIZON,
        }
    }
}

impl ScriptMargins {
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }
}

impl Margins {
    /// Parse and check margins-file text; errors name `source` and the key.
    pub fn from_toml(text: &str, source: &str) -> Result<Self, String> {
        let m: Margins = toml::from_str(text).map_err(|e| format!("{source}: {e}"))?;
        m.check().map_err(|e| format!("{source}: {e}"))?;
        Ok(m)
    }

    /// The margins file at `path`; errors name it and say whether it is missing,
    /// unreadable or malformed (crate `inputs`).
    pub fn load(path: &Path) -> Result<Self, inputs::InputError> {
        inputs::parse_text("margins file", path, |text| {
            let m: Margins = toml::from_str(text).map_err(|e| e.to_string())?;
            m.check().map(|()| m)
        })
    }

    fn check(&self) -> Result<(), String> {
        let f = &self.filter;
        let g = &self.greedy_orca;
        for (key, v, unit) in [
            ("filter.clearance", f.clearance, "metres"),
            ("filter.rest_clearance", f.rest_clearance, "metres"),
            ("filter.obstacle_horizon", f.obstacle_horizon, "seconds"),
            ("greedy_orca.clearance", g.clearance, "metres"),
            (
                "greedy_orca.obstacle_horizon",
                g.obstacle_horizon,
                "seconds",
            ),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{key} = {v}: must be a positive number of {unit}"));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn configs() -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/margins")
    }

    #[test]
    fn the_deployed_file_is_the_built_in_default() {
        let m = Margins::load(&configs().join("deployed.toml")).unwrap();
        assert_eq!(m, Margins::default());
        assert_eq!(m.filter, FilterMargins::DEPLOYED);
    }

    #[test]
    fn every_shipped_file_loads() {
        let mut n = 0;
        for e in std::fs::read_dir(configs()).unwrap() {
            let p = e.unwrap().path();
            Margins::load(&p).unwrap_or_else(|e| panic!("{e}"));
            n += 1;
        }
        assert!(n >= 2, "{n} files");
    }

    #[test]
    fn a_missing_key_keeps_its_default_and_bad_ones_are_named() {
        let m = Margins::from_toml("[filter]\nobstacle_horizon = 0.3\n", "x.toml").unwrap();
        assert_eq!(m.filter.obstacle_horizon, 0.3);
        assert_eq!(m.filter.clearance, FilterMargins::DEPLOYED.clearance);
        assert!(m.greedy_orca.is_default());
        let e = Margins::from_toml("[filter]\nclearance = -1.0\n", "x.toml").unwrap_err();
        assert!(
            e.contains("x.toml") && e.contains("filter.clearance"),
            "{e}"
        );
        let e = Margins::from_toml("[filter]\nclearence = 0.1\n", "x.toml").unwrap_err();
        assert!(e.contains("x.toml") && e.contains("clearence"), "{e}");
        let e = Margins::from_toml("[greedy_orca]\nobstacle_horizon = nan\n", "y").unwrap_err();
        assert!(e.contains("greedy_orca.obstacle_horizon"), "{e}");
    }
}
