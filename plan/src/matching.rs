//! The matching behind the target menu's "matched" entry (`crate::targets`,
//! docs/adr/0020, 0026-0028): every part-less robot a robot observes, itself included, is
//! assigned a machine by an optimal assignment of travel plus wait, so that no two robots
//! head for the same machine and no machine is left out while a robot is free.

use crate::greedy::GreedyParams;
use obs::{MACHINE_DIM, PEER_DIM, STORAGE_DIM};
use pathfinding::kuhn_munkres::kuhn_munkres;
use pathfinding::matrix::Matrix;

/// What a busy machine whose timer the robot does not know costs in [`matched_machine`],
/// in control steps on top of the travel: half the default preparation time (20 steps),
/// the expected wait at a machine whose pick was seen at a random moment. A machine the
/// robot has timed ([`crate::machine_clock`]) costs its steps until ready instead. A
/// nearer busy machine can so beat a farther ready one. Screened without retraining
/// (seed 7, 20 episodes, the 7-entry bundled policy with "nearest busy" replaced by the
/// matching): with 10 steps 6.4_2 35.1 ->
/// 36.2 parts, 42.28_14 255.3 -> 263.9; ready machines strictly first (busy ones only
/// by distance after every ready one) gave 35.9 / 263.6, 20 steps 35.9 / 263.8.
/// docs/RESULTS.md 7.8.
pub const MATCH_BUSY_STEPS: f32 = 10.0;

/// Weight of a robot's lateness at a machine (its travel steps beyond the machine's steps
/// until ready) in the matching cost, when the part-less robots are at least as many as
/// the machines ([`matched_machine`]). Then every machine gets a robot and every
/// assignment sums the same waits, so travel plus wait only minimizes travel: it would send
/// the robot that is 2 steps from both a ready machine and one ready in 15 to the busy one
/// whenever the other robot is nearer the ready one, however far (the unit test
/// `matching_weighs_lateness_when_every_machine_gets_a_robot`). With fewer robots than
/// machines the weight is 0: the cost then chooses which machines to serve, and lateness
/// there sent robots across the room (2.8_1 -23 % parts at weight 1 on every setup).
/// Screened at 1, 2, 4 and 10 (28 setups, 20 episodes, seeds 7 and 8, the bundled
/// policy): 4 gained +0.28 % and +0.21 % over all, +0.3 to +1.7 % on the balanced
/// setups from 12 robots (12.8_4 +0.9 % / +1.5 %, 30.20_10 +1.4 % / +0.9 %, 50.20_5
/// +1.0 % / +1.4 %), at most -0.7 % on one setup and seed (60.12_3, seed 8).
/// docs/adr/0028-lateness-in-the-matching.md, docs/RESULTS.md 7.16.
pub const MATCH_LATENESS_WEIGHT: f32 = 4.0;

/// Above this many observed robots carrying a part per storage area, the "matched" entry
/// falls back to the greedy script's choice (nearest unclaimed ready machine, else make
/// room). Where the storages are the bottleneck, every extra robot carrying a part only
/// lengthens the queue there: at 80.40_4 the matching raised the share of robot-steps
/// spent carrying from 46 % to 60 % and cut the parts from 193 to 158 (seed 7, 20
/// episodes). Screened on seed 7 with the always-matched script at 2, 4, 8 and no limit:
/// 4 keeps every setup that is not storage-bound unchanged and gives 80.40_4 204.6
/// parts, 40.40_2 109.3 (100.0 without), 30.6_1 46.9 with 1.2 contact steps (45.6 / 2.8),
/// 100.16_2 98.5 / 4.0 (95.3 / 10.4). docs/RESULTS.md 7.8.
pub const MATCH_MAX_CARRIERS_PER_STORAGE: f32 = 4.0;

/// Whether more than [`MATCH_MAX_CARRIERS_PER_STORAGE`] observed peers per storage area
/// carry a part.
pub(crate) fn storages_crowded(storages: &[f32], peers: &[f32]) -> bool {
    let carriers = peers.chunks_exact(PEER_DIM).filter(|q| q[2] > 0.5).count();
    let storages = (storages.len() / STORAGE_DIM).max(1);
    carriers as f32 > MATCH_MAX_CARRIERS_PER_STORAGE * storages as f32
}

