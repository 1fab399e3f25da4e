//! `robot_node` parameters, from the ROS 2 command-line conventions (`ros::args`).

use std::path::PathBuf;

use ros::args::{
    boolean, non_negative, num, optional_path, param_error, parse_params, positive, rate_hz,
    timeout_s,
};
pub use ros::args::{
    key_matches, load_params_file, parse_params_yaml, parse_ros_args, ArgError, NodeArgs,
    ParamValue,
};

/// Default node name.
pub const DEFAULT_NODE_NAME: &str = "robot_node";

/// Everything the node is configured with, in the groups the node's parts take: the
/// parameter names on the command line stay flat (`orca_clearance`, `lockstep_wait_s`, ...),
/// as ROS 2 parameters are; `apply_param` puts each in its group.
#[derive(Debug, Clone, PartialEq)]
pub struct Params {
    /// Namespace (e.g. `/robot_3`: this robot's identity), node name, domain, log level,
    /// `--enclave` (the DDS Security enclave, used when `ROS_SECURITY_ENABLE=true`).
    pub node: NodeArgs,
    pub control: ControlParams,
    pub filter: FilterParams,
    pub geometry: Geometry,
    pub perception: Perception,
    pub lockstep: LockstepParams,
    pub realtime: RealTimeParams,
    pub watchdog: WatchdogParams,
    pub stats: StatsParams,
    /// Multi-robot mode: these robots (ids such as `robot_3`) in one process: one DDS
    /// context, one node (in `namespace`), one reader per input topic fanned out to every
    /// hosted robot, one `cmd_vel` writer and controller per robot, one event loop.
    /// Empty: one robot, identified by the namespace.
    pub robots: Vec<String>,
}

/// What drives the robot and at what rate.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlParams {
    /// Checkpoint of the learned policy; `None` = scripted greedy controller.
    pub policy: Option<PathBuf>,
    /// `greedy`, `greedy-orca`, `matching-orca` or `policy`; default: `policy` if a policy
    /// path is given, else `greedy`.
    pub controller: plan::MethodName,
    /// Put the policy's actions behind the one-step action shield (plan::shield).
    pub shield: bool,
    /// Pass the policy's velocity through ORCA as a safety filter (plan::orca); None: on,
    /// unless `shield` is (safety by default; `orca_filter:=false` for the raw policy).
    pub orca_filter: Option<bool>,
    /// Speed of one discrete action, m/s.
    pub k_speed: f64,
    /// Control periods a machine takes to make a part after a pick (the simulator's
    /// `task.prep_steps`): the planner times machines from their ready flag with it.
    pub prep_steps: u32,
    /// Pick/place reach beyond the robot radius (greedy-orca stops within it); default:
    /// `robot_radius` (the simulator's default reach equals its radius at every scale).
    pub reach: Option<f64>,
    /// `control_rate_hz`.
    pub rate_hz: f64,
    pub use_sim_time: bool,
}

/// The ORCA safety filter's margins (a policy's, matching-ORCA's): the parameters
/// `orca_clearance`, `orca_rest_clearance`, `orca_obstacle_horizon`, the one way in (a
/// margins file's `[filter]` table, plan::margins, reaches a robot through them: `tending
/// fleet --margins FILE` writes them into fleet.yaml; a `margins` parameter is refused).
#[derive(Debug, Clone, PartialEq)]
pub struct FilterParams {
    /// Peer clearance at full speed, m (`plan::orca::FILTER_CLEARANCE`); at rest it is the
    /// smaller of this and `rest_clearance` (ADR 0017, 0019).
    pub clearance: f64,
    /// Peer clearance at rest, m (`plan::orca::FILTER_REST_CLEARANCE`, what the policy is
    /// evaluated with; 0.035 is ADR 0017's more conservative margin).
    pub rest_clearance: f64,
    /// Horizon for boxes and walls, s (`plan::orca::FILTER_OBSTACLE_HORIZON`, ADR 0030;
    /// greedy-orca keeps `plan::orca::OBSTACLE_HORIZON`).
    pub obstacle_horizon: f64,
}

