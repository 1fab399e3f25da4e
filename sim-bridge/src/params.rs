//! `sim_bridge` parameters, from the ROS 2 command-line conventions (`ros::args`).

use std::path::PathBuf;

use ros::args::{num, parse_ros_args, positive, ArgError, ParamValue};
use sim::Setup;

pub const DEFAULT_NODE_NAME: &str = "sim_bridge";

pub const USAGE: &str = "usage: sim_bridge [--ros-args [-p NAME:=VALUE]... [--params-file FILE.yaml]...]
parameters: setup (6.4_2), seed (0), mode (realtime|lockstep), rate_hz (10), stale_timeout_s (2.0),
            config (scenario TOML; default: built-in), spawn_initial (true), max_steps (0 = run until stopped),
            lockstep_timeout_s (2.0), startup_grace_s (10.0), settle_s (2.0), metrics_period_s (1.0),
            discovery_period_s (0.5), record (bag directory: record every published topic and every
            received cmd_vel as a rosbag2 MCAP bag; default: none), stdin_commands (false: also read
            /tending/command lines from stdin), test_cmd_delay_ms (0: fault injection, hold every
            received cmd_vel this long before the simulator sees it), startup_timeout_s (10),
            stall_timeout_s (10): watchdog, exit code 75 when start-up or the step loop makes no
            progress that long (0 disables)
topics: /clock, /<robot>/pose, /<robot>/has_part, /machine_<j>/pose, /machine_<j>/part_ready,
        /storage_<k>/pose, /tending/markers, /tending/metrics; subscribes /<robot>/cmd_vel (discovered)
        and /tending/command (std_msgs/String: add_machine [x y] | remove_machine ID | add_storage [x y] |
        remove_storage ID | add_robot NAME [x y] | remove_robot NAME)
environment: ROS_DOMAIN_ID (0)";

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Step at `rate_hz` on the wall clock with the latest command of each robot.
    Realtime,
    /// Step when every live robot answered the last published state (or after
    /// `lockstep_timeout_s`): reproducible runs (docs/adr/0003-lockstep.md).
    Lockstep,
}

#[derive(Debug, Clone, PartialEq)]
pub struct BridgeParams {
    pub namespace: String,
    pub node_name: String,
    pub domain_id: u16,
    /// `--enclave`: the DDS Security enclave, used when `ROS_SECURITY_ENABLE=true`.
    pub enclave: Option<String>,
    pub log_level: Option<String>,
    pub enable_rosout: bool,
    pub setup: Setup,
    pub seed: u64,
    pub mode: Mode,
    pub rate_hz: f64,
    /// A robot body whose cmd_vel is older than this (wall seconds) is removed.
    pub stale_timeout_s: f64,
    pub config: Option<PathBuf>,
    pub spawn_initial: bool,
    /// Stop after this many steps (0: run until stopped).
    pub max_steps: u64,
    pub lockstep_timeout_s: f64,
    /// Initial bodies are kept this long without any cmd_vel.
    pub startup_grace_s: f64,
    /// Lockstep: wait this long after every initial robot's cmd_vel was discovered before
    /// publishing the first state (robot nodes finish their own discovery meanwhile).
    pub settle_s: f64,
    pub metrics_period_s: f64,
    pub discovery_period_s: f64,
    /// Record everything published and every cmd_vel received into this bag directory.
    pub record: Option<PathBuf>,
    /// Read `/tending/command` lines from stdin too (what `tending fleet` uses).
    pub stdin_commands: bool,
    /// Fault injection (tests and bench/faults only): every received cmd_vel reaches the
    /// simulator this many milliseconds late.
    pub test_cmd_delay_ms: f64,
    /// Fault injection (tests and bench/faults only): every state message the bridge
    /// publishes (poses, has_part, part_ready, markers, metrics, /clock) goes out this many
    /// milliseconds after the step that produced it; the step loop does not wait.
    pub test_state_delay_ms: f64,
    /// Watchdog: exit with code 75 when start-up makes no progress this long (0: off).
    pub startup_timeout_s: f64,
    /// Watchdog: exit with code 75 when the step loop stalls this long (0: off).
    pub stall_timeout_s: f64,
}

