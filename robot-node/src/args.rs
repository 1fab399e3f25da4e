//! ROS 2 command-line conventions, parsed here because ros2-client parses none:
//!
//! ```text
//! robot_node [--ros-args [-r|--remap __ns:=/robot_3] [-r __node:=name]
//!                        [-p|--param name:=value]... [--params-file f.yaml]...
//!                        [--log-level LEVEL] [--enclave E]
//!                        [--enable-rosout-logs|--disable-rosout-logs|--disable-stdout-logs]
//!                        [--] ]
//! ```
//!
//! Parameter files use the ROS 2 YAML form `<node>: ros__parameters: {...}` where the key
//! may be the node name, its fully qualified name, or a pattern with `*` (one segment)
//! and `**` (any segments), e.g. `/**:`; nested namespace keys are joined with `/`.
//! Files apply in order, then `-p` overrides. `ROS_DOMAIN_ID` comes from the environment.

use std::path::PathBuf;

/// Default node name.
pub const DEFAULT_NODE_NAME: &str = "robot_node";

/// Everything the node is configured with.
#[derive(Debug, Clone, PartialEq)]
pub struct Params {
    /// Namespace with leading slash, e.g. `/robot_3` (this robot's identity).
    pub namespace: String,
    pub node_name: String,
    pub domain_id: u16,
    /// Checkpoint of the learned policy; `None` = scripted greedy controller.
    pub policy: Option<PathBuf>,
    /// `greedy` or `policy`; default: `policy` if a policy path is given, else `greedy`.
    pub controller: ControllerKind,
    pub control_rate_hz: f64,
    pub use_sim_time: bool,
    /// Speed of one discrete action, m/s.
    pub k_speed: f64,
    /// No sample from a robot (own or peer) for this long: stale.
    pub stale_timeout_s: f64,
    /// Staleness of machine and storage data (latched topics); <= 0 disables it.
    /// Default: `stale_timeout_s`.
    pub static_stale_timeout_s: f64,
    /// Accepted positions: |x|,|y| <= 1.15 + room_margin.
    pub room_margin: f64,
    /// Period of the counters log line.
    pub stats_period_s: f64,
    /// Period of topic discovery scans.
    pub discovery_period_s: f64,
    /// `--log-level`, if given (tracing filter directive).
    pub log_level: Option<String>,
    pub enable_rosout: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControllerKind {
    Greedy,
    Policy,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            namespace: "/".into(),
            node_name: DEFAULT_NODE_NAME.into(),
            domain_id: 0,
            policy: None,
            controller: ControllerKind::Greedy,
            control_rate_hz: 10.0,
            use_sim_time: false,
            k_speed: 0.5,
            stale_timeout_s: 1.0,
            static_stale_timeout_s: 1.0,
            room_margin: msgs::validate::DEFAULT_MARGIN,
            stats_period_s: 10.0,
            discovery_period_s: 0.5,
            log_level: None,
            enable_rosout: true,
        }
    }
}

