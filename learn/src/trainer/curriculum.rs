//! Curriculum stages: `6.4_2:2000,12.8_4:100` (setup:episodes, comma separated).

use super::TrainError;
use sim::Setup;

/// One curriculum stage: train on `setup` for `episodes` episodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stage {
    pub setup: Setup,
    pub episodes: u64,
}

/// Parse `6.4_2:2000,12.8_4:100` (setup:episodes, comma separated).
pub fn parse_curriculum(s: &str) -> Result<Vec<Stage>, TrainError> {
    let bad = |m: String| TrainError::Config(format!("curriculum `{s}`: {m}"));
    let mut out = vec![];
    for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (name, eps) = part
            .split_once(':')
            .ok_or_else(|| bad(format!("`{part}` is not setup:episodes")))?;
        let setup: Setup = name.parse()?;
        let episodes: u64 = eps
            .trim()
            .parse()
            .map_err(|_| bad(format!("`{eps}` is not an episode count")))?;
        if episodes == 0 {
            return Err(bad(format!("stage {name} has 0 episodes")));
        }
        out.push(Stage { setup, episodes });
    }
    if out.is_empty() {
        return Err(bad("no stage".into()));
    }
    Ok(out)
}

pub fn format_curriculum(stages: &[Stage]) -> String {
    stages
        .iter()
        .map(|s| format!("{}:{}", s.setup, s.episodes))
        .collect::<Vec<_>>()
        .join(",")
}