/// The fleet's bodies and room (the launcher passes the simulator's values for the setup;
/// defaults: the unscaled base sizes in the contract's 2.3 m room).
#[derive(Debug, Clone, PartialEq)]
pub struct Geometry {
    pub robot_radius: f64,
    pub machine_half: [f64; 2],
    pub storage_half: [f64; 2],
    /// Side of the room, m: the planner's walls, and accepted positions are |x|,|y| <=
    /// room_size / 2 + room_margin. A grown floor's (docs/adr/0037) from `tending fleet`.
    pub room_size: f64,
    pub room_margin: f64,
}

/// What the robot reads and observes, and when its data goes stale.
#[derive(Debug, Clone, PartialEq)]
pub struct Perception {
    /// `nearest_machines`, `nearest_storages`, `nearest_peers` (0 or absent: everything,
    /// the paper's): the simulator's rule.
    pub bound: obs::Bound,
    /// Read machines, storages and peers from the cell topics (`/tending/cells/c<i>_<j>`,
    /// docs/adr/0038-cell-topics.md) of cells of this side, m, instead of every entity's
    /// topics; 0: every entity's (the contract's default).
    pub cell_size: f64,
    /// Cell mode: how many cells around its own a robot reads at least (1: 3 x 3).
    pub cell_reach: u32,
    /// No sample from a robot (own or peer) for this long: stale.
    pub stale_timeout_s: f64,
    /// Staleness of machine and storage data (latched topics); <= 0 disables it.
    /// Default: `stale_timeout_s`.
    pub static_stale_timeout_s: f64,
    /// Period of topic discovery scans.
    pub discovery_period_s: f64,
}

/// Lockstep with the sim bridge (docs/adr/0003-lockstep.md): act once per simulator state,
/// when own and all expected entity data of that state's stamp are in (or after `wait_s`),
/// and tag cmd_vel with the state's stamp. Implies sim time.
#[derive(Debug, Clone, PartialEq)]
pub struct LockstepParams {
    /// `lockstep`.
    pub enabled: bool,
    /// `lockstep_wait_s`.
    pub wait_s: f64,
    /// `lockstep_resend_s`: send the answer to a state again every this many seconds while
    /// the bridge has not published the next one (0: never). An answer written before the
    /// DDS Security key exchange with the bridge finished never reaches it (volatile QoS)
    /// (docs/adr/0029-lockstep-resends.md).
    pub resend_s: f64,
}

/// Real time on the wall clock.
#[derive(Debug, Clone, PartialEq)]
pub struct RealTimeParams {
    /// Act on each new state as soon as own data and every expected entity of its stamp
    /// are in (or after `state_wait_s`), instead of at the control timer's phase; the
    /// timer then only repeats the last command while no new state comes (a heartbeat)
    /// (docs/adr/0024-act-on-state.md).
    pub act_on_state: bool,
    pub state_wait_s: f64,
}

/// Watchdog (docs/bench/ros.md): exit code 75 (`EX_TEMPFAIL`) for the launcher to restart
/// the process; 0 disables either.
#[derive(Debug, Clone, PartialEq)]
pub struct WatchdogParams {
    /// Start-up (controller, DDS context, node, writers, subscriptions) must make
    /// progress (a stage, an entity, a retry) at least this often until the event loop runs.
    pub startup_timeout_s: f64,
    /// The event loop must iterate at least this often once running (it wakes every
    /// 100 ms at most).
    pub stall_timeout_s: f64,
}

/// The counters' log line.
#[derive(Debug, Clone, PartialEq)]
pub struct StatsParams {
    /// `stats_period_s`.
    pub period_s: f64,
    /// `stats_json`: also print the counters as one JSON object per line on stdout (every
    /// stats period and on exit, with `"final": true`), for benchmarks and launchers.
    pub json: bool,
}

