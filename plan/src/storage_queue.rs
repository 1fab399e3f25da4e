//! Where a robot with a part delivers it: the storage area that gets it there soonest once
//! the queue is counted, and holding back from one that is full.
//!
//! Where the storages are the bottleneck (40.40_2, 80.40_4, 100.16_2), carriers heading
//! for the nearest storage jam it: the robots that have just placed their part are ringed
//! in by carriers pressing towards the box, no one moves, and the other storage area sits
//! half idle (docs/RESULTS.md 7.9 has the frames). Two rules, each computed by a robot
//! from its own observation (peer positions and part flags, storage positions), no
//! messages:
//! - choose the storage by travel steps plus [`QUEUE_STEPS_PER_CARRIER`] for every carrier
//!   nearer to it than this robot that is heading for it (by nearest storage);
//! - hold back (no target: the planner's make-room keeps the robot clear of the storage)
//!   while as many robots as the storage has room for along its edge are already near it.
//!
//! Used by the "matched" menu entry ([`crate::targets::TargetAction::Matched`]) for a
//! robot with a part; greedy and greedy-ORCA keep the nearest storage.

use crate::geom::box_distance;
use crate::greedy::GreedyParams;
use obs::{PEER_DIM, STORAGE_DIM};

/// Steps a carrier expects to wait per carrier ahead of it in a storage's queue. Screened
/// on seed 7 (20 episodes, always-matched script, with the hold below at one robot per
/// 4 radii of edge): 2 steps gave 40.40_2 136.6 parts, 80.40_4 236.6, 6.4_2 35.8,
/// 100.16_2 105.8; 4 steps 137.4 / 237.5 / 36.6 / 105.0 (without the choice: 109.3 /
/// 204.6 / 35.6 / 98.5). docs/RESULTS.md 7.9.
pub const QUEUE_STEPS_PER_CARRIER: f32 = 4.0;

/// A robot is near a storage while its centre is within this many robot radii of the
/// box's surface: the pick/place reach (one radius at default sizes) and a robot's width
/// behind it.
pub const NEAR_RADII: f32 = 4.0;

/// Room along a storage's edge per robot near it, in robot radii: a storage holds
/// `perimeter / (SLOT_RADII x radius)` robots near it, the perimeter taken two radii out
/// from the box. 4 radii (one robot per two diameters) screened best of 2.7, 4, 5.7 and 8
/// (seed 7: 40.40_2 126.9 / 136.6 / 132.6 / 122.8 parts with a 2-step queue cost;
/// 8 radii also cost 100.16_2 and 100.8_1 5-13 %). docs/RESULTS.md 7.9.
pub const SLOT_RADII: f32 = 4.0;

/// Robots a storage area has room for near its edge ([`SLOT_RADII`]), at least one.
pub fn storage_capacity(p: &GreedyParams) -> usize {
    let r = p.robot_radius;
    let [hx, hy] = p.storage_half;
    let perimeter = 4.0 * (hx + hy) + std::f32::consts::TAU * 2.0 * r;
    ((perimeter / (SLOT_RADII * r)).floor() as usize).max(1)
}

/// A carrier keeps the storage it chose unless another one's queue-counted trip is
/// shorter by more than this many steps (one carrier's worth of queue). Without it the
/// choice flipped whenever the two costs crossed as carriers came and went: at 20.10_4
/// (seed 7, 10 episodes, always "matched") 493 storage flips in 10,357 carrying steps,
/// against 22 for the nearest storage; with it 107 (with 8 steps: 40, but -0.5 to -3 % of
/// the parts). A flip reverses a robot its peers' ORCA expected to go on. docs/RESULTS.md 7.9.
pub const SWITCH_STEPS: f32 = QUEUE_STEPS_PER_CARRIER;

/// What a carrier remembers between decisions: the storage it is heading for, by absolute
/// centre (relative positions move with the robot). Cleared when it has no part or asks
/// for another menu entry; [`crate::orca::GreedyOrca`] holds one per robot.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StorageMemory(Option<[f32; 2]>);

impl StorageMemory {
    pub fn clear(&mut self) {
        self.0 = None;
    }
}

/// Index (in the observation) of the storage a robot with a part should head for: fewest
/// travel steps at K_speed plus [`QUEUE_STEPS_PER_CARRIER`] per carrier ahead in its
/// queue. A carrier is in storage k's queue when k is its nearest storage, and ahead when
/// it is nearer to k than this robot. None without storages. Ties: observation order.
/// Stateless: see [`queued_storage_kept`] for the choice a robot sticks to.
pub fn queued_storage(storages: &[f32], peers: &[f32], p: &GreedyParams) -> Option<usize> {
    queue_costs(storages, peers, p)
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, k)| k)
}

