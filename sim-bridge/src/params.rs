//! `sim_bridge` parameters, from the ROS 2 command-line conventions (`ros::args`).

use std::path::PathBuf;

use ros::args::{
    boolean, non_negative, optional_path, param_error, parse_params, positive, rate_hz, timeout_s,
    ArgError, NodeArgs, ParamValue,
};
use sim::Setup;

pub const DEFAULT_NODE_NAME: &str = "sim_bridge";

pub const USAGE: &str = "usage: sim_bridge [--ros-args [-p NAME:=VALUE]... [--params-file FILE.yaml]...]
parameters: setup (6.4_2), seed (0), mode (realtime|lockstep), rate_hz (10), stale_timeout_s (2.0),
            cmd_vel_timeout_s (0.5: realtime, a body whose latest cmd_vel is older is commanded zero
            velocity, like a base controller's command timeout; must be < stale_timeout_s),
            config (scenario TOML; default: built-in), spawn_initial (true), max_steps (0 = run until stopped),
            lockstep_timeout_s (2.0), lockstep_resend_s (0.5: publish a state again while a robot
            has not answered it; 0 = never), startup_grace_s (10.0), settle_s (2.0), metrics_period_s (1.0),
            wait_for_robots (true: realtime holds the simulator at its first state until every
            initial robot commands from state, at most startup_grace_s),
            discovery_period_s (0.5), record (bag directory: record every published topic and every
            received cmd_vel as a rosbag2 MCAP bag; default: none), stdin_commands (false: also read
            /tending/command lines from stdin), test_cmd_delay_ms (0: fault injection, hold every
            received cmd_vel this long before the simulator sees it), startup_timeout_s (10),
            stall_timeout_s (10): watchdog, exit code 75 when start-up or the step loop makes no
            progress that long (0 disables), cell_size (0 = off: metres; also publish each cell's
            state on /tending/cells/c<i>_<j>, docs/adr/0038-cell-topics.md)
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
    /// Namespace, node name, domain, log level, `--enclave` (the DDS Security enclave,
    /// used when `ROS_SECURITY_ENABLE=true`).
    pub node: NodeArgs,
    pub setup: Setup,
    pub seed: u64,
    pub mode: Mode,
    pub rate_hz: f64,
    /// A robot body whose cmd_vel is older than this (wall seconds) is removed.
    pub stale_timeout_s: f64,
    /// Realtime: a body whose latest cmd_vel is older than this (wall seconds) is commanded
    /// zero velocity (it brakes to a stop), as a ROS 2 base controller does on its
    /// `cmd_vel_timeout`; it is removed later, at `stale_timeout_s`. Must be below it
    /// (docs/adr/0031-command-timeout.md). Lockstep ignores it (it waits for commands).
    pub cmd_vel_timeout_s: f64,
    pub config: Option<PathBuf>,
    pub spawn_initial: bool,
    /// Stop after this many steps (0: run until stopped).
    pub max_steps: u64,
    pub lockstep_timeout_s: f64,
    /// Lockstep: publish the current state again every this many seconds while some robot
    /// has not answered it (0: never). A sample written before the DDS Security key
    /// exchange with a reader finished never reaches it (volatile QoS), so without this a
    /// robot that joined the data late would wait for a state that never comes
    /// (docs/adr/0029-lockstep-resends.md).
    pub lockstep_resend_s: f64,
    /// Initial bodies are kept this long without any cmd_vel.
    pub startup_grace_s: f64,
    /// Realtime: hold the simulator at its first state (published at the rate) until every
    /// initial robot sends a command computed from state, or `startup_grace_s` runs out.
    /// Without it the first robots up drive among peers that do not move yet.
    pub wait_for_robots: bool,
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
    /// Side of the square cells whose state is also published per cell
    /// (`/tending/cells/c<i>_<j>`, docs/adr/0038-cell-topics.md); 0: no cell topics.
    pub cell_size: f64,
}

