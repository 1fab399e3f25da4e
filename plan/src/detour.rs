//! Going around a box instead of pressing into it.
//!
//! The planner drives straight for its target and leaves the rest to ORCA. ORCA only
//! forbids moving *into* an obstacle: when the straight line runs into a box, the
//! preferred velocity points at its face and ORCA's nearest allowed velocity is about zero,
//! so the robot stops there for good. Counted with `policy/examples/stuck_carriers.rs`
//! (seed 0 x 50 episodes, docs/RESULTS.md 7.10): before this, a carrier stood still for
//! 40+ steps in 12 (greedy-ORCA) and 16 (the bundled policy) of 50 episodes at 6.4_2, 50
//! and 41 at 42.28_14, typically right beside the machine it had just picked from, whose
//! far side faced the storage.
//!
//! The planner (`crate::orca::GreedyOrca`) calls it only once a robot has been stuck at a
//! box for `STUCK_STEPS`, and then for `DETOUR_STEPS`: going for corners whenever a line met a
//! grown box lengthened paths that ORCA's slide along a face handles well (-3 % parts).
//!
//! [`waypoint`] gives the point to head for instead: the goal when the straight segment
//! misses every box (grown by the robot's obstacle margin), else the farthest point in
//! straight sight along a shortest grid path (A*) to a reachable stand-off point of the
//! target (docs/adr/0025-detour-by-grid-path.md). The first version went for one box
//! corner at a time; it sent robots into gaps their margin closes and at stand-off points
//! inside another box's margin, where they stayed for the rest of the episode. A grid of
//! half-radius cells over a room of a few metres is a few thousand cells, searched only on
//! detour steps.

use crate::geom::box_distance;

/// Grid cell side, in robot radii: a gap the margin closes (narrower than two margins,
/// about 2.6 radii) has no free cell centre in it.
const CELL_RADII: f32 = 0.5;
/// Cells this close (Chebyshev, in cells) to the robot's own are free when they are at
/// least as clear of every box as the robot is: a robot pushed inside a box's margin can
/// leave it, but not by pressing further in.
const START_FREE_CELLS: i64 = 2;

/// Where a robot is going: a point at `stand_off` from its target box, the nearest such
/// point first (robot frame: the robot at the origin).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Goal {
    pub point: [f32; 2],
    /// (centre, half) of the target box.
    pub target: ([f32; 2], [f32; 2]),
    /// Distance from the target box at which the robot stops (it picks or places there).
    pub stand_off: f32,
}

/// Where a robot at the origin heads for on its way to `goal`. `boxes`: (centre, half)
/// of everything it must go around, the target box included. `margin`: how far from a
/// box or wall the robot's centre keeps (radius + clearance). `room`: (robot's own
/// absolute position, room half size).
///
/// The goal's point itself when the straight segment to it misses every box (grown by the
/// margin, but never around the robot itself: it may stand inside a margin). Otherwise a
/// shortest path on a grid of half-radius cells whose centres keep the margin to every box
/// and wall (A*, the `pathfinding` crate) to any such cell within the stand-off of the
/// target box (the nearest stand-off point may be in another box's margin, e.g. a storage
/// face a machine stands in front of), pulled taut: the farthest point of that path the
/// robot can reach in a straight line. A gap too narrow for the margin has no free cell,
/// so it is never taken; walls and clusters of boxes need no special case. Stateless:
/// recomputed every step of a detour. No path (boxed in): the goal's point, as without a
/// detour.
pub fn waypoint(
    goal: Goal,
    boxes: &[([f32; 2], [f32; 2])],
    margin: f32,
    radius: f32,
    room: ([f32; 2], f32),
) -> [f32; 2] {
    let grown: Vec<([f32; 2], [f32; 2])> = boxes
        .iter()
        .map(|&(c, h)| {
            // grown to just short of the robot, measured per axis: the grown rectangle
            // must not contain the robot (a Euclidean cap would, diagonal to a corner)
            let dx = (c[0].abs() - h[0]).max(0.0);
            let dy = (c[1].abs() - h[1]).max(0.0);
            let g = margin.min(dx.max(dy) - 1e-3).max(0.0);
            (c, [h[0] + g, h[1] + g])
        })
        .collect();
    if first_blocking(goal.point, &grown).is_none() {
        return goal.point;
    }
    let Some(path) = grid_path(goal, boxes, margin, radius, room) else {
        return goal.point;
    };
    // the farthest path point in straight sight (the path's first step always is)
    path.iter()
        .rev()
        .find(|&&p| first_blocking(p, &grown).is_none())
        .copied()
        .unwrap_or(path[0])
}

