//! The DDS side: one ros2-client node per process, hosting one robot (`-r __ns:=/robot_3`)
//! or several (`-p robots:=robot_0..99`). Subscribes once to each hosted robot's own
//! pose/has_part, discovers machines, storages and peers from topic discovery (one reader
//! per topic, whatever the number of hosted robots; samples fanned out to every hosted
//! robot's world by [`crate::fanout`]), ticks each robot's [`Brain`] at the control rate
//! (wall clock, or `/clock` with `use_sim_time`) and publishes each robot's `cmd_vel`.
//!
//! Single-threaded event loop on a mio 1 `Poll` (every subscription is a mio source;
//! readers are drained when signalled, plus a sweep of all every 100 ms); the ros2-client
//! spinner (graph events, parameters, rosout discovery) runs on a helper thread
//! ([`ros::RosNode`]). Why: docs/adr/0007-mio-event-loop.md, 0008-shared-readers.md.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{anyhow, Context as _};
use ros2_client::dds::Context;
use tracing::{info, warn};

use ros::RosNode;

use crate::args::{ControllerKind, Params};
use crate::controller::{Controller, GreedyController, GreedyOrcaController, PolicyController};
use crate::watchdog::{NodeStage, Watchdog};
use crate::world::Counters;
use obs::greedy::GreedyParams;

/// Build the controller the parameters ask for, and the speed limit of its commands.
///
/// `policy`: a [`PolicyController`] from the checkpoint (a wrong or corrupt file is an
/// error naming the file and the problem); its k_speed comes from the checkpoint's
/// training metadata when present, else from the `k_speed` parameter.
pub fn make_controller(p: &Params) -> anyhow::Result<(Box<dyn Controller>, f64)> {
    match p.controller {
        ControllerKind::Greedy => {
            let gp = greedy_params(p);
            Ok((Box::new(GreedyController::new(gp)), p.k_speed))
        }
        ControllerKind::GreedyOrca => {
            let c = GreedyOrcaController::new(crate::controller::orca_params(p))?;
            Ok((Box::new(c), p.k_speed))
        }
        ControllerKind::Policy => {
            let path = p.policy.as_ref().ok_or_else(|| {
                anyhow!("controller `policy` needs a checkpoint: -p policy:=PATH")
            })?;
            let (mut c, from_meta) = PolicyController::load(path, p.k_speed as f32)?;
            let filter_on = p.orca_filter.unwrap_or(!p.shield);
            // `tending eval`'s parameters (OrcaParams::for_policy_filter / for_policy).
            let base = crate::controller::orca_params(p);
            let op = if filter_on {
                base.for_policy_filter(p.orca_clearance as f32, p.orca_rest_clearance as f32)
                    .with_obstacle_horizon(p.orca_obstacle_horizon as f32)
            } else {
                base.for_policy(None)
            };
            if c.has_target_actions() {
                anyhow::ensure!(
                    !p.shield,
                    "policy {} picks target boxes; the action shield (shield:=true) acts on \
                     velocity moves: use the ORCA filter (the default) instead",
                    path.display()
                );
                c = c.with_target_planner(op)?;
            }
            if p.shield {
                c = c.with_shield(crate::controller::shield_params(p));
            }
            // Safety on by default, as a factory deploys it: a learned policy's command goes
            // through the ORCA filter unless `orca_filter:=false`; the shield, when asked
            // for, replaces it (the rules `tending eval --orca-filter/--shield` reproduce).
            let trained = c.trained_with_orca_filter();
            if filter_on {
                info!("policy commands pass through the ORCA safety filter");
                c = c.with_orca_filter(op)?;
            } else if trained {
                tracing::warn!(
                    "policy {} was trained behind the ORCA filter; running it without \
                     (orca_filter:=false) changes what it learned on",
                    path.display()
                );
            }
            let k = c.k_speed as f64;
            info!(
                "policy {} loaded ({}), k_speed {k} m/s from {}",
                path.display(),
                "checkpoint",
                if from_meta {
                    "checkpoint metadata"
                } else {
                    "the k_speed parameter"
                }
            );
            Ok((Box::new(c), k))
        }
    }
}

