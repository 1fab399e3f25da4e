//! The fleet's ROS 2 parameters file: one section per node, in the form `ros2 param dump`
//! writes and launch files pass (`--ros-args --params-file fleet.yaml`). Every child reads
//! its settings from it; only what differs per process (a robot's namespace or robot list)
//! and the user's `--robot-param` overrides stay on the command line (a `-p` after the
//! file wins, as in ROS 2).

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};

/// Section keys: the bridge by its full name, every robot_node in any namespace (a
/// single-robot process runs as `/robot_i/robot_node`, a multi-robot one as `/robot_node`).
pub(super) const BRIDGE_KEY: &str = "/sim_bridge";
pub(super) const ROBOT_KEY: &str = "/**/robot_node";

/// A parameter value, typed as ROS 2 types it.
pub(super) enum Scalar {
    Str(String),
    Int(i64),
    Double(f64),
    Bool(bool),
}

impl Scalar {
    /// The YAML text. Written here rather than by serde_yaml because serde_yaml leaves a
    /// string such as `6.4_2` unquoted, which YAML 1.1 readers (PyYAML, hence rclpy's
    /// parameter loader) take for the float 6.42: strings are always double-quoted (a JSON
    /// string is a valid YAML double-quoted scalar), doubles always carry a point.
    fn yaml(&self) -> String {
        match self {
            Scalar::Str(s) => serde_json::to_string(s).expect("a string serialises"),
            Scalar::Int(i) => i.to_string(),
            Scalar::Double(d) => format!("{d:?}"),
            Scalar::Bool(b) => b.to_string(),
        }
    }
}

impl From<&str> for Scalar {
    fn from(s: &str) -> Self {
        Scalar::Str(s.into())
    }
}
impl From<String> for Scalar {
    fn from(s: String) -> Self {
        Scalar::Str(s)
    }
}
impl From<bool> for Scalar {
    fn from(b: bool) -> Self {
        Scalar::Bool(b)
    }
}
impl From<f64> for Scalar {
    fn from(d: f64) -> Self {
        Scalar::Double(d)
    }
}
impl From<u32> for Scalar {
    fn from(i: u32) -> Self {
        Scalar::Int(i.into())
    }
}
impl From<u64> for Scalar {
    fn from(i: u64) -> Self {
        // every count the fleet passes (seed, steps) is far below i64::MAX; a larger
        // one is written as a double rather than wrapped
        i64::try_from(i).map_or(Scalar::Double(i as f64), Scalar::Int)
    }
}

/// One node's parameters, in insertion order.
#[derive(Default)]
pub(super) struct Section(Vec<(String, Scalar)>);

impl Section {
    pub(super) fn set(&mut self, name: &str, v: impl Into<Scalar>) -> &mut Self {
        self.0.push((name.into(), v.into()));
        self
    }

    /// An f32 setting, widened exactly: the node gets back the very f32 the fleet computed.
    pub(super) fn set_f32(&mut self, name: &str, v: f32) -> &mut Self {
        self.set(name, v as f64)
    }
}

/// The whole file's text: a header saying who wrote it, then the two sections.
pub(super) fn render(bridge: Section, robot: Section) -> String {
    let mut out = String::from(
        "# Written by `tending fleet`: every sim_bridge and robot_node of the run reads it\n\
         # (--ros-args --params-file); per-process names and --robot-param stay on the\n\
         # command line and override it.\n",
    );
    for (key, section) in [(BRIDGE_KEY, bridge), (ROBOT_KEY, robot)] {
        let _ = writeln!(out, "{key}:\n  ros__parameters:");
        for (name, v) in section.0 {
            let _ = writeln!(out, "    {name}: {}", v.yaml());
        }
    }
    out
}

pub(super) fn write(path: &Path, bridge: Section, robot: Section) -> Result<()> {
    std::fs::write(path, render(bridge, robot))
        .with_context(|| format!("writing {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use ros::args::{parse_params_yaml, ParamValue};

    fn sample() -> String {
        let mut b = Section::default();
        b.set("setup", "6.4_2")
            .set("seed", 3u64)
            .set("stdin_commands", true);
        b.set("rate_hz", 10.0);
        let mut r = Section::default();
        r.set_f32("k_speed", 0.05).set("lockstep", true);
        render(b, r)
    }

    #[test]
    fn each_node_reads_only_its_section_with_its_types() {
        let text = sample();
        let bridge = parse_params_yaml(&text, "/", "sim_bridge").unwrap();
        let names: Vec<_> = bridge.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(
            names,
            ["setup", "seed", "stdin_commands", "rate_hz"],
            "{text}"
        );
        // a setup name is a string even though YAML 1.1 reads 6.4_2 as a number
        assert!(
            matches!(&bridge[0].1, ParamValue::Str(s) if s == "6.4_2"),
            "{text}"
        );
        assert!(matches!(bridge[1].1, ParamValue::Int(3)));
        assert!(matches!(bridge[2].1, ParamValue::Bool(true)));
        for ns in ["/robot_3", "/"] {
            let robot = parse_params_yaml(&text, ns, "robot_node").unwrap();
            assert_eq!(robot.len(), 2, "{ns}: {robot:?}");
            match robot[0].1 {
                // the f32 comes back exactly
                ParamValue::Double(d) => assert_eq!(d as f32, 0.05f32),
                ref other => panic!("k_speed read as {other:?}"),
            }
        }
        assert!(parse_params_yaml(&text, "/", "other").unwrap().is_empty());
    }
}