impl Default for BridgeParams {
    fn default() -> Self {
        Self {
            node: NodeArgs::new(DEFAULT_NODE_NAME),
            setup: Setup::new(6, 4, 2),
            seed: 0,
            mode: Mode::Realtime,
            rate_hz: 10.0,
            stale_timeout_s: 2.0,
            cmd_vel_timeout_s: 0.5,
            config: None,
            spawn_initial: true,
            max_steps: 0,
            lockstep_timeout_s: 2.0,
            lockstep_resend_s: 0.5,
            startup_grace_s: 10.0,
            wait_for_robots: true,
            settle_s: 2.0,
            metrics_period_s: 1.0,
            discovery_period_s: 0.5,
            record: None,
            stdin_commands: false,
            test_cmd_delay_ms: 0.0,
            test_state_delay_ms: 0.0,
            startup_timeout_s: 10.0,
            stall_timeout_s: 10.0,
            cell_size: 0.0,
        }
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
    let init = |node| BridgeParams {
        node,
        ..BridgeParams::default()
    };
    let (p, _, warnings) = parse_params(args, ros_domain_id, DEFAULT_NODE_NAME, init, apply_param)?;
    p.check()?;
    Ok((p, warnings))
}

impl BridgeParams {
    /// Constraints between parameters (each one alone is checked as it is parsed).
    pub fn check(&self) -> Result<(), ArgError> {
        if self.cmd_vel_timeout_s >= self.stale_timeout_s {
            return Err(param_error(
                "cmd_vel_timeout_s",
                format!(
                    "must be below stale_timeout_s ({}): a body stops at the command timeout \
                     and is removed at the staleness timeout, got {}",
                    self.stale_timeout_s, self.cmd_vel_timeout_s
                ),
            ));
        }
        Ok(())
    }
}

/// Set parameter `name`; false if it is not one of `sim_bridge`'s.
fn apply_param(p: &mut BridgeParams, n: &str, v: &ParamValue) -> Result<bool, ArgError> {
    let bad = |msg: String| param_error(n, msg);
    match n {
        "setup" => {
            let s = match v {
                ParamValue::Str(s) => s.clone(),
                ParamValue::Double(d) => format!("{d}"),
                other => return Err(bad(format!("expected N.M_K, got {other:?}"))),
            };
            p.setup = s.parse().map_err(|e| bad(format!("{e}")))?;
        }
        "seed" => p.seed = non_negative_int(n, v)?,
        "max_steps" => p.max_steps = non_negative_int(n, v)?,
        "mode" => {
            p.mode = match v {
                ParamValue::Str(s) if s == "realtime" => Mode::Realtime,
                ParamValue::Str(s) if s == "lockstep" => Mode::Lockstep,
                other => return Err(bad(format!("expected realtime or lockstep, got {other:?}"))),
            }
        }
        "rate_hz" => p.rate_hz = rate_hz(n, v)?,
        "stale_timeout_s" => p.stale_timeout_s = positive(n, v)?,
        "cmd_vel_timeout_s" => p.cmd_vel_timeout_s = positive(n, v)?,
        "lockstep_timeout_s" => p.lockstep_timeout_s = positive(n, v)?,
        "lockstep_resend_s" => p.lockstep_resend_s = non_negative(n, v)?,
        "startup_grace_s" => p.startup_grace_s = non_negative(n, v)?,
        "startup_timeout_s" => p.startup_timeout_s = timeout_s(n, v)?,
        "stall_timeout_s" => p.stall_timeout_s = timeout_s(n, v)?,
        "settle_s" => p.settle_s = non_negative(n, v)?,
        "cell_size" => p.cell_size = non_negative(n, v)?,
        "metrics_period_s" => p.metrics_period_s = positive(n, v)?,
        "discovery_period_s" => p.discovery_period_s = positive(n, v)?,
        "config" => p.config = optional_path(n, v, "path")?,
        "record" => p.record = optional_path(n, v, "directory")?,
        "test_cmd_delay_ms" => p.test_cmd_delay_ms = delay_ms(n, v)?,
        "test_state_delay_ms" => p.test_state_delay_ms = delay_ms(n, v)?,
        "stdin_commands" => p.stdin_commands = boolean(n, v)?,
        "spawn_initial" => p.spawn_initial = boolean(n, v)?,
        "wait_for_robots" => p.wait_for_robots = boolean(n, v)?,
        "use_sim_time" => {} // the bridge is the clock
        _ => return Ok(false),
    }
    Ok(true)
}

fn non_negative_int(n: &str, v: &ParamValue) -> Result<u64, ArgError> {
    match v {
        ParamValue::Int(i) if *i >= 0 => Ok(*i as u64),
        other => Err(param_error(
            n,
            format!("expected an integer >= 0, got {other:?}"),
        )),
    }
}

/// A fault-injection delay: [0, 10000] ms.
fn delay_ms(n: &str, v: &ParamValue) -> Result<f64, ArgError> {
    let x = ros::args::num(n, v)?;
    if !(x.is_finite() && (0.0..=10_000.0).contains(&x)) {
        return Err(param_error(n, format!("must be in [0, 10000] ms, got {x}")));
    }
    Ok(x)
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
        assert_eq!(p.node.domain_id, 7);
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
            "cell_size:=-1",
        ] {
            assert!(parse(["--ros-args", "-p", bad], None).is_err(), "{bad}");
        }
    }

    #[test]
    fn the_command_timeout_defaults_to_half_a_second_and_stays_below_the_stale_timeout() {
        let (p, _) = parse(Vec::<String>::new(), None).unwrap();
        assert_eq!((p.cmd_vel_timeout_s, p.stale_timeout_s), (0.5, 2.0));
        let (p, _) = parse(["--ros-args", "-p", "cmd_vel_timeout_s:=0.25"], None).unwrap();
        assert_eq!(p.cmd_vel_timeout_s, 0.25);
        for bad in [
            &["-p", "cmd_vel_timeout_s:=0"][..],
            &["-p", "cmd_vel_timeout_s:=-1"],
            &["-p", "cmd_vel_timeout_s:=2.0"],
            &["-p", "stale_timeout_s:=0.4"],
            &["-p", "cmd_vel_timeout_s:=1.5", "-p", "stale_timeout_s:=1.0"],
        ] {
            let args = std::iter::once("--ros-args").chain(bad.iter().copied());
            let e = parse(args, None).unwrap_err().to_string();
            assert!(e.contains("cmd_vel_timeout_s"), "{bad:?}: {e}");
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