impl Params {
    pub fn fully_qualified_name(&self) -> String {
        if self.namespace == "/" {
            format!("/{}", self.node_name)
        } else {
            format!("{}/{}", self.namespace, self.node_name)
        }
    }
    /// Robot identity used by the topic contract (`robot_3`).
    pub fn robot_id(&self) -> String {
        self.namespace.trim_matches('/').to_string()
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ArgError {
    #[error("argument `{arg}`: {msg}")]
    Bad { arg: String, msg: String },
    #[error("argument `{0}` needs a value")]
    MissingValue(String),
    #[error("unknown argument `{0}` (robot_node takes only ROS 2 arguments after --ros-args)")]
    Unknown(String),
    #[error("parameter `{name}`: {msg}")]
    Param { name: String, msg: String },
    #[error("params file `{path}`: {msg}")]
    ParamsFile { path: String, msg: String },
    #[error("environment variable ROS_DOMAIN_ID=`{0}`: expected an integer 0..=232")]
    DomainId(String),
    #[error("help requested")]
    Help,
}

pub const USAGE: &str = "usage: robot_node [--ros-args -r __ns:=/robot_N [-r __node:=NAME] \
[-p NAME:=VALUE]... [--params-file FILE.yaml]... [--log-level LEVEL]]
parameters: policy (path), controller (greedy|policy), control_rate_hz (10), use_sim_time (false),
            k_speed (0.5), stale_timeout_s (1.0), static_stale_timeout_s (= stale_timeout_s, <=0 off),
            room_margin (0.25), stats_period_s (10), discovery_period_s (0.5)
environment: ROS_DOMAIN_ID (0)";

/// A typed parameter value (YAML scalar).
#[derive(Debug, Clone, PartialEq)]
pub enum ParamValue {
    Bool(bool),
    Int(i64),
    Double(f64),
    Str(String),
    Other(String),
}

impl ParamValue {
    /// Parse a `-p` value as ROS does: YAML scalar typing.
    pub fn parse_cli(s: &str) -> Self {
        match serde_yaml::from_str::<serde_yaml::Value>(s) {
            Ok(v) => Self::from_yaml(&v),
            Err(_) => ParamValue::Str(s.to_string()),
        }
    }
    fn from_yaml(v: &serde_yaml::Value) -> Self {
        use serde_yaml::Value as Y;
        match v {
            Y::Bool(b) => ParamValue::Bool(*b),
            Y::Number(n) => {
                if let Some(i) = n.as_i64() {
                    ParamValue::Int(i)
                } else {
                    ParamValue::Double(n.as_f64().unwrap_or(f64::NAN))
                }
            }
            Y::String(s) => ParamValue::Str(s.clone()),
            Y::Null => ParamValue::Str(String::new()),
            other => ParamValue::Other(serde_yaml::to_string(other).unwrap_or_default()),
        }
    }
}

/// Parse the process arguments (without argv\[0\]) and `ROS_DOMAIN_ID`.
pub fn parse<I, S>(args: I, ros_domain_id: Option<&str>) -> Result<(Params, Vec<String>), ArgError>
where
    I: IntoIterator<Item = S>,
    S: AsRef<str>,
{
    let args: Vec<String> = args.into_iter().map(|s| s.as_ref().to_string()).collect();
    let mut p = Params::default();
    let mut warnings = Vec::new();
    if let Some(d) = ros_domain_id {
        let d = d.trim();
        if !d.is_empty() {
            p.domain_id = d
                .parse::<u16>()
                .ok()
                .filter(|v| *v <= 232)
                .ok_or_else(|| ArgError::DomainId(d.to_string()))?;
        }
    }

    let mut overrides: Vec<(String, ParamValue)> = Vec::new();
    let mut files: Vec<String> = Vec::new();
    let mut in_ros = false;
    let mut i = 0;
    let next = |i: &mut usize, flag: &str| -> Result<String, ArgError> {
        *i += 1;
        args.get(*i)
            .cloned()
            .ok_or_else(|| ArgError::MissingValue(flag.to_string()))
    };
    while i < args.len() {
        let a = args[i].as_str();
        if !in_ros {
            match a {
                "--ros-args" => in_ros = true,
                "-h" | "--help" => return Err(ArgError::Help),
                _ => return Err(ArgError::Unknown(a.to_string())),
            }
        } else {
            match a {
                "--" => in_ros = false,
                "--ros-args" => {}
                "-r" | "--remap" => {
                    let v = next(&mut i, a)?;
                    apply_remap(&mut p, &v)?;
                }
                "-p" | "--param" => {
                    let v = next(&mut i, a)?;
                    let (name, value) = v.split_once(":=").ok_or_else(|| ArgError::Bad {
                        arg: format!("{a} {v}"),
                        msg: "expected NAME:=VALUE".into(),
                    })?;
                    if name.is_empty() {
                        return Err(ArgError::Bad {
                            arg: format!("{a} {v}"),
                            msg: "empty parameter name".into(),
                        });
                    }
                    overrides.push((name.to_string(), ParamValue::parse_cli(value)));
                }
                "--params-file" => files.push(next(&mut i, a)?),
                "--log-level" => {
                    let v = next(&mut i, a)?;
                    p.log_level =
                        Some(ros_log_level_to_filter(&v).ok_or_else(|| ArgError::Bad {
                            arg: format!("--log-level {v}"),
                            msg: "expected debug, info, warn, error or fatal".into(),
                        })?);
                }
                "-e" | "--enclave" => {
                    next(&mut i, a)?;
                }
                "--enable-rosout-logs" => p.enable_rosout = true,
                "--disable-rosout-logs" => p.enable_rosout = false,
                "--enable-stdout-logs"
                | "--disable-stdout-logs"
                | "--enable-external-lib-logs"
                | "--disable-external-lib-logs" => {}
                "-h" | "--help" => return Err(ArgError::Help),
                _ => return Err(ArgError::Unknown(a.to_string())),
            }
        }
        i += 1;
    }

    // params files first (in order), then -p overrides
    let mut values: Vec<(String, ParamValue, String)> = Vec::new();
    for f in &files {
        for (n, v) in load_params_file(f, &p.namespace, &p.node_name)? {
            values.push((n, v, format!("params file {f}")));
        }
    }
    for (n, v) in overrides {
        values.push((n, v, "-p".into()));
    }
    let mut set: Vec<String> = Vec::new();
    for (name, value, origin) in values {
        match apply_param(&mut p, &name, &value)? {
            Applied::Yes => set.push(name),
            Applied::Unknown => {
                warnings.push(format!("unknown parameter `{name}` ({origin}) ignored"))
            }
        }
    }
    let was_set = |n: &str| set.iter().any(|s| s == n);
    if !was_set("static_stale_timeout_s") {
        p.static_stale_timeout_s = p.stale_timeout_s;
    }
    // a policy path selects the policy controller unless `controller` was given
    if p.policy.is_some() && !was_set("controller") {
        p.controller = ControllerKind::Policy;
    }
    Ok((p, warnings))
}

enum Applied {
    Yes,
    Unknown,
}

fn apply_remap(p: &mut Params, v: &str) -> Result<(), ArgError> {
    let bad = |msg: &str| ArgError::Bad {
        arg: format!("-r {v}"),
        msg: msg.to_string(),
    };
    let (from, to) = v.split_once(":=").ok_or_else(|| bad("expected FROM:=TO"))?;
    // `node_name:__ns:=...` targets one node; we are the only node in this process
    let from = match from.split_once(':') {
        Some((node, rest)) if node == p.node_name || node == DEFAULT_NODE_NAME => rest,
        Some(_) => return Ok(()), // remap for another node: not ours
        None => from,
    };
    match from {
        "__ns" => {
            let ns = to.trim_end_matches('/');
            let ns = if ns.is_empty() { "/" } else { ns };
            if !ns.starts_with('/') {
                return Err(bad("namespace must be absolute (start with /)"));
            }
            if ns != "/" {
                for seg in ns[1..].split('/') {
                    if !valid_token(seg) {
                        return Err(bad(&format!("invalid namespace segment `{seg}`")));
                    }
                }
            }
            p.namespace = ns.to_string();
        }
        "__node" | "__name" => {
            if !valid_token(to) {
                return Err(bad("invalid node name"));
            }
            p.node_name = to.to_string();
        }
        _ => {
            return Err(bad(
                "only __ns and __node remaps are supported (topic names are fixed by the contract)",
            ))
        }
    }
    Ok(())
}

fn valid_token(seg: &str) -> bool {
    !seg.is_empty()
        && (seg.as_bytes()[0].is_ascii_alphabetic() || seg.as_bytes()[0] == b'_')
        && seg.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_')
        && !seg.contains("__")
}

fn ros_log_level_to_filter(v: &str) -> Option<String> {
    // `--log-level debug` or `--log-level robot_node:=debug`
    let lvl = v.rsplit(":=").next().unwrap_or(v).to_ascii_lowercase();
    Some(
        match lvl.as_str() {
            "debug" => "debug",
            "info" => "info",
            "warn" | "warning" => "warn",
            "error" | "fatal" => "error",
            _ => return None,
        }
        .to_string(),
    )
}

fn num(name: &str, v: &ParamValue) -> Result<f64, ArgError> {
    match v {
        ParamValue::Int(i) => Ok(*i as f64),
        ParamValue::Double(d) => Ok(*d),
        other => Err(ArgError::Param {
            name: name.into(),
            msg: format!("expected a number, got {other:?}"),
        }),
    }
}

fn positive(name: &str, v: &ParamValue) -> Result<f64, ArgError> {
    let x = num(name, v)?;
    if x.is_finite() && x > 0.0 {
        Ok(x)
    } else {
        Err(ArgError::Param {
            name: name.into(),
            msg: format!("must be a finite number > 0, got {x}"),
        })
    }
}

fn apply_param(p: &mut Params, name: &str, v: &ParamValue) -> Result<Applied, ArgError> {
    match name {
        "policy" => match v {
            ParamValue::Str(s) if s.is_empty() => p.policy = None,
            ParamValue::Str(s) => p.policy = Some(PathBuf::from(s)),
            other => {
                return Err(ArgError::Param {
                    name: name.into(),
                    msg: format!("expected a path, got {other:?}"),
                })
            }
        },
        "controller" => {
            p.controller = match v {
                ParamValue::Str(s) if s == "greedy" => ControllerKind::Greedy,
                ParamValue::Str(s) if s == "policy" => ControllerKind::Policy,
                other => {
                    return Err(ArgError::Param {
                        name: name.into(),
                        msg: format!("expected `greedy` or `policy`, got {other:?}"),
                    })
                }
            }
        }
        "control_rate_hz" => {
            let hz = positive(name, v)?;
            if hz > 1000.0 {
                return Err(ArgError::Param {
                    name: name.into(),
                    msg: format!("{hz} Hz is above the 1000 Hz limit"),
                });
            }
            p.control_rate_hz = hz;
        }
        "use_sim_time" => match v {
            ParamValue::Bool(b) => p.use_sim_time = *b,
            other => {
                return Err(ArgError::Param {
                    name: name.into(),
                    msg: format!("expected true or false, got {other:?}"),
                })
            }
        },
        "k_speed" => p.k_speed = positive(name, v)?,
        "stale_timeout_s" => p.stale_timeout_s = positive(name, v)?,
        "static_stale_timeout_s" => {
            let x = num(name, v)?;
            if !x.is_finite() {
                return Err(ArgError::Param {
                    name: name.into(),
                    msg: "must be finite".into(),
                });
            }
            p.static_stale_timeout_s = x;
        }
        "room_margin" => {
            let x = num(name, v)?;
            if !(x.is_finite() && x >= 0.0) {
                return Err(ArgError::Param {
                    name: name.into(),
                    msg: format!("must be a finite number >= 0, got {x}"),
                });
            }
            p.room_margin = x;
        }
        "stats_period_s" => p.stats_period_s = positive(name, v)?,
        "discovery_period_s" => p.discovery_period_s = positive(name, v)?,
        _ => return Ok(Applied::Unknown),
    }
    Ok(Applied::Yes)
}

/// Does a params-file key (`/**`, `robot_node`, `/robot_3/robot_node`, `/*/robot_node`)
/// select this node?
pub fn key_matches(key: &str, namespace: &str, node_name: &str) -> bool {
    let fq: Vec<&str> = namespace
        .split('/')
        .filter(|s| !s.is_empty())
        .chain(std::iter::once(node_name))
        .collect();
    let pat: Vec<&str> = key.split('/').filter(|s| !s.is_empty()).collect();
    if !key.starts_with('/') && pat.len() == 1 {
        // a bare node name matches in any namespace
        return pat[0] == node_name || pat[0] == "**" || pat[0] == "*";
    }
    fn m(pat: &[&str], name: &[&str]) -> bool {
        match pat.first() {
            None => name.is_empty(),
            Some(&"**") => (0..=name.len()).any(|k| m(&pat[1..], &name[k..])),
            Some(&"*") => !name.is_empty() && m(&pat[1..], &name[1..]),
            Some(seg) => !name.is_empty() && *seg == name[0] && m(&pat[1..], &name[1..]),
        }
    }
    m(&pat, &fq)
}

/// Parameters for this node from a ROS 2 params YAML file.
pub fn load_params_file(
    path: &str,
    namespace: &str,
    node_name: &str,
) -> Result<Vec<(String, ParamValue)>, ArgError> {
    let text = std::fs::read_to_string(path).map_err(|e| ArgError::ParamsFile {
        path: path.into(),
        msg: e.to_string(),
    })?;
    parse_params_yaml(&text, namespace, node_name).map_err(|msg| ArgError::ParamsFile {
        path: path.into(),
        msg,
    })
}

/// Parse params-file text; see [`load_params_file`].
pub fn parse_params_yaml(
    text: &str,
    namespace: &str,
    node_name: &str,
) -> Result<Vec<(String, ParamValue)>, String> {
    use serde_yaml::Value as Y;
    let doc: Y = serde_yaml::from_str(text).map_err(|e| e.to_string())?;
    let Y::Mapping(top) = doc else {
        return Err("top level must be a mapping of node names".into());
    };
    let mut out = Vec::new();
    fn flatten(prefix: &str, v: &Y, out: &mut Vec<(String, ParamValue)>) {
        match v {
            Y::Mapping(m) => {
                for (k, v) in m {
                    let k = key_str(k);
                    let name = if prefix.is_empty() {
                        k
                    } else {
                        format!("{prefix}.{k}")
                    };
                    flatten(&name, v, out);
                }
            }
            other => out.push((prefix.to_string(), ParamValue::from_yaml(other))),
        }
    }
    fn key_str(k: &Y) -> String {
        match k {
            Y::String(s) => s.clone(),
            other => serde_yaml::to_string(other)
                .unwrap_or_default()
                .trim()
                .to_string(),
        }
    }
    fn walk(
        path: &str,
        m: &serde_yaml::Mapping,
        ns: &str,
        node: &str,
        out: &mut Vec<(String, ParamValue)>,
    ) -> Result<(), String> {
        for (k, v) in m {
            let k = key_str(k);
            if k == "ros__parameters" {
                if key_matches(path, ns, node) {
                    if !v.is_mapping() && !v.is_null() {
                        return Err(format!("`{path}: ros__parameters` must be a mapping"));
                    }
                    flatten("", v, out);
                }
                continue;
            }
            let sub = if path.is_empty() {
                k.clone()
            } else {
                format!(
                    "{}/{}",
                    path.trim_end_matches('/'),
                    k.trim_start_matches('/')
                )
            };
            match v {
                Y::Mapping(inner) => walk(&sub, inner, ns, node, out)?,
                _ => return Err(format!("key `{sub}`: expected a mapping")),
            }
        }
        Ok(())
    }
    walk("", &top, namespace, node_name, &mut out)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_ok(a: &[&str]) -> Params {
        parse(a.iter().copied(), None).unwrap().0
    }

    #[test]
    fn defaults() {
        let p = parse_ok(&[]);
        assert_eq!(p, Params::default());
        assert_eq!(p.fully_qualified_name(), "/robot_node");
    }

    #[test]
    fn full_command_line() {
        let p = parse_ok(&[
            "--ros-args",
            "-r",
            "__ns:=/robot_3",
            "-r",
            "__node:=brain",
            "-p",
            "policy:=/tmp/p.safetensors",
            "-p",
            "control_rate_hz:=20",
            "-p",
            "use_sim_time:=true",
            "-p",
            "k_speed:=0.25",
            "-p",
            "stale_timeout_s:=2",
        ]);
        assert_eq!(p.namespace, "/robot_3");
        assert_eq!(p.robot_id(), "robot_3");
        assert_eq!(p.node_name, "brain");
        assert_eq!(p.fully_qualified_name(), "/robot_3/brain");
        assert_eq!(
            p.policy.as_deref(),
            Some(std::path::Path::new("/tmp/p.safetensors"))
        );
        assert_eq!(p.controller, ControllerKind::Policy);
        assert_eq!(p.control_rate_hz, 20.0);
        assert!(p.use_sim_time);
        assert_eq!(p.k_speed, 0.25);
        assert_eq!(p.stale_timeout_s, 2.0);
        assert_eq!(p.static_stale_timeout_s, 2.0);
    }

    #[test]
    fn long_forms_and_node_targeted_remaps() {
        let p = parse_ok(&[
            "--ros-args",
            "--remap",
            "robot_node:__ns:=/r1/",
            "--param",
            "controller:=greedy",
            "--log-level",
            "WARN",
            "--",
        ]);
        assert_eq!(p.namespace, "/r1");
        assert_eq!(p.log_level.as_deref(), Some("warn"));
        assert_eq!(p.controller, ControllerKind::Greedy);
        // remap aimed at another node is not ours
        let p = parse_ok(&["--ros-args", "-r", "other:__ns:=/x"]);
        assert_eq!(p.namespace, "/");
    }

    #[test]
    fn domain_id_from_env() {
        let (p, _) = parse(Vec::<String>::new(), Some("42")).unwrap();
        assert_eq!(p.domain_id, 42);
        assert_eq!(
            parse(Vec::<String>::new(), Some("")).unwrap().0.domain_id,
            0
        );
        assert!(matches!(
            parse(Vec::<String>::new(), Some("abc")),
            Err(ArgError::DomainId(_))
        ));
        assert!(matches!(
            parse(Vec::<String>::new(), Some("300")),
            Err(ArgError::DomainId(_))
        ));
    }

    #[test]
    fn bad_arguments_name_the_argument() {
        let cases: &[(&[&str], &str)] = &[
            (&["--foo"], "--foo"),
            (&["--ros-args", "-p"], "-p"),
            (&["--ros-args", "-p", "k_speed"], "k_speed"),
            (&["--ros-args", "-p", "k_speed:=fast"], "k_speed"),
            (&["--ros-args", "-p", "k_speed:=-1"], "k_speed"),
            (
                &["--ros-args", "-p", "control_rate_hz:=0"],
                "control_rate_hz",
            ),
            (&["--ros-args", "-p", "use_sim_time:=maybe"], "use_sim_time"),
            (&["--ros-args", "-p", "controller:=magic"], "controller"),
            (&["--ros-args", "-r", "__ns:=robot_3"], "__ns:=robot_3"),
            (&["--ros-args", "-r", "__ns:=/3robot"], "3robot"),
            (&["--ros-args", "-r", "cmd_vel:=/x"], "cmd_vel:=/x"),
            (&["--ros-args", "-r"], "-r"),
            (&["--ros-args", "--bogus"], "--bogus"),
            (&["--ros-args", "--log-level", "loud"], "loud"),
            (
                &["--ros-args", "--params-file", "/nonexistent/x.yaml"],
                "/nonexistent/x.yaml",
            ),
        ];
        for (args, needle) in cases {
            let e = parse(args.iter().copied(), None).unwrap_err();
            let s = e.to_string();
            assert!(
                s.contains(needle),
                "{args:?}: `{s}` does not name `{needle}`"
            );
        }
        assert_eq!(parse(["--help"], None).unwrap_err(), ArgError::Help);
    }

    #[test]
    fn unknown_params_warn() {
        let (p, w) = parse(["--ros-args", "-p", "foo:=1", "-p", "k_speed:=1"], None).unwrap();
        assert_eq!(p.k_speed, 1.0);
        assert_eq!(w.len(), 1);
        assert!(w[0].contains("foo"));
    }

    #[test]
    fn key_patterns() {
        assert!(key_matches("/**", "/robot_3", "robot_node"));
        assert!(key_matches("robot_node", "/robot_3", "robot_node"));
        assert!(key_matches("/robot_3/robot_node", "/robot_3", "robot_node"));
        assert!(key_matches("/*/robot_node", "/robot_3", "robot_node"));
        assert!(key_matches("/**/robot_node", "/a/b", "robot_node"));
        assert!(!key_matches(
            "/robot_4/robot_node",
            "/robot_3",
            "robot_node"
        ));
        assert!(!key_matches("other", "/robot_3", "robot_node"));
        assert!(!key_matches("/*/robot_node", "/", "robot_node"));
        assert!(key_matches("/robot_node", "/", "robot_node"));
    }

    #[test]
    fn params_file_forms() {
        let yaml = r#"
/**:
  ros__parameters:
    k_speed: 0.3
    use_sim_time: true
robot_3:
  robot_node:
    ros__parameters:
      control_rate_hz: 5
/robot_4/robot_node:
  ros__parameters:
    control_rate_hz: 99.0
robot_node:
  ros__parameters:
    nested:
      thing: 1
"#;
        let v = parse_params_yaml(yaml, "/robot_3", "robot_node").unwrap();
        assert!(v.contains(&("k_speed".into(), ParamValue::Double(0.3))));
        assert!(v.contains(&("use_sim_time".into(), ParamValue::Bool(true))));
        assert!(v.contains(&("control_rate_hz".into(), ParamValue::Int(5))));
        assert!(v.contains(&("nested.thing".into(), ParamValue::Int(1))));
        assert!(!v.iter().any(|(_, x)| *x == ParamValue::Double(99.0)));
        assert!(parse_params_yaml("- a\n- b\n", "/", "robot_node").is_err());
        assert!(parse_params_yaml(":::\n  -", "/", "robot_node").is_err());
    }

    #[test]
    fn params_file_then_cli_override() {
        let dir = std::env::temp_dir().join(format!("robot_node_args_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("p.yaml");
        std::fs::write(
            &f,
            "/**:\n  ros__parameters:\n    k_speed: 0.3\n    control_rate_hz: 5\n",
        )
        .unwrap();
        let fs = f.to_str().unwrap();
        let p = parse_ok(&["--ros-args", "--params-file", fs, "-p", "k_speed:=0.7"]);
        assert_eq!(p.k_speed, 0.7);
        assert_eq!(p.control_rate_hz, 5.0);
        // order on the command line does not matter: -p wins
        let p = parse_ok(&["--ros-args", "-p", "k_speed:=0.7", "--params-file", fs]);
        assert_eq!(p.k_speed, 0.7);
        std::fs::write(&f, "/**:\n  ros__parameters:\n    k_speed: nope\n").unwrap();
        let e = parse(["--ros-args", "--params-file", fs], None).unwrap_err();
        assert!(e.to_string().contains("k_speed"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
