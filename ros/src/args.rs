//! ROS 2 command-line conventions, parsed here because ros2-client parses none; shared by
//! `robot_node` and `sim_bridge` (each applies the parameters it knows):
//!
//! ```text
//! <node> [--ros-args [-r|--remap __ns:=/robot_3] [-r __node:=name]
//!                    [-p|--param name:=value]... [--params-file f.yaml]...
//!                    [--log-level LEVEL] [--enclave E]
//!                    [--enable-rosout-logs|--disable-rosout-logs|--disable-stdout-logs]
//!                    [--] ]
//! ```
//!
//! Parameter files use the ROS 2 YAML form `<node>: ros__parameters: {...}` where the key
//! may be the node name, its fully qualified name, or a pattern with `*` (one segment)
//! and `**` (any segments), e.g. `/**:`; nested namespace keys are joined with `/`.
//! Files apply in order, then `-p` overrides. `ROS_DOMAIN_ID` comes from the environment.
//!
//! Each node's parameters hold a [`NodeArgs`] and apply the rest ([`parse_params`]) with
//! the typed readers ([`positive`], [`boolean`], [`timeout_s`], ...), so the two
//! nodes accept and refuse values alike.

/// The node identity of one command line: what every node's parameters start with.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeArgs {
    /// Namespace with leading slash (`/` when none).
    pub namespace: String,
    pub node_name: String,
    pub domain_id: u16,
    /// `--log-level`, if given (tracing filter directive).
    pub log_level: Option<String>,
    pub enable_rosout: bool,
    /// `--enclave`, if given: the DDS Security enclave (see [`crate::security`]).
    pub enclave: Option<String>,
}

impl NodeArgs {
    /// No arguments: node `node_name` in `/`, domain 0, rosout on.
    pub fn new(node_name: &str) -> Self {
        Self {
            namespace: "/".into(),
            node_name: node_name.into(),
            domain_id: 0,
            log_level: None,
            enable_rosout: true,
            enclave: None,
        }
    }

    /// What [`crate::node`] creates the node from.
    pub fn spec(&self) -> crate::NodeSpec<'_> {
        crate::NodeSpec {
            namespace: &self.namespace,
            name: &self.node_name,
            enable_rosout: self.enable_rosout,
        }
    }

    pub fn fully_qualified_name(&self) -> String {
        if self.namespace == "/" {
            format!("/{}", self.node_name)
        } else {
            format!("{}/{}", self.namespace, self.node_name)
        }
    }
}

/// The node identity and raw parameters of one command line.
#[derive(Debug, Clone, PartialEq)]
pub struct RosArgs {
    pub node: NodeArgs,
    /// The node's built-in name (`-r robot_node:__ns:=...` remaps target it too).
    pub default_node_name: String,
    /// (name, value, origin) in application order: params files, then `-p`.
    pub values: Vec<(String, ParamValue, String)>,
}

/// Parse a node's command line (see [`parse_ros_args`]) into its parameters `P`: `init`
/// makes them from the node identity, `apply` sets one parameter and returns whether it
/// knows the name. Returns the parameters, the names set (in order) and a warning per
/// unknown name.
pub fn parse_params<P, I, S>(
    args: I,
    ros_domain_id: Option<&str>,
    default_node_name: &str,
    init: impl FnOnce(NodeArgs) -> P,
    mut apply: impl FnMut(&mut P, &str, &ParamValue) -> Result<bool, ArgError>,
) -> Result<(P, Vec<String>, Vec<String>), ArgError>
where
    I: IntoIterator<Item = S>,
    S: AsRef<str>,
{
    let ra = parse_ros_args(args, ros_domain_id, default_node_name)?;
    let mut p = init(ra.node);
    let (set, warnings) = apply_values(ra.values, |name, v| apply(&mut p, name, v))?;
    Ok((p, set, warnings))
}