/// The greedy controller's knowledge of the fleet: sizes, speed and control period.
pub fn greedy_params(p: &Params) -> GreedyParams {
    GreedyParams {
        robot_radius: p.robot_radius as f32,
        machine_half: [p.machine_half[0] as f32, p.machine_half[1] as f32],
        storage_half: [p.storage_half[0] as f32, p.storage_half[1] as f32],
        k_speed: p.k_speed as f32,
        dt: (1.0 / p.control_rate_hz) as f32,
        prep_steps: p.prep_steps,
    }
}

/// Run the node until `stop` is set. Returns the final counters (summed over robots in
/// multi-robot mode).
///
/// One robot (`-r __ns:=/robot_3`) or several (`-p robots:=robot_0,robot_1,...`): either
/// way one DDS context, one ros2-client node (namespace `/robot_3`, or the given namespace
/// in multi-robot mode), one reader per input topic whose samples are fanned out to every
/// hosted robot ([`crate::fanout`]), one `cmd_vel` writer per robot, one event loop.
pub fn run(p: &Params, stop: &AtomicBool) -> anyhow::Result<Counters> {
    run_watched(p, stop, &Watchdog::disabled())
}

/// [`run`], reporting its start-up stages and event-loop heartbeat to `wd`
/// ([`crate::watchdog`]).
pub fn run_watched(p: &Params, stop: &AtomicBool, wd: &Watchdog) -> anyhow::Result<Counters> {
    wd.stage(NodeStage::Controller);
    let multi = !p.robots.is_empty();
    let names: Vec<String> = if multi {
        p.robots.clone()
    } else {
        let me = p.robot_id();
        if me.is_empty() {
            return Err(anyhow!(
                "no robot namespace: start with --ros-args -r __ns:=/robot_N"
            ));
        }
        vec![me]
    };
    let mut robots = Vec::with_capacity(names.len());
    for name in names {
        let (controller, k_speed) = if multi {
            let mut q = p.clone();
            q.node.namespace = format!("/{name}");
            q.robots = Vec::new();
            make_controller(&q).with_context(|| format!("robot {name}"))?
        } else {
            make_controller(p)?
        };
        robots.push((name, controller, k_speed));
        wd.beat(); // start-up progress
    }
    wd.stage(NodeStage::Context);
    let ctx = ros::context(p.node.domain_id, p.node.enclave.as_deref())?;
    if multi {
        info!(
            "{} robots in one process: one reader per topic, shared",
            robots.len()
        );
    }
    run_on(&ctx, p, stop, robots, multi, wd)
}

/// Retry a DDS set-up step that can fail transiently (RustDDS reports a full internal
/// channel as a poisoned entity when many entities are created at once): 40 attempts,
/// 250 ms apart, unless stopping.
///
/// Every attempt is start-up progress for the watchdog (a retry loop is not a hang).
pub(crate) fn retry<T>(
    what: &str,
    stop: &AtomicBool,
    wd: &Watchdog,
    mut f: impl FnMut() -> anyhow::Result<T>,
) -> anyhow::Result<T> {
    let mut attempt = 1;
    loop {
        let r = f();
        wd.beat();
        match r {
            Ok(x) => return Ok(x),
            Err(e) if attempt < 40 && !stop.load(Ordering::SeqCst) => {
                if attempt == 1 {
                    warn!("{what}: {e:#} (retrying)");
                }
                attempt += 1;
                std::thread::sleep(Duration::from_millis(250));
            }
            Err(e) => return Err(e),
        }
    }
}

/// A hosted robot (name, controller, its k_speed).
pub(crate) type RobotSpec = (String, Box<dyn Controller>, f64);

/// The node on a DDS context, until `stop` is set.
fn run_on(
    ctx: &Context,
    p: &Params,
    stop: &AtomicBool,
    robots: Vec<RobotSpec>,
    multi: bool,
    wd: &Watchdog,
) -> anyhow::Result<Counters> {
    wd.stage(NodeStage::Node);
    let spin_name = if multi {
        "spin".to_string()
    } else {
        format!("spin-{}", p.robot_id())
    };
    let spec = p.node.spec();
    let mut ros = retry("node", stop, wd, || RosNode::start(ctx, &spec, &spin_name))?;
    let result = crate::event_loop::run(p, stop, ctx, ros.node(), robots, multi, wd);
    wd.stage(NodeStage::Done);
    drop(ros); // stops the spinner
    result
}