/// [`queued_storage`], but the storage in `memory` (if still observed) is kept unless
/// another is cheaper by more than [`SWITCH_STEPS`]; the choice is written back. `own`:
/// this robot's observation row (absolute position first).
pub fn queued_storage_kept(
    own: &[f32],
    storages: &[f32],
    peers: &[f32],
    p: &GreedyParams,
    memory: &mut StorageMemory,
) -> Option<usize> {
    let abs = |k: usize| {
        [
            own[0] + storages[k * STORAGE_DIM],
            own[1] + storages[k * STORAGE_DIM + 1],
        ]
    };
    let mut best: Option<(f32, usize)> = None;
    let mut kept: Option<(f32, usize)> = None;
    for (cost, k) in queue_costs(storages, peers, p) {
        if best.is_none_or(|(b, _)| cost < b) {
            best = Some((cost, k));
        }
        if let Some(m) = memory.0 {
            let a = abs(k);
            // The same box seen from a moved robot: equal up to float rounding.
            if (a[0] - m[0]).abs() < 1e-3 && (a[1] - m[1]).abs() < 1e-3 {
                kept = Some((cost, k));
            }
        }
    }
    let choice = match (best, kept) {
        (Some((b, _)), Some((c, k))) if c <= b + SWITCH_STEPS => Some(k),
        (b, _) => b.map(|(_, k)| k),
    };
    memory.0 = choice.map(abs);
    choice
}

/// (queue-counted trip in steps, storage index) for every observed storage.
fn queue_costs<'a>(
    storages: &'a [f32],
    peers: &'a [f32],
    p: &GreedyParams,
) -> impl Iterator<Item = (f32, usize)> + 'a {
    let n = storages.len() / STORAGE_DIM;
    let d2 = |k: usize, x: f32, y: f32| {
        let (dx, dy) = (
            storages[k * STORAGE_DIM] - x,
            storages[k * STORAGE_DIM + 1] - y,
        );
        dx * dx + dy * dy
    };
    // Each carrier's nearest storage and its squared distance, then count per storage
    // those nearer than this robot (at the origin).
    let mut ahead = vec![0u32; n];
    for q in peers.chunks_exact(PEER_DIM).filter(|q| q[2] > 0.5) {
        let nearest = (0..n)
            .map(|k| (d2(k, q[0], q[1]), k))
            .min_by(|a, b| a.0.total_cmp(&b.0));
        if let Some((dq, k)) = nearest {
            if dq < d2(k, 0.0, 0.0) {
                ahead[k] += 1;
            }
        }
    }
    let step = p.k_speed * p.dt;
    (0..n).map(move |k| {
        let travel = d2(k, 0.0, 0.0).sqrt() / step;
        (travel + QUEUE_STEPS_PER_CARRIER * ahead[k] as f32, k)
    })
}