/// The machine (index in the observation) that an optimal matching gives this robot, or
/// None when it carries a part or the matching leaves it out (more robots than machines).
///
/// Robots: this one and every part-less peer it observes. Cost of robot r at machine m:
/// travel steps at K_speed from r to m's centre, plus the steps until m has a part:
/// `ready_in[m]` ([`crate::machine_clock`]; empty = none known), [`MATCH_BUSY_STEPS`]
/// for a busy machine of unknown timer. Travel plus wait rather than the later of the
/// two: on the 28-setup screen (seed 7 x 20 episodes, the bundled policy) the sum gained
/// 1.3 % over the constant wait (2.8_1 +13 %, 5.10_2 +9 %), the later of the two 1.0 %,
/// the wait weighted 0.75x-2x the same within 0.1 %, and counting a machine ready by
/// the robot's arrival as ready lost 0.4 % (docs/RESULTS.md 7.13). When the part-less
/// robots are at least as many as the machines, plus [`MATCH_LATENESS_WEIGHT`] x the
/// steps the robot would arrive after the part is ready.
///
/// The assignment minimizes the summed cost (Kuhn-Munkres, the `pathfinding` crate's),
/// every robot and machine at most once. Every robot observes the same fleet, so robots
/// compute the same matching up to rounding and go to different machines with no messages
/// between them. Optimal rather than ADR 0020's greedy pairs-in-increasing-cost: +0.5 % and
/// +0.3 % parts on two 28-setup screens (seeds 7 and 8), most where few robots serve
/// many machines or many robots few (3.3_1 +3.3 % / +1.0 %, 16.4_1 +1.8 % / +1.9 %);
/// O(n^2 m) for n = min(robots, machines), 45 s for the whole screen either way
/// (docs/adr/0027-optimal-matching.md). Recomputed from scratch every step: preferring the
/// previous step's matching lost parts (RESULTS 7.13).
pub fn matched_machine(
    own: &[f32],
    machines: &[f32],
    peers: &[f32],
    p: &GreedyParams,
    ready_in: &[Option<u32>],
) -> Option<usize> {
    if own[2] > 0.5 {
        return None;
    }
    let step = p.k_speed * p.dt;
    let n_machines = machines.len() / MACHINE_DIM;
    if n_machines == 0 {
        return None;
    }
    // Robot 0 is this one, at the origin of the relative frame.
    let robots: Vec<[f32; 2]> = std::iter::once([0.0f32, 0.0])
        .chain(
            peers
                .chunks_exact(PEER_DIM)
                .filter(|q| q[2] < 0.5)
                .map(|q| [q[0], q[1]]),
        )
        .collect();
    let lateness_weight = if robots.len() >= n_machines {
        MATCH_LATENESS_WEIGHT
    } else {
        0.0
    };
    // Kuhn-Munkres maximizes integer weights: minus the cost in thousandths of a step.
    let weight = |r: usize, j: usize| -> i64 {
        let (pos, m) = (robots[r], &machines[j * MACHINE_DIM..(j + 1) * MACHINE_DIM]);
        let (dx, dy) = (m[0] - pos[0], m[1] - pos[1]);
        // Steps until the machine has a part: 0 when ready, the clock's count when known,
        // else MATCH_BUSY_STEPS.
        let wait = match (m[2] > 0.5, ready_in.get(j).copied().flatten()) {
            (true, _) => 0.0,
            (false, Some(t)) => t as f32,
            (false, None) => MATCH_BUSY_STEPS,
        };
        let travel = (dx * dx + dy * dy).sqrt() / step;
        let cost = travel + wait + lateness_weight * (travel - wait).max(0.0);
        -((cost * 1000.0).round() as i64)
    };
    // The solver wants no more rows than columns: rows are the smaller side.
    if robots.len() <= n_machines {
        let w = Matrix::from_fn(robots.len(), n_machines, |(r, j)| weight(r, j));
        let (_, machine_of_robot) = kuhn_munkres(&w);
        Some(machine_of_robot[0])
    } else {
        let w = Matrix::from_fn(n_machines, robots.len(), |(j, r)| weight(r, j));
        let (_, robot_of_machine) = kuhn_munkres(&w);
        robot_of_machine.iter().position(|&r| r == 0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::targets::{menu_size_ok, target};

    fn params() -> GreedyParams {
        GreedyParams {
            robot_radius: 0.05,
            machine_half: [0.1, 0.1],
            ..GreedyParams::default()
        }
    }

    const STORAGES: [f32; 4] = [-1.0, -1.0, 0.0, -0.4];

    #[test]
    fn the_matching_gives_each_free_robot_its_own_machine() {
        let p = params(); // 0.05 m per step
        let own = [0.0, 0.0, 0.0];
        // Two ready machines, right (0.5 m) and left (0.6 m). Alone: the nearer one.
        let two_ready = [0.5, 0.0, 1.0, -0.6, 0.0, 1.0];
        assert_eq!(matched_machine(&own, &two_ready, &[], &p, &[]), Some(0));
        // A free peer right next to the right machine takes it: this robot gets the left
        // one, where the claim rule would only have said "claimed".
        let peer_right = [0.45, 0.0, 0.0];
        assert_eq!(
            matched_machine(&own, &two_ready, &peer_right, &p, &[]),
            Some(1)
        );
        // A peer carrying a part is not matched.
        let loaded_right = [0.45, 0.0, 1.0];
        assert_eq!(
            matched_machine(&own, &two_ready, &loaded_right, &p, &[]),
            Some(0)
        );
        // Two free peers nearer to both machines: nothing left for this robot.
        let two_peers = [0.45, 0.0, 0.0, -0.55, 0.0, 0.0];
        assert_eq!(matched_machine(&own, &two_ready, &two_peers, &p, &[]), None);
        // Carrying a part: no machine; the menu entry then names the nearest storage.
        assert_eq!(
            matched_machine(&[0.0, 0.0, 1.0], &two_ready, &[], &p, &[]),
            None
        );
        assert_eq!(
            target(7, &[0.0, 0.0, 1.0], &two_ready, &STORAGES, &[], &p).map(|t| t.rel),
            Some([0.0, -0.4])
        );
        // A busy machine costs MATCH_BUSY_STEPS (0.5 m here): a busy one at 0.2 m loses to
        // a ready one at 0.6 m, a busy one at 0.05 m wins.
        let busy_near = [0.2, 0.0, 0.0, -0.6, 0.0, 1.0];
        assert_eq!(matched_machine(&own, &busy_near, &[], &p, &[]), Some(1));
        let busy_nearer = [0.05, 0.0, 0.0, -0.6, 0.0, 1.0];
        assert_eq!(matched_machine(&own, &busy_nearer, &[], &p, &[]), Some(0));
        // A timed busy machine costs its steps until ready (0.05 m per step here): at 0.2 m
        // (4 steps) with 3 steps left it beats the ready one at 0.6 m (12 steps), with 9
        // left it loses.
        let soon = [Some(3), Some(0)];
        assert_eq!(matched_machine(&own, &busy_near, &[], &p, &soon), Some(0));
        let late = [Some(9), Some(0)];
        assert_eq!(matched_machine(&own, &busy_near, &[], &p, &late), Some(1));
        // Unknown timer: MATCH_BUSY_STEPS again.
        assert_eq!(
            matched_machine(&own, &busy_near, &[], &p, &[None, Some(0)]),
            Some(1)
        );
        // Through the menu: entry 7 names the matched box; a 7-entry policy never asks.
        assert_eq!(
            target(7, &own, &two_ready, &STORAGES, &peer_right, &p).map(|t| t.rel),
            Some([-0.6, 0.0])
        );
        assert!(menu_size_ok(7) && menu_size_ok(8) && !menu_size_ok(6));
    }

    #[test]
    fn matching_minimizes_the_summed_cost() {
        let p = params();
        let own = [0.0, 0.0, 0.0];
        // A peer 1.0 m right; ready machines 0.9 m and 2.2 m right. Taking the cheapest pair
        // first (the peer to 0.9 m) would send this robot 2.2 m (total 2.3 m); the optimal
        // assignment sends it 0.9 m and the peer 1.2 m (total 2.1 m).
        let machines = [0.9, 0.0, 1.0, 2.2, 0.0, 1.0];
        let peer = [1.0, 0.0, 0.0];
        assert_eq!(matched_machine(&own, &machines, &peer, &p, &[]), Some(0));
        // Seen from the peer (this robot 1.0 m left of it) the matching is the same.
        let from_peer = [-0.1, 0.0, 1.0, 1.2, 0.0, 1.0];
        assert_eq!(
            matched_machine(&own, &from_peer, &[-1.0, 0.0, 0.0], &p, &[]),
            Some(1)
        );
        // More robots than machines: the one left out gets None.
        let one = [0.9, 0.0, 1.0];
        assert_eq!(matched_machine(&own, &one, &peer, &p, &[]), None);
        assert_eq!(matched_machine(&own, &[], &peer, &p, &[]), None);
    }

    #[test]
    fn matching_weighs_lateness_when_every_machine_gets_a_robot() {
        let p = params(); // 0.05 m per step
        let own = [0.0, 0.0, 0.0];
        // Machine 0 ready, 2 steps left of this robot; machine 1 ready in 15 steps, 2 steps
        // right. The peer is 10 steps from machine 0 and 14 from machine 1. Travel plus
        // wait alone: this robot to machine 1 (2 + 15 + 10 = 27 against 2 + 14 + 15 = 31),
        // leaving machine 0's part waiting 10 steps; with lateness it serves machine 0
        // (the peer arrives 1 step before machine 1's part).
        let machines = [-0.1, 0.0, 1.0, 0.1, 0.0, 0.0];
        let ready_in = [Some(0), Some(15)];
        let peer = [-0.6, 0.0, 0.0];
        assert_eq!(
            matched_machine(&own, &machines, &peer, &p, &ready_in),
            Some(0)
        );
        // A second peer next to machine 1 takes it whatever the weight: then this robot
        // serves machine 0 by either cost, and the far peer is left out.
        let peers = [-0.6, 0.0, 0.0, 0.15, 0.0, 0.0];
        assert_eq!(
            matched_machine(&own, &machines, &peers, &p, &ready_in),
            Some(0)
        );
        // Fewer robots than machines (a third, ready one 2 m away): no lateness term, so
        // the first case goes by travel plus wait again and this robot takes machine 1.
        let three = [-0.1, 0.0, 1.0, 0.1, 0.0, 0.0, 2.0, 0.0, 1.0];
        let ready3 = [Some(0), Some(15), Some(0)];
        assert_eq!(matched_machine(&own, &three, &peer, &p, &ready3), Some(1));
    }

    #[test]
    fn robots_agree_on_the_matching() {
        // Three free robots (absolute positions) and three machines: each robot runs the
        // matching from its own relative view; together they cover every machine once.
        let p = params();
        let robots = [[0.0f32, 0.0], [0.3, 0.1], [-0.4, 0.2]];
        let machines = [[0.2f32, 0.0, 1.0], [-0.5, 0.3, 0.0], [0.6, 0.6, 1.0]];
        let mut got = Vec::new();
        for (i, me) in robots.iter().enumerate() {
            let own = [me[0], me[1], 0.0];
            let rel_m: Vec<f32> = machines
                .iter()
                .flat_map(|m| [m[0] - me[0], m[1] - me[1], m[2]])
                .collect();
            let rel_p: Vec<f32> = robots
                .iter()
                .enumerate()
                .filter(|&(k, _)| k != i)
                .flat_map(|(_, q)| [q[0] - me[0], q[1] - me[1], 0.0])
                .collect();
            got.push(matched_machine(&own, &rel_m, &rel_p, &p, &[]).unwrap());
        }
        got.sort_unstable();
        assert_eq!(got, vec![0, 1, 2]);
    }
}