impl Default for Params {
    /// The default scenario's fleet in the contract's room: bodies, action speed and
    /// machine timing are the planner's defaults (`plan::greedy::GreedyParams`, the
    /// simulator's own at scale 1), not a copy of them.
    fn default() -> Self {
        let fleet = plan::greedy::GreedyParams::default();
        Self {
            node: NodeArgs::new(DEFAULT_NODE_NAME),
            control: ControlParams {
                policy: None,
                controller: plan::MethodName::Greedy,
                shield: false,
                orca_filter: None,
                k_speed: fleet.k_speed.into(),
                prep_steps: fleet.prep_steps,
                reach: None,
                rate_hz: 10.0,
                use_sim_time: false,
            },
            filter: FilterParams {
                clearance: plan::orca::FILTER_CLEARANCE as f64,
                rest_clearance: plan::orca::FILTER_REST_CLEARANCE as f64,
                obstacle_horizon: plan::orca::FILTER_OBSTACLE_HORIZON as f64,
            },
            geometry: Geometry {
                robot_radius: fleet.robot_radius.into(),
                machine_half: fleet.machine_half.map(f64::from),
                storage_half: fleet.storage_half.map(f64::from),
                room_size: 2.0 * msgs::validate::ROOM_HALF_EXTENT,
                room_margin: msgs::validate::DEFAULT_MARGIN,
            },
            perception: Perception {
                bound: obs::Bound::EVERYTHING,
                cell_size: 0.0,
                cell_reach: 1,
                stale_timeout_s: 1.0,
                static_stale_timeout_s: 1.0,
                discovery_period_s: 0.5,
            },
            lockstep: LockstepParams {
                enabled: false,
                wait_s: 0.5,
                resend_s: 0.5,
            },
            realtime: RealTimeParams {
                act_on_state: true,
                state_wait_s: 0.03,
            },
            watchdog: WatchdogParams {
                startup_timeout_s: 10.0,
                stall_timeout_s: 10.0,
            },
            stats: StatsParams {
                period_s: 10.0,
                json: false,
            },
            robots: Vec::new(),
        }
    }
}

impl Params {
    /// Robot identity used by the topic contract (`robot_3`).
    pub fn robot_id(&self) -> String {
        self.node.namespace.trim_matches('/').to_string()
    }

    /// Cell mode's grid (`cell_size` > 0) over the room of `room_size`.
    pub fn cell_grid(&self) -> Result<Option<msgs::cells::CellGrid>, ArgError> {
        if self.perception.cell_size <= 0.0 {
            return Ok(None);
        }
        msgs::cells::CellGrid::new(self.geometry.room_size, self.perception.cell_size)
            .map(Some)
            .map_err(|e| param_error("cell_size", e.to_string()))
    }
}

