//! An upper bound on the parts any controller can deliver in one episode, from the layout
//! at its start (issue 10: "1.1x the best script" is only a target where it is possible).
//!
//! `Metrics::p_max` (machines x ceil(steps / prep)) ignores that a part must be picked and
//! then carried to a storage area before the episode ends. This bound counts only what is
//! physically possible for robots that move at most `k_speed` per second:
//!
//! - **Machines.** Machine j can first be picked when the nearest robot can first reach its
//!   pick zone (centre within radius + reach of its surface), and again every `prep_steps`
//!   after that at the earliest; a part picked at step t is delivered at the earliest after
//!   the shortest trip from that zone into a storage area's zone. Count the picks whose
//!   earliest delivery is within the episode.
//! - **Robots.** Robot i delivers first after reaching some machine's zone and then a
//!   storage zone; every later delivery from machine j needs a trip from a storage zone to
//!   j's zone and back, at least twice j's gap to the nearest storage zone. So the fleet's
//!   robot-steps cap the deliveries (a fractional knapsack over the machines, nearest
//!   first, each machine capped as above), and so does every robot shuttling on the
//!   shortest gap. A robot does one pick or one place per step.
//!
//! The bound is the smaller of the two. It comes out within 1-3 % of P_max wherever
//! robots are not scarce (`tending bound`): physics alone does not cap the throughput
//! of a crowded setup; its traffic does. Trips are straight lines between convex zones
//! (the Minkowski sums of the boxes and a disc), so obstacles and other robots only make
//! them longer. It assumes what the simulator's velocity tracker guarantees in
//! contact-free motion: a robot moves at most `k_speed * dt` per step. Contact forces can
//! push a robot faster; the check against every controller we evaluate is in
//! `policy/tests/parts_bound.rs`.

use crate::Env;

/// The bound and its two parts (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PartsBound {
    /// Picks every machine could have delivered, each served the moment it is ready.
    pub machines: u32,
    /// Deliveries every robot could make, shuttling on the shortest machine-storage gap.
    pub robots: u32,
}

impl PartsBound {
    /// No controller delivers more than this in the episode.
    pub fn value(&self) -> u32 {
        self.machines.min(self.robots)
    }
}

/// Distance between two axis-aligned boxes given as (centre, half extents); 0 if they
/// overlap.
fn box_gap(a: ([f32; 2], [f32; 2]), b: ([f32; 2], [f32; 2])) -> f32 {
    let dx = ((a.0[0] - b.0[0]).abs() - a.1[0] - b.1[0]).max(0.0);
    let dy = ((a.0[1] - b.0[1]).abs() - a.1[1] - b.1[1]).max(0.0);
    (dx * dx + dy * dy).sqrt()
}

/// Distance from a point to a box (centre, half extents); 0 inside.
fn point_gap(p: [f32; 2], b: ([f32; 2], [f32; 2])) -> f32 {
    box_gap((p, [0.0, 0.0]), b)
}