/// A shortest 8-connected grid path from the origin (points after the start) to a cell
/// within `goal.stand_off` (plus most of a cell) of the target box, through cell centres
/// at least `margin` from every box and wall.
fn grid_path(
    goal: Goal,
    boxes: &[([f32; 2], [f32; 2])],
    margin: f32,
    radius: f32,
    room: ([f32; 2], f32),
) -> Option<Vec<[f32; 2]>> {
    let cell = CELL_RADII * radius;
    let (own, room_half) = room;
    // cell (i, j) has its centre at (i, j) * cell: the robot is cell (0, 0)
    let centre = |(i, j): (i64, i64)| [i as f32 * cell, j as f32 * cell];
    let (tc, th) = goal.target;
    // a band at least a cell wide, so that some cell centres fall in it
    let arrive = goal.stand_off.max(margin) + 0.75 * cell;
    let clearance = |p: [f32; 2]| {
        boxes
            .iter()
            .map(|&(c, h)| box_distance(c, h, p))
            .fold(f32::INFINITY, f32::min)
    };
    let own_clear = clearance([0.0, 0.0]).min(margin);
    let free = |ij: (i64, i64)| {
        let p = centre(ij);
        let (x, y) = (own[0] + p[0], own[1] + p[1]);
        let wall = room_half - margin;
        if x.abs() > wall || y.abs() > wall {
            return false;
        }
        let clear = clearance(p);
        if ij.0.abs() <= START_FREE_CELLS && ij.1.abs() <= START_FREE_CELLS {
            return clear >= own_clear - 1e-4;
        }
        clear >= margin
    };
    // integer costs: 10 a cell straight, 14 diagonal; the heuristic (straight-line
    // distance to the arrival band, in tenths of a cell) never overestimates
    let (cells, _) = pathfinding::directed::astar::astar(
        &(0i64, 0i64),
        |&(i, j)| {
            [
                (1, 0),
                (-1, 0),
                (0, 1),
                (0, -1),
                (1, 1),
                (1, -1),
                (-1, 1),
                (-1, -1),
            ]
            .into_iter()
            .map(move |(di, dj): (i64, i64)| {
                ((i + di, j + dj), if di != 0 && dj != 0 { 14 } else { 10 })
            })
            .filter(|&(n, _)| free(n))
        },
        |&c| ((box_distance(tc, th, centre(c)) - arrive).max(0.0) / cell * 10.0) as i64,
        |&c| box_distance(tc, th, centre(c)) <= arrive,
    )?;
    Some(cells.into_iter().skip(1).map(centre).collect()).filter(|p: &Vec<_>| !p.is_empty())
}

/// The grown box (index) the segment origin -> `to` enters first.
fn first_blocking(to: [f32; 2], grown: &[([f32; 2], [f32; 2])]) -> Option<usize> {
    let mut first: Option<(f32, usize)> = None;
    for (i, &(c, g)) in grown.iter().enumerate() {
        if let Some(t) = segment_enters(to, c, g) {
            if first.is_none_or(|(b, _)| t < b) {
                first = Some((t, i));
            }
        }
    }
    first.map(|(_, i)| i)
}

/// Where (fraction of the segment origin -> `to`) the segment enters the open box
/// (`c`, `h`), if it does (slab test). Touching an edge does not count.
fn segment_enters(to: [f32; 2], c: [f32; 2], h: [f32; 2]) -> Option<f32> {
    let (mut t0, mut t1) = (0.0f32, 1.0f32);
    for k in 0..2 {
        let (lo, hi) = (c[k] - h[k], c[k] + h[k]);
        if to[k].abs() < 1e-9 {
            if 0.0 <= lo || 0.0 >= hi {
                return None;
            }
            continue;
        }
        let (a, b) = ((lo) / to[k], (hi) / to[k]);
        let (a, b) = if a < b { (a, b) } else { (b, a) };
        t0 = t0.max(a);
        t1 = t1.min(b);
    }
    // a strictly positive length inside, so grazing a corner or an edge is not blocking
    (t1 - t0 > 1e-6).then_some(t0)
}

#[cfg(test)]
mod tests {
    use super::*;

    const ROOM: ([f32; 2], f32) = ([0.0, 0.0], 10.0);

    /// A goal point in free space: a target box of no size there, no stand-off.
    fn at(p: [f32; 2]) -> Goal {
        Goal {
            point: p,
            target: (p, [0.0, 0.0]),
            stand_off: 0.0,
        }
    }

    /// The goal at `stand_off` from box (`c`, `h`), nearest point first, as the planner
    /// sets it.
    fn towards(c: [f32; 2], h: [f32; 2], stand_off: f32) -> Goal {
        let q = crate::geom::nearest_on_box(c, h, [0.0, 0.0]);
        let d = (q[0] * q[0] + q[1] * q[1]).sqrt();
        Goal {
            point: [q[0] * (d - stand_off) / d, q[1] * (d - stand_off) / d],
            target: (c, h),
            stand_off,
        }
    }

