//! The controller `tending sim` and `tending eval` run: a scripted baseline by name, or a
//! checkpoint with its safety-filter flags, and the label their tables show it under.

use anyhow::{bail, Context, Result};
use policy::train::Controller;
use policy::Policy;
use std::path::Path;

/// How a checkpoint runs: the flags both commands take.
pub struct CheckpointFlags {
    /// Sample actions instead of taking the most probable one.
    pub sample: bool,
    /// Behind the one-step action shield (obs::shield).
    pub shield: bool,
    /// Through ORCA as a safety filter (obs::orca).
    pub orca_filter: bool,
    /// Without the ORCA filter even when the checkpoint was trained behind it.
    pub no_orca_filter: bool,
    /// Peer clearance of the ORCA filter at full speed, m.
    pub clearance: f32,
    /// Peer clearance of the ORCA filter at rest, m (at most `clearance`).
    pub rest_clearance: f32,
    /// The ORCA filter's horizon for boxes and walls, s.
    pub obstacle_horizon: f32,
}

/// A clearance in whole millimetres, for method names.
pub fn mm(m: f32) -> i32 {
    (m * 1000.0).round() as i32
}

/// The scripted baseline `name` names: greedy | greedy-orca | random.
pub fn scripted(name: &str) -> Result<Controller> {
    Ok(match name {
        "greedy" => Controller::Greedy,
        "greedy-orca" => Controller::greedy_orca(),
        "random" => Controller::Random,
        o => bail!("unknown --policy `{o}`: expected greedy, greedy-orca or random"),
    })
}

/// The checkpoint at `path` as a controller, and its label: `smappo+orca (file)`. A
/// checkpoint trained behind the ORCA filter runs behind it (as it was trained and as
/// robot_node runs it) unless the shield or `no_orca_filter` says otherwise; a
/// target-action policy says so in its label (its rows must not read as the paper's
/// policy).
pub fn checkpoint(path: &Path, f: &CheckpointFlags) -> Result<(Controller, String)> {
    let pol = Policy::load(path).with_context(|| format!("--checkpoint {}", path.display()))?;
    let orca_filter =
        f.orca_filter || (pol.trained_with_orca_filter() && !f.shield && !f.no_orca_filter);
    let targets = pol.actor().arch.actions == policy::ActionSpace::Targets;
    // Margins other than the deployed ones are part of the method's name (sweeps).
    let rest = f.rest_clearance.min(f.clearance);
    let mut margin = if orca_filter
        && (f.clearance != obs::orca::FILTER_CLEARANCE
            || rest != obs::orca::FILTER_REST_CLEARANCE.min(f.clearance))
    {
        format!(" {}/{} mm", mm(rest), mm(f.clearance))
    } else {
        String::new()
    };
    if orca_filter && f.obstacle_horizon != obs::orca::FILTER_OBSTACLE_HORIZON {
        margin = format!(" obstacles {} s{margin}", f.obstacle_horizon);
    }
    let label = format!(
        "{}{}{}{margin} ({})",
        pol.kind(),
        if targets { " targets" } else { "" },
        if f.shield {
            "+shield"
        } else if orca_filter {
            "+orca"
        } else {
            ""
        },
        path.file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("checkpoint")
    );
    let actor = Box::new(pol.actor().clone());
    let sample = f.sample;
    let ctrl = if f.shield {
        Controller::Shielded { actor, sample }
    } else if orca_filter {
        Controller::Filtered {
            actor,
            sample,
            clearance: f.clearance,
            rest_clearance: f.rest_clearance,
            obstacle_horizon: f.obstacle_horizon,
        }
    } else {
        Controller::Learned { actor, sample }
    };
    Ok((ctrl, label))
}