/// The bound for `env` as it is at the start of an episode (step 0, no part carried,
/// every machine ready, as `Env::reset` leaves it). `None` at any other moment: after
/// steps or live changes the state it reasons from no longer holds.
pub fn parts_bound(env: &Env) -> Option<PartsBound> {
    if env.steps() != 0 || env.robots().any(|r| r.has_part) || env.machines().any(|m| !m.part_ready)
    {
        return None;
    }
    let cfg = env.config();
    let sizes = env.sizes();
    let horizon = cfg.world.episode_steps;
    let prep = cfg.task.prep_steps.max(1);
    let per_step = cfg.task.k_speed * cfg.world.dt;
    // A zone is a box grown by radius + reach; the gap between two zones is the boxes' gap
    // less twice that, the gap from a point to a zone the point's gap less it once.
    let grow = sizes.robot_radius + sizes.reach;
    // Steps to cover `d`, rounded down by a hair so float noise never makes the bound too
    // small; one pick or place per step, so never fewer than one.
    let steps = |d: f32| ((d / per_step - 1e-3).ceil().max(1.0)) as u32;
    let machines: Vec<_> = env.machines().map(|m| (m.centre, m.half)).collect();
    let storages: Vec<_> = env.storages().map(|s| (s.centre, s.half)).collect();
    let robots: Vec<[f32; 2]> = env.robots().map(|r| r.pos).collect();
    if machines.is_empty() || storages.is_empty() || robots.is_empty() {
        return Some(PartsBound {
            machines: 0,
            robots: 0,
        });
    }
    // Shortest trip from each machine's zone into any storage zone.
    let to_storage: Vec<u32> = machines
        .iter()
        .map(|&m| {
            let gap = storages
                .iter()
                .map(|&s| (box_gap(m, s) - 2.0 * grow).max(0.0))
                .fold(f32::INFINITY, f32::min);
            steps(gap)
        })
        .collect();
    let reach_machine = |p: [f32; 2], m| steps((point_gap(p, m) - grow).max(0.0));

    let machine_caps: Vec<u32> = machines
        .iter()
        .zip(&to_storage)
        .map(|(&m, &back)| {
            let first = robots
                .iter()
                .map(|&p| reach_machine(p, m))
                .min()
                .unwrap_or(u32::MAX);
            let last_pick = horizon.saturating_sub(back);
            if first <= last_pick {
                (last_pick - first) / prep + 1
            } else {
                0
            }
        })
        .collect();
    let by_machines = machine_caps.iter().sum();

    // Each robot's deliveries: the first after reaching a machine and carrying its part;
    // every later one after a trip from a storage zone to machine j's zone and back, at
    // least 2 x to_storage[j] steps. So over all deliveries, sum of 2 x to_storage[j] is at
    // most robots x (horizon + the longest carry); with each machine's own cap (above),
    // the most deliveries that fits is a fractional knapsack: the nearest machines first.
    let mut caps: Vec<(u32, u32)> = machine_caps
        .iter()
        .zip(&to_storage)
        .map(|(&c, &leg)| (leg, c))
        .collect();
    caps.sort_unstable();
    let longest = caps.last().map_or(0, |c| c.0);
    let mut budget = robots.len() as f64 * (horizon + longest) as f64;
    let mut by_robots = 0.0f64;
    for (leg, cap) in caps {
        let cost = 2.0 * leg as f64;
        let n = (cap as f64).min(budget / cost);
        by_robots += n;
        budget -= n * cost;
        if budget <= 0.0 {
            break;
        }
    }
    // Every robot also needs its first trip: none delivers more than a shuttle on the
    // shortest gap allows after it.
    let leg = *to_storage.iter().min().expect("machines is not empty");
    let mut shuttle = 0;
    for &p in &robots {
        let first = machines
            .iter()
            .zip(&to_storage)
            .map(|(&m, &back)| reach_machine(p, m) + back)
            .min()
            .expect("machines is not empty");
        if first <= horizon {
            shuttle += (horizon - first) / (2 * leg) + 1;
        }
    }
    let by_robots = (by_robots.floor() as u32).min(shuttle);
    Some(PartsBound {
        machines: by_machines,
        robots: by_robots,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{ScenarioConfig, Setup};

    #[test]
    fn gaps_between_boxes_and_points() {
        let a = ([0.0, 0.0], [0.5, 0.5]);
        assert_eq!(box_gap(a, ([2.0, 0.0], [0.5, 0.5])), 1.0);
        assert!((box_gap(a, ([2.0, 2.0], [0.5, 0.5])) - 2f32.sqrt()).abs() < 1e-6);
        assert_eq!(box_gap(a, ([0.5, 0.0], [0.5, 0.5])), 0.0);
        assert_eq!(point_gap([0.0, 3.0], a), 2.5);
        assert_eq!(point_gap([0.1, 0.1], a), 0.0);
    }

    /// One robot, one machine, one storage on a line: the bound by hand.
    #[test]
    fn hand_computed_layout() {
        let cfg = ScenarioConfig::default();
        let layout = crate::layout::Layout {
            robots: vec![[0.0, 0.0]],
            machines: vec![[-0.9, 0.0]],
            storages: vec![[0.9, 0.0]],
        };
        let env = Env::with_layout(cfg.clone(), Setup::new(1, 1, 1), layout, 0).unwrap();
        let s = *env.sizes();
        let grow = s.robot_radius + s.reach;
        let per_step = cfg.task.k_speed * cfg.world.dt;
        let steps = |d: f32| ((d / per_step - 1e-3).ceil().max(1.0)) as u32;
        // Robot to the machine's zone, then machine zone to storage zone.
        let to_m = steps(0.9 - s.machine_half[0] - grow);
        let leg = steps(1.8 - s.machine_half[0] - s.storage_half[0] - 2.0 * grow);
        let h = cfg.world.episode_steps;
        let p = cfg.task.prep_steps;
        let b = parts_bound(&env).unwrap();
        assert_eq!(b.machines, (h - leg - to_m) / p + 1);
        let knapsack = b.machines.min((h + leg) / (2 * leg));
        let shuttle = (h - to_m - leg) / (2 * leg) + 1;
        assert_eq!(b.robots, knapsack.min(shuttle));
        assert_eq!(b.value(), b.machines.min(b.robots));
        // One robot shuttling across the room: far below P_max (one machine, never
        // waiting).
        assert!(b.value() < h.div_ceil(p));
    }

    #[test]
    fn only_at_the_start_of_an_episode() {
        let mut env = Env::new(ScenarioConfig::default(), Setup::new(6, 4, 2), 3).unwrap();
        assert!(parts_bound(&env).is_some());
        env.step_actions(&[0; 6]).unwrap();
        assert!(parts_bound(&env).is_none());
    }
}