    #[test]
    fn a_clear_line_goes_straight() {
        let boxes = [([0.0, 1.0], [0.1, 0.1])];
        assert_eq!(
            waypoint(at([1.0, 0.0]), &boxes, 0.1, 0.05, ROOM),
            [1.0, 0.0]
        );
    }

    #[test]
    fn a_box_in_the_way_is_passed_at_its_nearer_corner() {
        // box centred on the line, a little above it: around below is shorter
        let boxes = [([1.0, 0.05], [0.2, 0.2])];
        let w = waypoint(at([2.0, 0.0]), &boxes, 0.1, 0.08, ROOM);
        assert!(w[0] > 0.6 && w[0] < 0.8, "{w:?}");
        assert!(w[1] < -0.25, "below the box: {w:?}");
        // from there the line to the goal is clear of the grown box
        let from_w: Vec<_> = boxes
            .iter()
            .map(|&(c, h)| ([c[0] - w[0], c[1] - w[1]], h))
            .collect();
        let g = [2.0 - w[0], 0.0 - w[1]];
        let second = waypoint(at(g), &from_w, 0.1, 0.08, ROOM);
        assert!(
            (second[0] - g[0]).abs() < 1e-6 || second[0] > 0.0,
            "{second:?}"
        );
    }

    #[test]
    fn the_box_just_left_is_gone_around_not_pressed_into() {
        // the robot touches the left face of a box (closer than the margin); the goal is
        // straight through it on the right
        let boxes = [([0.15, 0.0], [0.1, 0.1])];
        let w = waypoint(at([0.5, 0.0]), &boxes, 0.12, 0.05, ROOM);
        assert!(w[1].abs() > 0.1, "around the box: {w:?}");
    }

    #[test]
    fn a_gap_too_narrow_for_the_margin_is_not_taken() {
        // two boxes side by side with a 0.1 gap; margin 0.1 closes it. The goal is above
        // the gap; the robot is below the left box.
        let boxes = [([-0.2, 0.5], [0.15, 0.15]), ([0.2, 0.5], [0.15, 0.15])];
        let w = waypoint(at([0.0, 1.0]), &boxes, 0.1, 0.05, ROOM);
        // beyond the pair's outer faces (x = +-0.35)
        assert!(w[0].abs() > 0.35, "around the outside of the pair: {w:?}");
    }

    #[test]
    fn a_robot_diagonal_to_a_corner_is_not_inside_its_grown_box() {
        // 2.8_1, seed 0, episode 16: a carrier at the mouth of a gap between two machines
        // narrower than two margins, within the margin of both; the storage is up and to
        // the right. The corner rule before the grid path grew each box only to the
        // robot's Euclidean distance, so the robot stood inside the right box's grown
        // rectangle and was sent up into the gap for 180 steps.
        let storage = ([0.289, 0.809], [0.15, 0.08]);
        let mut boxes = vec![
            ([0.215, 0.164], [0.12, 0.12]),
            ([-0.225, 0.127], [0.12, 0.12]),
        ];
        boxes.push(storage);
        let goal = towards(storage.0, storage.1, 0.1325);
        let w = waypoint(goal, &boxes, 0.105, 0.08, ([0.175, -0.263], 1.15));
        // the gap is straight up: any way round starts sideways or down
        assert!(w[1] <= 0.0, "not up into the gap: {w:?}");
    }

    #[test]
    fn an_approach_in_another_box_margin_is_not_aimed_at() {
        // 2.8_1, seed 0, episode 2: the carrier's nearest stand-off point at the storage
        // (straight up) lies between a machine and the storage, 0.213 m apart, in the
        // machine's margin; the straight line there runs into the machine. The path ends
        // at another stand-off point of the storage, round the machine.
        let storage = ([0.150, 0.638], [0.15, 0.08]);
        let machine = ([0.060, 0.225], [0.12, 0.12]);
        let goal = towards(storage.0, storage.1, 0.1325);
        assert!(goal.point[0].abs() < 1e-3, "straight up: {goal:?}");
        let w = waypoint(
            goal,
            &[machine, storage],
            0.105,
            0.08,
            ([-0.006, 0.027], 1.15),
        );
        assert!(
            w[0].abs() > 0.05,
            "round the machine, not up into it: {w:?}"
        );
    }

    #[test]
    fn walls_are_kept_to() {
        // box against the left wall: only the right side is open
        let room = ([-0.7, 0.0], 1.0);
        let boxes = [([-0.1, 0.3], [0.2, 0.1])];
        let w = waypoint(at([-0.1, 0.6]), &boxes, 0.1, 0.08, room);
        assert!(w[0] > 0.0, "right of the box: {w:?}");
    }
}
