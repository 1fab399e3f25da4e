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

use std::sync::atomic::AtomicBool;

use anyhow::{anyhow, Context as _};
use ros2_client::dds::Context;
use tracing::{info, warn};

use ros::RosNode;

use crate::args::{ControlParams, FilterParams, Geometry, Params};
use crate::controller::{
    Controller, GreedyController, GreedyOrcaController, MatchingOrcaController, PolicyController,
};
use crate::hosted::RobotSpec;
use crate::watchdog::{retry, NodeStage, Watchdog};
use crate::world::Counters;
use plan::MethodName;
use plan::{Deployment, FilterMargins, FleetParams, Safety};

/// Build the controller the parameters ask for, and the speed limit of its commands.
///
/// `policy`: a [`PolicyController`] from the checkpoint (a wrong or corrupt file is an
/// error naming the file and the problem); its k_speed comes from the checkpoint's
/// training metadata when present, else from the `k_speed` parameter.
pub fn make_controller(p: &Params) -> anyhow::Result<(Box<dyn Controller>, f64)> {
    let fleet = fleet_params(&p.geometry, &p.control);
    match p.control.controller {
        MethodName::Greedy => Ok((
            Box::new(GreedyController::new(fleet.greedy_params())),
            p.control.k_speed,
        )),
        MethodName::GreedyOrca => Ok((
            Box::new(GreedyOrcaController::new(fleet.orca_params())?),
            p.control.k_speed,
        )),
        MethodName::MatchingOrca => Ok((
            Box::new(MatchingOrcaController::new(
                &fleet,
                filter_margins(&p.filter),
            )?),
            p.control.k_speed,
        )),
        MethodName::Policy => policy_controller(p, fleet),
        // refused when the parameter is read (args.rs); kept as an error, not a panic
        MethodName::Random => anyhow::bail!("controller `random` is an offline baseline"),
    }
}

/// The learned policy behind the safety layer [`Safety::choose`] picks on a robot: the
/// ORCA filter unless `orca_filter:=false` or `shield:=true` (the rules `tending eval
/// --orca-filter/--shield` reproduce offline).
fn policy_controller(p: &Params, fleet: FleetParams) -> anyhow::Result<(Box<dyn Controller>, f64)> {
    let path = p
        .control
        .policy
        .as_ref()
        .ok_or_else(|| anyhow!("controller `policy` needs a checkpoint: -p policy:=PATH"))?;
    let (c, from_meta) = PolicyController::load(path, p.control.k_speed as f32)?;
    let safety = Safety::choose(
        p.control.shield,
        p.control.orca_filter,
        Deployment::Robot,
        filter_margins(&p.filter),
    );
    if safety.filter.is_some() {
        info!("policy commands pass through the ORCA safety filter");
    } else if c.trained_with_orca_filter() {
        warn!(
            "policy {} was trained behind the ORCA filter; running it without \
             (orca_filter:=false) changes what it learned on",
            path.display()
        );
    }
    let c = c
        .with_pilot(fleet, safety)
        .with_context(|| format!("policy {}", path.display()))?;
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

/// What a robot knows about its fleet: sizes, speed, control period, machine timing, the
/// room (`room_size`, the contract's 2.3 m unless a grown floor says otherwise), its reach and the default contact distance. The planner's
/// parameter sets (greedy, ORCA, shield) come from it.
pub fn fleet_params(g: &Geometry, c: &ControlParams) -> FleetParams {
    FleetParams {
        robot_radius: g.robot_radius as f32,
        machine_half: [g.machine_half[0] as f32, g.machine_half[1] as f32],
        storage_half: [g.storage_half[0] as f32, g.storage_half[1] as f32],
        k_speed: c.k_speed as f32,
        dt: (1.0 / c.rate_hz) as f32,
        prep_steps: c.prep_steps,
        room_size: g.room_size as f32,
        reach: c.reach.unwrap_or(g.robot_radius) as f32,
        collision_distance: plan::fleet::DEFAULT_COLLISION_DISTANCE,
    }
}

/// The ORCA filter's margins behind a policy or matching-ORCA (`orca_clearance`,
/// `orca_rest_clearance`, `orca_obstacle_horizon`).
fn filter_margins(f: &FilterParams) -> FilterMargins {
    FilterMargins {
        clearance: f.clearance as f32,
        rest_clearance: f.rest_clearance as f32,
        obstacle_horizon: f.obstacle_horizon as f32,
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

#[cfg(test)]
mod tests {
    use super::*;

    /// robot_node's default parameters (bodies, speed and machine timing taken from the
    /// planner's defaults, the control rate and room its own) rebuild the planner's default
    /// fleet: dt from `control_rate_hz`, the reach from the radius, the contract's room.
    #[test]
    fn default_parameters_are_the_default_fleet() {
        let d = Params::default();
        let f = fleet_params(&d.geometry, &d.control);
        assert_eq!(f, crate::controller::tests::fleet());
        assert_eq!(f.greedy_params(), plan::greedy::GreedyParams::default());
        assert_eq!(f.shield_params().margin, 0.015);
        assert_eq!(
            filter_margins(&Params::default().filter),
            FilterMargins::DEPLOYED
        );
    }
}