/// Whether a robot with a part should hold back from the storage at `rel` (its centre
/// relative to the robot): it is not near the storage itself ([`NEAR_RADII`]) and at
/// least [`storage_capacity`] observed peers, with a part or not, already are.
pub fn storage_full(rel: [f32; 2], peers: &[f32], p: &GreedyParams) -> bool {
    let near = NEAR_RADII * p.robot_radius;
    // Negative inside the box; every test here is "within `near`", so that is harmless.
    if box_distance(rel, p.storage_half, [0.0, 0.0]) <= near {
        return false;
    }
    let near_peers = peers
        .chunks_exact(PEER_DIM)
        .filter(|q| box_distance(rel, p.storage_half, [q[0], q[1]]) <= near)
        .count();
    near_peers >= storage_capacity(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> GreedyParams {
        GreedyParams {
            robot_radius: 0.05,
            storage_half: [0.1, 0.05],
            ..GreedyParams::default()
        }
    }

    fn carrier(x: f32, y: f32) -> [f32; 3] {
        [x, y, 1.0]
    }

    #[test]
    fn capacity_counts_the_edge_in_robot_widths() {
        // Perimeter 4 x 0.15 + 2 pi x 0.1 = 1.228 m; 4 radii = 0.2 m per robot: 6.
        assert_eq!(storage_capacity(&params()), 6);
        let tiny = GreedyParams {
            robot_radius: 1.0,
            storage_half: [0.01, 0.01],
            ..params()
        };
        assert_eq!(storage_capacity(&tiny), 3);
    }

    #[test]
    fn the_nearer_storage_unless_its_queue_is_longer() {
        let p = params();
        // Storage 0 at 0.3 m (6 steps at 5 cm), storage 1 at 0.5 m (10 steps).
        let storages = [0.3, 0.0, -0.5, 0.0];
        assert_eq!(queued_storage(&storages, &[], &p), Some(0));
        // One carrier ahead at storage 0: 6 + 4 = 10, a tie, observation order keeps 0.
        let one: Vec<f32> = carrier(0.25, 0.0).to_vec();
        assert_eq!(queued_storage(&storages, &one, &p), Some(0));
        // Two ahead: 14 > 10, go to storage 1.
        let two: Vec<f32> = [carrier(0.25, 0.0), carrier(0.28, 0.02)].concat();
        assert_eq!(queued_storage(&storages, &two, &p), Some(1));
        // Carriers behind this robot (farther from storage 0) or part-less robots ahead
        // are not in its way.
        let behind: Vec<f32> = [carrier(0.7, 0.0), carrier(0.8, 0.0)].concat();
        assert_eq!(queued_storage(&storages, &behind, &p), Some(0));
        let empty_handed: Vec<f32> = [[0.25, 0.0, 0.0], [0.28, 0.02, 0.0]].concat();
        assert_eq!(queued_storage(&storages, &empty_handed, &p), Some(0));
        assert_eq!(queued_storage(&[], &two, &p), None);
    }

    #[test]
    fn a_carrier_keeps_its_storage_until_another_is_clearly_better() {
        let p = params();
        // Robot at (0, 0); storage 0 at 0.3 m (6 steps), storage 1 at 0.5 m (10 steps).
        let own = [0.0, 0.0, 1.0];
        let storages = [0.3, 0.0, -0.5, 0.0];
        let mut memory = StorageMemory::default();
        let two: Vec<f32> = [carrier(0.25, 0.0), carrier(0.28, 0.02)].concat();
        // Two ahead at storage 0: 14 against 10, so storage 1, remembered.
        assert_eq!(
            queued_storage_kept(&own, &storages, &two, &p, &mut memory),
            Some(1)
        );
        // The queue empties: storage 0 costs 6 against 10, within SWITCH_STEPS of it: keep 1.
        assert_eq!(
            queued_storage_kept(&own, &storages, &[], &p, &mut memory),
            Some(1)
        );
        assert_eq!(queued_storage(&storages, &[], &p), Some(0));
        // Seen after a move of 0.1 m to the left (relative positions shift): still 1.
        let moved = [-0.1, 0.0, 1.0];
        let storages_moved = [0.4, 0.0, -0.4, 0.0];
        assert_eq!(
            queued_storage_kept(&moved, &storages_moved, &[], &p, &mut memory),
            Some(1)
        );
        // Back at (0, 0) with storage 0 just ahead (0.05 m, 1 step) against storage 1's
        // 10: better by more than SWITCH_STEPS, switch.
        let near = [0.05, 0.0, -0.5, 0.0];
        assert_eq!(
            queued_storage_kept(&own, &near, &[], &p, &mut memory),
            Some(0)
        );
        memory.clear();
        assert_eq!(
            queued_storage_kept(&own, &storages, &two, &p, &mut memory),
            Some(1)
        );
    }

    #[test]
    fn hold_back_only_from_outside_a_full_storage() {
        let p = params();
        let cap = storage_capacity(&p);
        let storage = [1.0, 0.0];
        // `cap` peers just right of the box's left edge... placed along its top edge.
        let ring: Vec<f32> = (0..cap)
            .flat_map(|i| [0.9 + 0.04 * i as f32, 0.1, 0.0])
            .collect();
        assert!(storage_full(storage, &ring, &p));
        assert!(!storage_full(storage, &ring[..(cap - 1) * 3], &p));
        // This robot near the storage itself: it goes on and places.
        assert!(!storage_full([0.2, 0.0], &ring, &p));
        // Peers far from the storage do not count.
        let far: Vec<f32> = (0..cap)
            .flat_map(|i| [0.0, 0.3 + 0.1 * i as f32, 1.0])
            .collect();
        assert!(!storage_full(storage, &far, &p));
    }
}