impl Default for BridgeParams {
    fn default() -> Self {
        Self {
            namespace: "/".into(),
            node_name: DEFAULT_NODE_NAME.into(),
            domain_id: 0,
            enclave: None,
            log_level: None,
            enable_rosout: true,
            setup: Setup::new(6, 4, 2),
            seed: 0,
            mode: Mode::Realtime,
            rate_hz: 10.0,
            stale_timeout_s: 2.0,
            config: None,
            spawn_initial: true,
            max_steps: 0,
            lockstep_timeout_s: 2.0,
            startup_grace_s: 10.0,
            settle_s: 2.0,
            metrics_period_s: 1.0,
            discovery_period_s: 0.5,
            record: None,
            stdin_commands: false,
            test_cmd_delay_ms: 0.0,
            test_state_delay_ms: 0.0,
            startup_timeout_s: 10.0,
            stall_timeout_s: 10.0,
        }
    }
}

fn bad(name: &str, msg: String) -> ArgError {
    ArgError::Param {
        name: name.into(),
        msg,
    }
}

/// Parse the process arguments (without argv\[0\]) and `ROS_DOMAIN_ID`; returns the
/// parameters and warnings (unknown parameters).
pub fn parse<I, S>(
    args: I,
    ros_domain_id: Option<&str>,
) -> Result<(BridgeParams, Vec<String>), ArgError>
where
    I: IntoIterator<Item = S>,
    S: AsRef<str>,
{
    let ra = parse_ros_args(args, ros_domain_id, DEFAULT_NODE_NAME)?;
    let mut p = BridgeParams {
        namespace: ra.namespace,
        node_name: ra.node_name,
        domain_id: ra.domain_id,
        enclave: ra.enclave,
        log_level: ra.log_level,
        enable_rosout: ra.enable_rosout,
        ..BridgeParams::default()
    };
    let mut warnings = Vec::new();
    for (name, v, origin) in ra.values {
        let n = name.as_str();
        match n {
            "setup" => {
                let s = match &v {
                    ParamValue::Str(s) => s.clone(),
                    ParamValue::Double(d) => format!("{d}"),
                    other => return Err(bad(n, format!("expected N.M_K, got {other:?}"))),
                };
                p.setup = s.parse().map_err(|e| bad(n, format!("{e}")))?;
            }
            "seed" => match v {
                ParamValue::Int(i) if i >= 0 => p.seed = i as u64,
                other => return Err(bad(n, format!("expected an integer >= 0, got {other:?}"))),
            },
            "max_steps" => match v {
                ParamValue::Int(i) if i >= 0 => p.max_steps = i as u64,
                other => return Err(bad(n, format!("expected an integer >= 0, got {other:?}"))),
            },
            "mode" => {
                p.mode = match &v {
                    ParamValue::Str(s) if s == "realtime" => Mode::Realtime,
                    ParamValue::Str(s) if s == "lockstep" => Mode::Lockstep,
                    other => {
                        return Err(bad(
                            n,
                            format!("expected realtime or lockstep, got {other:?}"),
                        ))
                    }
                }
            }
            "rate_hz" => {
                let hz = positive(n, &v)?;
                if hz > 1000.0 {
                    return Err(bad(n, format!("{hz} Hz is above the 1000 Hz limit")));
                }
                p.rate_hz = hz;
            }
            "stale_timeout_s" => p.stale_timeout_s = positive(n, &v)?,
            "lockstep_timeout_s" => p.lockstep_timeout_s = positive(n, &v)?,
            "startup_grace_s" => {
                let x = num(n, &v)?;
                if !(x.is_finite() && x >= 0.0) {
                    return Err(bad(n, format!("must be finite and >= 0, got {x}")));
                }
                p.startup_grace_s = x;
            }
            "startup_timeout_s" | "stall_timeout_s" => {
                let x = num(n, &v)?;
                if !(x.is_finite() && x >= 0.0) {
                    return Err(bad(
                        n,
                        format!("must be a finite number of seconds >= 0 (0 disables), got {x}"),
                    ));
                }
                if n == "startup_timeout_s" {
                    p.startup_timeout_s = x;
                } else {
                    p.stall_timeout_s = x;
                }
            }
            "settle_s" => {
                let x = num(n, &v)?;
                if !(x.is_finite() && x >= 0.0) {
                    return Err(bad(n, format!("must be finite and >= 0, got {x}")));
                }
                p.settle_s = x;
            }
            "metrics_period_s" => p.metrics_period_s = positive(n, &v)?,
            "discovery_period_s" => p.discovery_period_s = positive(n, &v)?,
            "config" => match &v {
                ParamValue::Str(s) if s.is_empty() => p.config = None,
                ParamValue::Str(s) => p.config = Some(PathBuf::from(s)),
                other => return Err(bad(n, format!("expected a path, got {other:?}"))),
            },
            "record" => match &v {
                ParamValue::Str(s) if s.is_empty() => p.record = None,
                ParamValue::Str(s) => p.record = Some(PathBuf::from(s)),
                other => return Err(bad(n, format!("expected a directory, got {other:?}"))),
            },
            "test_cmd_delay_ms" | "test_state_delay_ms" => {
                let x = num(n, &v)?;
                if !(x.is_finite() && (0.0..=10_000.0).contains(&x)) {
                    return Err(bad(n, format!("must be in [0, 10000] ms, got {x}")));
                }
                if n == "test_cmd_delay_ms" {
                    p.test_cmd_delay_ms = x;
                } else {
                    p.test_state_delay_ms = x;
                }
            }
            "stdin_commands" => match v {
                ParamValue::Bool(b) => p.stdin_commands = b,
                other => return Err(bad(n, format!("expected true or false, got {other:?}"))),
            },
            "spawn_initial" => match v {
                ParamValue::Bool(b) => p.spawn_initial = b,
                other => return Err(bad(n, format!("expected true or false, got {other:?}"))),
            },
            "use_sim_time" => {} // the bridge is the clock
            _ => warnings.push(format!("unknown parameter `{name}` ({origin}) ignored")),
        }
    }
    Ok((p, warnings))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_documented_command_line() {
        let (p, w) = parse(
            [
                "--ros-args",
                "-p",
                "setup:=6.4_2",
                "-p",
                "seed:=3",
                "-p",
                "mode:=lockstep",
                "-p",
                "rate_hz:=20",
                "-p",
                "stale_timeout_s:=1.5",
                "-p",
                "spawn_initial:=false",
                "-p",
                "max_steps:=200",
                "-p",
                "test_state_delay_ms:=50",
                "-p",
                "test_cmd_delay_ms:=200.5",
                "-p",
                "bogus:=1",
            ],
            Some("7"),
        )
        .unwrap();
        assert_eq!(p.setup, Setup::new(6, 4, 2));
        assert_eq!(p.seed, 3);
        assert_eq!(p.mode, Mode::Lockstep);
        assert_eq!(p.rate_hz, 20.0);
        assert_eq!(p.stale_timeout_s, 1.5);
        assert!(!p.spawn_initial);
        assert_eq!(p.max_steps, 200);
        assert_eq!(p.domain_id, 7);
        assert_eq!(p.test_state_delay_ms, 50.0);
        assert_eq!(p.test_cmd_delay_ms, 200.5);
        assert_eq!(w.len(), 1);
    }

    #[test]
    fn refuses_bad_values() {
        for bad in [
            "setup:=6.4",
            "mode:=fast",
            "rate_hz:=0",
            "seed:=-1",
            "spawn_initial:=maybe",
            "test_state_delay_ms:=-1",
            "test_state_delay_ms:=20000",
            "test_cmd_delay_ms:=nan",
            "startup_timeout_s:=-1",
            "stall_timeout_s:=soon",
            "stall_timeout_s:=.inf",
        ] {
            assert!(parse(["--ros-args", "-p", bad], None).is_err(), "{bad}");
        }
    }

    #[test]
    fn watchdog_timeouts() {
        let (p, _) = parse(Vec::<String>::new(), None).unwrap();
        assert_eq!((p.startup_timeout_s, p.stall_timeout_s), (10.0, 10.0));
        let (p, _) = parse(
            [
                "--ros-args",
                "-p",
                "startup_timeout_s:=2.5",
                "-p",
                "stall_timeout_s:=0",
            ],
            None,
        )
        .unwrap();
        assert_eq!((p.startup_timeout_s, p.stall_timeout_s), (2.5, 0.0));
    }
}