/// Apply [`RosArgs::values`] in order with `apply`, which returns whether it knows the
/// name. Returns the names applied and a warning per unknown name.
pub fn apply_values(
    values: Vec<(String, ParamValue, String)>,
    mut apply: impl FnMut(&str, &ParamValue) -> Result<bool, ArgError>,
) -> Result<(Vec<String>, Vec<String>), ArgError> {
    let (mut set, mut warnings) = (Vec::new(), Vec::new());
    for (name, value, origin) in values {
        if apply(&name, &value)? {
            set.push(name);
        } else {
            warnings.push(format!("unknown parameter `{name}` ({origin}) ignored"));
        }
    }
    Ok((set, warnings))
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ArgError {
    #[error("argument `{arg}`: {msg}")]
    Bad { arg: String, msg: String },
    #[error("argument `{0}` needs a value")]
    MissingValue(String),
    #[error("unknown argument `{0}` (only ROS 2 arguments are accepted after --ros-args)")]
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

/// Parse the process arguments (without argv\[0\]) and `ROS_DOMAIN_ID` into the node
/// identity and the raw parameter values (params files in order, then `-p`), each with
/// where it came from. The caller applies them (see `robot_node::args::parse`).
pub fn parse_ros_args<I, S>(
    args: I,
    ros_domain_id: Option<&str>,
    default_node_name: &str,
) -> Result<RosArgs, ArgError>
where
    I: IntoIterator<Item = S>,
    S: AsRef<str>,
{
    let args: Vec<String> = args.into_iter().map(|s| s.as_ref().to_string()).collect();
    let mut p = RosArgs {
        node: NodeArgs::new(default_node_name),
        default_node_name: default_node_name.to_string(),
        values: Vec::new(),
    };
    if let Some(d) = ros_domain_id {
        let d = d.trim();
        if !d.is_empty() {
            p.node.domain_id = d
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
                    p.node.log_level =
                        Some(ros_log_level_to_filter(&v).ok_or_else(|| ArgError::Bad {
                            arg: format!("--log-level {v}"),
                            msg: "expected debug, info, warn, error or fatal".into(),
                        })?);
                }
                "-e" | "--enclave" => p.node.enclave = Some(next(&mut i, a)?),
                "--enable-rosout-logs" => p.node.enable_rosout = true,
                "--disable-rosout-logs" => p.node.enable_rosout = false,
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
        for (n, v) in load_params_file(f, &p.node.namespace, &p.node.node_name)? {
            values.push((n, v, format!("params file {f}")));
        }
    }
    for (n, v) in overrides {
        values.push((n, v, "-p".into()));
    }
    p.values = values;
    Ok(p)
}

fn apply_remap(p: &mut RosArgs, v: &str) -> Result<(), ArgError> {
    let bad = |msg: &str| ArgError::Bad {
        arg: format!("-r {v}"),
        msg: msg.to_string(),
    };
    let (from, to) = v.split_once(":=").ok_or_else(|| bad("expected FROM:=TO"))?;
    // `node_name:__ns:=...` targets one node; we are the only node in this process
    let from = match from.split_once(':') {
        Some((node, rest)) if node == p.node.node_name || node == p.default_node_name => rest,
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
            p.node.namespace = ns.to_string();
        }
        "__node" | "__name" => {
            if !valid_token(to) {
                return Err(bad("invalid node name"));
            }
            p.node.node_name = to.to_string();
        }
        _ => {
            return Err(bad(
                "only __ns and __node remaps are supported (topic names are fixed by the contract)",
            ))
        }
    }
    Ok(())
}

pub fn valid_token(seg: &str) -> bool {
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

/// An [`ArgError::Param`] naming parameter `name`.
pub fn param_error(name: &str, msg: impl Into<String>) -> ArgError {
    ArgError::Param {
        name: name.into(),
        msg: msg.into(),
    }
}

pub fn num(name: &str, v: &ParamValue) -> Result<f64, ArgError> {
    match v {
        ParamValue::Int(i) => Ok(*i as f64),
        ParamValue::Double(d) => Ok(*d),
        other => Err(param_error(
            name,
            format!("expected a number, got {other:?}"),
        )),
    }
}

/// A number for which `ok` holds, else an error saying it `must be {what}`.
fn checked(
    name: &str,
    v: &ParamValue,
    ok: impl Fn(f64) -> bool,
    what: &str,
) -> Result<f64, ArgError> {
    let x = num(name, v)?;
    if ok(x) {
        Ok(x)
    } else {
        Err(param_error(name, format!("must be {what}, got {x}")))
    }
}

pub fn positive(name: &str, v: &ParamValue) -> Result<f64, ArgError> {
    checked(name, v, |x| x.is_finite() && x > 0.0, "a finite number > 0")
}

pub fn non_negative(name: &str, v: &ParamValue) -> Result<f64, ArgError> {
    checked(
        name,
        v,
        |x| x.is_finite() && x >= 0.0,
        "a finite number >= 0",
    )
}

/// A watchdog timeout: finite seconds >= 0, 0 disabling it.
pub fn timeout_s(name: &str, v: &ParamValue) -> Result<f64, ArgError> {
    let what = "a finite number of seconds >= 0 (0 disables)";
    checked(name, v, |x| x.is_finite() && x >= 0.0, what)
}

/// A loop rate: > 0 and at most 1000 Hz.
pub fn rate_hz(name: &str, v: &ParamValue) -> Result<f64, ArgError> {
    let hz = positive(name, v)?;
    if hz > 1000.0 {
        return Err(param_error(
            name,
            format!("{hz} Hz is above the 1000 Hz limit"),
        ));
    }
    Ok(hz)
}

pub fn boolean(name: &str, v: &ParamValue) -> Result<bool, ArgError> {
    match v {
        ParamValue::Bool(b) => Ok(*b),
        other => Err(param_error(
            name,
            format!("expected true or false, got {other:?}"),
        )),
    }
}

/// A path; the empty string is none. `what` names the expected kind in the error.
pub fn optional_path(
    name: &str,
    v: &ParamValue,
    what: &str,
) -> Result<Option<std::path::PathBuf>, ArgError> {
    match v {
        ParamValue::Str(s) if s.is_empty() => Ok(None),
        ParamValue::Str(s) => Ok(Some(s.into())),
        other => Err(param_error(
            name,
            format!("expected a {what}, got {other:?}"),
        )),
    }
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
