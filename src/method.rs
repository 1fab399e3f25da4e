//! The method `tending sim` and `tending eval` run (`learn::Method`): a scripted
//! method by name, or a checkpoint with its safety-layer flags, and the label their tables
//! show it under.

use anyhow::{bail, Context, Result};
use learn::Method;
use plan::{Deployment, FilterMargins, Margins, MethodName, Safety, ScriptMargins};
use policy::Policy;
use std::path::Path;

/// The scripted methods `--policy` names.
pub const SCRIPTS: &str = "greedy, greedy-orca, matching-orca or random";

/// How a checkpoint runs: the flags both commands take.
pub struct CheckpointFlags {
    /// Sample actions instead of taking the most probable one.
    pub sample: bool,
    /// Behind the one-step action shield (plan::shield).
    pub shield: bool,
    /// Through ORCA as a safety filter (plan::orca): `--orca-filter` Some(true),
    /// `--no-orca-filter` Some(false), neither None (as the checkpoint was trained).
    pub orca_filter: Option<bool>,
    /// The ORCA filter's margins.
    pub margins: FilterMargins,
}

/// A clearance in whole millimetres, for method names.
pub fn mm(m: f32) -> i32 {
    (m * 1000.0).round() as i32
}

/// Margins of the ORCA filter other than the deployed ones, as a method's name shows them
/// (sweeps): " obstacles 0.3 s", " 25/40 mm" (rest/full speed), or both in that order;
/// empty when deployed.
fn margin_label(m: &FilterMargins) -> String {
    let mut s = String::new();
    if m.obstacle_horizon != FilterMargins::DEPLOYED.obstacle_horizon {
        s = format!(" obstacles {} s", m.obstacle_horizon);
    }
    if !m.deployed_clearances() {
        let rest = m.rest_clearance.min(m.clearance);
        s += &format!(" {}/{} mm", mm(rest), mm(m.clearance));
    }
    s
}

/// greedy-ORCA's name with margins other than its defaults: "greedy-orca 30 mm" (a point
/// of the clearance sweep, which `tending plot pareto --sweep` joins by the "mm" ending),
/// "greedy-orca obstacles 0.15 s", or both.
fn script_label(m: &ScriptMargins) -> String {
    let mut s = String::from("greedy-orca");
    if m.obstacle_horizon != ScriptMargins::default().obstacle_horizon {
        s += &format!(" obstacles {} s", m.obstacle_horizon);
    }
    if m.clearance != ScriptMargins::default().clearance {
        s += &format!(" {} mm", mm(m.clearance));
    }
    s
}

/// The scripted method `name` names (greedy | greedy-orca | matching-orca | random), and
/// its label. matching-ORCA runs behind the ORCA filter with the filter's margins,
/// greedy-ORCA with its own (each named in the label when not the deployed ones); the
/// others have none.
pub fn scripted(name: &str, margins: &Margins) -> Result<(Method, String)> {
    let g = margins.greedy_orca;
    let method: MethodName = name.parse().map_err(|e| anyhow::anyhow!("--policy: {e}"))?;
    Ok(match method {
        MethodName::Greedy => (Method::Greedy, name.into()),
        MethodName::GreedyOrca if g.is_default() => (Method::greedy_orca(), name.into()),
        MethodName::GreedyOrca => (
            Method::GreedyOrca {
                clearance: g.clearance,
                obstacle_horizon: g.obstacle_horizon,
            },
            script_label(&g),
        ),
        MethodName::MatchingOrca => (
            Method::MatchingOrca {
                margins: margins.filter,
            },
            format!("{name}{}", margin_label(&margins.filter)),
        ),
        MethodName::Random => (Method::Random, name.into()),
        MethodName::Policy => bail!("--policy policy: give the checkpoint with --checkpoint"),
    })
}

/// The checkpoint at `path` as a controller, and its label: `smappo+orca (file)`. Its
/// safety layer follows [`Safety::choose`] offline: a checkpoint trained behind the ORCA
/// filter runs behind it (as it was trained and as robot_node runs it) unless the shield
/// or `--no-orca-filter` says otherwise; a target-action policy says so in its label (its
/// rows must not read as the paper's policy).
pub fn checkpoint(path: &Path, f: &CheckpointFlags) -> Result<(Method, String)> {
    // the loader's error names the file already ("checkpoint X: no such file")
    let pol = Policy::load(path).context("--checkpoint")?;
    let deployment = Deployment::Offline {
        trained_with_filter: pol.trained_with_orca_filter(),
    };
    let safety = Safety::choose(f.shield, f.orca_filter, deployment, f.margins);
    let targets = pol.actor().arch.actions == policy::ActionSpace::Targets;
    // Margins other than the deployed ones are part of the method's name (sweeps).
    let margin = safety.filter.map_or(String::new(), |m| margin_label(&m));
    let label = format!(
        "{}{}{}{margin} ({})",
        pol.kind(),
        if targets { " targets" } else { "" },
        if safety.shield {
            "+shield"
        } else if safety.filter.is_some() {
            "+orca"
        } else {
            ""
        },
        path.file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("checkpoint")
    );
    let ctrl = Method::Learned {
        actor: Box::new(pol.actor().clone()),
        sample: f.sample,
        safety,
    };
    Ok((ctrl, label))
}

/// How a controller picks its actions, for the results' header.
pub fn mode(ctrl: &Method) -> &'static str {
    match ctrl {
        Method::Learned { sample, safety, .. } => {
            match (*sample, safety.shield, safety.filter.is_some()) {
                (true, true, _) => "sampled shielded actions",
                (false, true, _) => "argmax shielded actions",
                (true, false, true) => "sampled actions through the ORCA filter",
                (false, false, true) => "argmax actions through the ORCA filter",
                (true, false, false) => "sampled actions",
                (false, false, false) => "argmax actions",
            }
        }
        _ => "scripted",
    }
}

/// `--margins FILE` (plan::margins), or the deployed margins without one.
pub fn margins(path: &Option<std::path::PathBuf>) -> Result<Margins> {
    match path {
        Some(p) => Margins::load(p).map_err(|e| anyhow::anyhow!("--margins: {e}")),
        None => Ok(Margins::default()),
    }
}