pub const USAGE: &str = "usage: robot_node [--ros-args -r __ns:=/robot_N [-r __node:=NAME] \
[-p NAME:=VALUE]... [--params-file FILE.yaml]... [--log-level LEVEL]]
parameters: policy (path), controller (greedy|greedy-orca|matching-orca|policy), shield (false), orca_filter (true unless shield:=true), orca_clearance (0.04 m at full speed), orca_rest_clearance (0.03 m at rest),
            orca_obstacle_horizon (0.15 s) (the ORCA filter's margins: a margins file's [filter]
            table, which `tending fleet --margins FILE` writes as these), control_rate_hz (10),
            use_sim_time (false), reach (= robot_radius),
            k_speed (0.5), prep_steps (20), stale_timeout_s (1.0), static_stale_timeout_s (= stale_timeout_s, <=0 off),
            room_size (2.3 m), room_margin (0.25), nearest_machines / nearest_storages /
            nearest_peers (0: everything), cell_size (0: off; m, read the cell topics of ADR 0038
            instead of every entity's), cell_reach (1: the 3 x 3 cells around), stats_period_s (10), discovery_period_s (0.5),
            robot_radius (0.08), machine_half_x/_y (0.12), storage_half_x (0.15), storage_half_y (0.08),
            lockstep (false; implies use_sim_time), lockstep_wait_s (0.5), lockstep_resend_s (0.5; 0 never),
            act_on_state (true: real time acts when a state is in), state_wait_s (0.03),
            stats_json (false; counters as JSON lines on stdout),
            robots (multi-robot mode: robot_0,robot_1,... or robot_0..N-1 in one process),
            startup_timeout_s (10), stall_timeout_s (10): watchdog, exit code 75 when
            start-up makes no progress or the control loop stops for that long (0 off)
environment: ROS_DOMAIN_ID (0)";

/// Parse the process arguments (without argv\[0\]) and `ROS_DOMAIN_ID`.
pub fn parse<I, S>(args: I, ros_domain_id: Option<&str>) -> Result<(Params, Vec<String>), ArgError>
where
    I: IntoIterator<Item = S>,
    S: AsRef<str>,
{
    let init = |node| Params {
        node,
        ..Params::default()
    };
    let (mut p, set, warnings) =
        parse_params(args, ros_domain_id, DEFAULT_NODE_NAME, init, apply_param)?;
    let was_set = |n: &str| set.iter().any(|s| s == n);
    if p.lockstep.enabled {
        p.control.use_sim_time = true;
    }
    if !was_set("static_stale_timeout_s") {
        p.perception.static_stale_timeout_s = p.perception.stale_timeout_s;
    }
    // a policy path selects the policy controller unless `controller` was given
    if p.control.policy.is_some() && !was_set("controller") {
        p.control.controller = plan::MethodName::Policy;
    }
    Ok((p, warnings))
}

/// Set parameter `name`; false if it is not one of `robot_node`'s.
fn apply_param(p: &mut Params, name: &str, v: &ParamValue) -> Result<bool, ArgError> {
    match name {
        "policy" => p.control.policy = optional_path(name, v, "path")?,
        "controller" => {
            let on_robot = plan::MethodName::ON_ROBOT;
            let expected = || format!("expected {}", plan::MethodName::list(&on_robot));
            p.control.controller = match v {
                ParamValue::Str(s) => match s.parse::<plan::MethodName>() {
                    Ok(m) if on_robot.contains(&m) => m,
                    Ok(m) => {
                        return Err(param_error(
                            name,
                            format!("`{m}` is an offline baseline: {}", expected()),
                        ))
                    }
                    Err(e) => return Err(param_error(name, e)),
                },
                other => return Err(param_error(name, format!("{}, got {other:?}", expected()))),
            }
        }
        "shield" => p.control.shield = boolean(name, v)?,
        "orca_filter" => p.control.orca_filter = Some(boolean(name, v)?),
        "reach" => p.control.reach = Some(positive(name, v)?),
        "orca_clearance" => p.filter.clearance = positive(name, v)?,
        "orca_rest_clearance" => p.filter.rest_clearance = positive(name, v)?,
        "orca_obstacle_horizon" => p.filter.obstacle_horizon = positive(name, v)?,
        // one way in for the filter's margins: the parameters above (ADR 0036)
        "margins" => {
            return Err(param_error(
                name,
                "robot_node takes no margins file: set the ORCA filter's margins as the \
                 parameters orca_clearance, orca_rest_clearance and orca_obstacle_horizon \
                 (a margins file's [filter] clearance, rest_clearance, obstacle_horizon; \
                 `tending fleet --margins FILE` writes them into fleet.yaml)",
            ))
        }
        "control_rate_hz" => p.control.rate_hz = rate_hz(name, v)?,
        "use_sim_time" => p.control.use_sim_time = boolean(name, v)?,
        "k_speed" => p.control.k_speed = positive(name, v)?,
        "prep_steps" => p.control.prep_steps = steps(name, v)?,
        "stale_timeout_s" => p.perception.stale_timeout_s = positive(name, v)?,
        "static_stale_timeout_s" => {
            let x = num(name, v)?;
            if !x.is_finite() {
                return Err(param_error(name, "must be finite"));
            }
            p.perception.static_stale_timeout_s = x;
        }
        "room_margin" => p.geometry.room_margin = non_negative(name, v)?,
        "room_size" => p.geometry.room_size = positive(name, v)?,
        "cell_size" => p.perception.cell_size = non_negative(name, v)?,
        "cell_reach" => {
            p.perception.cell_reach = match v {
                ParamValue::Int(i) if (1..=100).contains(i) => *i as u32,
                other => {
                    return Err(param_error(
                        name,
                        format!("expected a whole number of cells, 1 to 100, got {other:?}"),
                    ))
                }
            }
        }
        "nearest_machines" => p.perception.bound.nearest_machines = nearest(name, v)?,
        "nearest_storages" => p.perception.bound.nearest_storages = nearest(name, v)?,
        "nearest_peers" => p.perception.bound.nearest_peers = nearest(name, v)?,
        "stats_period_s" => p.stats.period_s = positive(name, v)?,
        "robot_radius" => p.geometry.robot_radius = positive(name, v)?,
        "machine_half_x" => p.geometry.machine_half[0] = positive(name, v)?,
        "machine_half_y" => p.geometry.machine_half[1] = positive(name, v)?,
        "storage_half_x" => p.geometry.storage_half[0] = positive(name, v)?,
        "storage_half_y" => p.geometry.storage_half[1] = positive(name, v)?,
        "lockstep_wait_s" => p.lockstep.wait_s = positive(name, v)?,
        "lockstep_resend_s" => p.lockstep.resend_s = non_negative(name, v)?,
        "lockstep" => p.lockstep.enabled = boolean(name, v)?,
        "act_on_state" => p.realtime.act_on_state = boolean(name, v)?,
        "state_wait_s" => p.realtime.state_wait_s = positive(name, v)?,
        "discovery_period_s" => p.perception.discovery_period_s = positive(name, v)?,
        "robots" => p.robots = parse_robots(name, v)?,
        "startup_timeout_s" => p.watchdog.startup_timeout_s = timeout_s(name, v)?,
        "stall_timeout_s" => p.watchdog.stall_timeout_s = timeout_s(name, v)?,
        "stats_json" => p.stats.json = boolean(name, v)?,
        _ => return Ok(false),
    }
    Ok(true)
}

/// An observation bound: a whole number of entities, 0 (everything) to 100,000.
fn nearest(name: &str, v: &ParamValue) -> Result<Option<usize>, ArgError> {
    let x = num(name, v)?;
    if x.fract() == 0.0 && (0.0..=100_000.0).contains(&x) {
        Ok((x > 0.0).then_some(x as usize))
    } else {
        Err(param_error(
            name,
            format!("must be a whole number from 0 (everything) to 100000, got {x}"),
        ))
    }
}

/// A whole number of control periods, 1 to 100,000.
fn steps(name: &str, v: &ParamValue) -> Result<u32, ArgError> {
    let x = num(name, v)?;
    if x.fract() == 0.0 && (1.0..=100_000.0).contains(&x) {
        Ok(x as u32)
    } else {
        Err(param_error(
            name,
            format!("must be a whole number of steps from 1 to 100000, got {x}"),
        ))
    }
}

/// `robot_0,robot_3` or the range form `robot_0..5` (= robot_0 .. robot_5).
fn parse_robots(name: &str, v: &ParamValue) -> Result<Vec<String>, ArgError> {
    let bad = |msg: String| param_error(name, msg);
    let s = match v {
        ParamValue::Str(s) => s.clone(),
        other => return Err(bad(format!("expected robot ids, got {other:?}"))),
    };
    let mut out: Vec<String> = Vec::new();
    for item in s.split(',').map(str::trim).filter(|x| !x.is_empty()) {
        if let Some((head, last)) = item.split_once("..") {
            let (prefix, first) = head
                .rsplit_once('_')
                .ok_or_else(|| bad(format!("range `{item}` must look like robot_0..9")))?;
            let a: u32 = first
                .parse()
                .map_err(|_| bad(format!("bad range start in `{item}`")))?;
            let b: u32 = last
                .parse()
                .map_err(|_| bad(format!("bad range end in `{item}`")))?;
            if b < a || b - a >= 10_000 {
                return Err(bad(format!("bad range `{item}`")));
            }
            out.extend((a..=b).map(|i| format!("{prefix}_{i}")));
        } else {
            out.push(item.to_string());
        }
    }
    for r in &out {
        if !ros::args::valid_token(r) {
            return Err(bad(format!("`{r}` is not a valid robot id")));
        }
    }
    let mut seen = std::collections::HashSet::new();
    if let Some(d) = out.iter().find(|r| !seen.insert(r.as_str())) {
        return Err(bad(format!("robot `{d}` listed twice")));
    }
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
        assert_eq!(p.node.fully_qualified_name(), "/robot_node");
    }

    #[test]
    fn robots_list_and_range() {
        assert!(parse_ok(&[]).robots.is_empty());
        let p = parse_ok(&["--ros-args", "-p", "robots:=robot_0,robot_3"]);
        assert_eq!(p.robots, ["robot_0", "robot_3"]);
        let p = parse_ok(&["--ros-args", "-p", "robots:=robot_0..2,robot_7"]);
        assert_eq!(p.robots, ["robot_0", "robot_1", "robot_2", "robot_7"]);
        for bad in [
            "robots:=robot_0,robot_0",
            "robots:=robot_3..1",
            "robots:=a-b",
            "robots:=3",
        ] {
            assert!(parse(["--ros-args", "-p", bad], None).is_err(), "{bad}");
        }
    }

    #[test]
    fn watchdog_timeouts() {
        let p = parse_ok(&[]);
        assert_eq!(
            (p.watchdog.startup_timeout_s, p.watchdog.stall_timeout_s),
            (10.0, 10.0)
        );
        let p = parse_ok(&[
            "--ros-args",
            "-p",
            "startup_timeout_s:=2.5",
            "-p",
            "stall_timeout_s:=0",
        ]);
        assert_eq!(
            (p.watchdog.startup_timeout_s, p.watchdog.stall_timeout_s),
            (2.5, 0.0)
        );
        for (bad, name) in [
            ("startup_timeout_s:=-1", "startup_timeout_s"),
            ("startup_timeout_s:=soon", "startup_timeout_s"),
            ("startup_timeout_s:=.inf", "startup_timeout_s"),
            ("stall_timeout_s:=-0.5", "stall_timeout_s"),
            ("stall_timeout_s:=true", "stall_timeout_s"),
        ] {
            let e = parse(["--ros-args", "-p", bad], None)
                .unwrap_err()
                .to_string();
            assert!(e.contains(name), "{bad}: `{e}` does not name {name}");
        }
    }

    #[test]
    fn stats_json_flag() {
        assert!(!parse_ok(&[]).stats.json);
        assert!(
            parse_ok(&["--ros-args", "-p", "stats_json:=true"])
                .stats
                .json
        );
        assert!(parse(["--ros-args", "-p", "stats_json:=3"], None).is_err());
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
            "-p",
            "prep_steps:=30",
        ]);
        assert_eq!(p.control.prep_steps, 30);
        assert_eq!(p.node.namespace, "/robot_3");
        assert_eq!(p.robot_id(), "robot_3");
        assert_eq!(p.node.node_name, "brain");
        assert_eq!(p.node.fully_qualified_name(), "/robot_3/brain");
        assert_eq!(
            p.control.policy.as_deref(),
            Some(std::path::Path::new("/tmp/p.safetensors"))
        );
        assert_eq!(p.control.controller, plan::MethodName::Policy);
        assert_eq!(p.control.rate_hz, 20.0);
        assert!(p.control.use_sim_time);
        assert_eq!(p.control.k_speed, 0.25);
        assert_eq!(p.perception.stale_timeout_s, 2.0);
        assert_eq!(p.perception.static_stale_timeout_s, 2.0);
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
        assert_eq!(p.node.namespace, "/r1");
        assert_eq!(p.node.log_level.as_deref(), Some("warn"));
        assert_eq!(p.control.controller, plan::MethodName::Greedy);
        // remap aimed at another node is not ours
        let p = parse_ok(&["--ros-args", "-r", "other:__ns:=/x"]);
        assert_eq!(p.node.namespace, "/");
    }

    #[test]
    fn greedy_orca_shield_and_reach_parameters() {
        let p = parse_ok(&[
            "--ros-args",
            "-p",
            "controller:=greedy-orca",
            "-p",
            "reach:=0.05",
            "-p",
            "orca_rest_clearance:=0.035",
            "-p",
            "orca_obstacle_horizon:=0.3",
        ]);
        assert_eq!(p.control.controller, plan::MethodName::GreedyOrca);
        assert_eq!(p.control.reach, Some(0.05));
        assert_eq!(p.filter.rest_clearance, 0.035);
        assert_eq!(p.filter.obstacle_horizon, 0.3);
        assert!(!p.control.shield);
        let p = parse_ok(&[
            "--ros-args",
            "-p",
            "policy:=/tmp/p.safetensors",
            "-p",
            "shield:=true",
        ]);
        assert_eq!(p.control.controller, plan::MethodName::Policy);
        assert!(p.control.shield);
        for bad in [
            "shield:=3",
            "reach:=-1",
            "controller:=orca",
            "orca_rest_clearance:=0",
            "orca_obstacle_horizon:=-0.1",
        ] {
            let e = parse(["--ros-args", "-p", bad].iter().copied(), None).unwrap_err();
            let name = bad.split(":=").next().unwrap();
            assert!(e.to_string().contains(name), "{bad}: {e}");
        }
    }

    #[test]
    fn domain_id_from_env() {
        let (p, _) = parse(Vec::<String>::new(), Some("42")).unwrap();
        assert_eq!(p.node.domain_id, 42);
        assert_eq!(
            parse(Vec::<String>::new(), Some(""))
                .unwrap()
                .0
                .node
                .domain_id,
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
            (&["--ros-args", "-p", "prep_steps:=2.5"], "prep_steps"),
            (&["--ros-args", "-p", "prep_steps:=0"], "prep_steps"),
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
        assert_eq!(p.control.k_speed, 1.0);
        assert_eq!(w.len(), 1);
        assert!(w[0].contains("foo"));
    }

    /// The launch file names the controllers robot_node takes, and no other.
    #[test]
    fn the_launch_files_controllers_are_robot_nodes() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../launch-scripts/fleet.launch.py"
        );
        let text = std::fs::read_to_string(path).unwrap();
        let line = text
            .lines()
            .find(|l| l.starts_with("CONTROLLERS = ("))
            .expect("CONTROLLERS in the launch file");
        let names: Vec<&str> = line
            .split('\'')
            .skip(1)
            .step_by(2)
            .filter(|n| !n.is_empty())
            .collect();
        let ours: Vec<&str> = plan::MethodName::ON_ROBOT
            .iter()
            .map(|m| m.as_str())
            .collect();
        assert_eq!(names, ours);
        let e = parse(["--ros-args", "-p", "controller:=random"], None).unwrap_err();
        assert!(e.to_string().contains("offline baseline"), "{e}");
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

    /// The filter's margins have one way in, the `orca_*` parameters: a `margins` file
    /// parameter is refused, on the command line or in a parameters file, naming them.
    #[test]
    fn a_margins_file_is_refused_naming_the_parameters() {
        let e = parse(
            ["--ros-args", "-p", "margins:=configs/margins/deployed.toml"],
            None,
        )
        .unwrap_err()
        .to_string();
        for name in [
            "margins",
            "orca_clearance",
            "orca_rest_clearance",
            "orca_obstacle_horizon",
        ] {
            assert!(e.contains(name), "`{e}` does not name {name}");
        }
        let v = ParamValue::Str("m.toml".into());
        assert!(apply_param(&mut Params::default(), "margins", &v).is_err());
        let p = parse_ok(&["--ros-args", "-p", "orca_clearance:=0.05"]);
        assert_eq!(p.filter.clearance, 0.05);
        assert_eq!(
            p.filter.rest_clearance,
            plan::orca::FILTER_REST_CLEARANCE as f64
        );
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
        assert_eq!(p.control.k_speed, 0.7);
        assert_eq!(p.control.rate_hz, 5.0);
        // order on the command line does not matter: -p wins
        let p = parse_ok(&["--ros-args", "-p", "k_speed:=0.7", "--params-file", fs]);
        assert_eq!(p.control.k_speed, 0.7);
        std::fs::write(&f, "/**:\n  ros__parameters:\n    k_speed: nope\n").unwrap();
        let e = parse(["--ros-args", "--params-file", fs], None).unwrap_err();
        assert!(e.to_string().contains("k_speed"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
