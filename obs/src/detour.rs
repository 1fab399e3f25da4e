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
//! misses every box (grown by the robot's obstacle margin), else the corner of the first
//! box in the way with the shortest path robot -> corner -> goal, skipping corners inside
//! another grown box or out of the room, so a gap too narrow to pass is not taken. It is
//! stateless: once past the corner, the line to the goal clears and the robot heads
//! straight for it. A visibility-graph search over every box would find whole paths; one
//! corner at a time, recomputed every step, is what this needs: rooms of a few boxes per
//! robot's neighbourhood, with no walls of boxes to get lost in.

use crate::geom::{box_distance, norm};

/// Corners are taken this fraction of a robot radius outside the grown box, so a robot at
/// one is past it, not on its edge.
const CORNER_OUT_RADII: f32 = 0.25;
/// Corners of at most this many boxes in a row (a corner whose own line is blocked).
const MAX_LEGS: usize = 3;

/// Where a robot at the origin heads for on its way to `goal` (same frame). `boxes`:
/// (centre, half) of everything it must go around, the goal's own box included (the
/// segment to a point on that box's surface does not cross it). `margin`: how far from a
/// box the robot's centre keeps (radius + clearance); a box the robot is already closer to
/// is grown only to just short of the robot. `room`: (robot's own absolute position, room
/// half size): corners must keep `radius` inside the walls.
pub fn waypoint(
    goal: [f32; 2],
    boxes: &[([f32; 2], [f32; 2])],
    margin: f32,
    radius: f32,
    room: ([f32; 2], f32),
) -> [f32; 2] {
    // never grown around the robot itself: it may stand inside the margin
    let grown: Vec<([f32; 2], [f32; 2])> = boxes
        .iter()
        .map(|&(c, h)| {
            let g = margin.min(box_distance(c, h, [0.0, 0.0]) - 1e-3).max(0.0);
            (c, [h[0] + g, h[1] + g])
        })
        .collect();
    let out = CORNER_OUT_RADII * radius;
    let (own, room_half) = room;
    let inside_room = |p: [f32; 2]| {
        let (x, y) = (own[0] + p[0], own[1] + p[1]);
        x.abs() <= room_half - radius && y.abs() <= room_half - radius
    };
    let mut to = goal;
    for _ in 0..MAX_LEGS {
        let Some(i) = first_blocking(to, &grown) else {
            return to;
        };
        // Boxes whose grown areas touch form one obstacle (a gap the margin closes is no
        // way through): go around their bounding box, unless the robot stands inside it
        // (between them), where only the blocking box's own corners make sense.
        let cluster = touching(i, &grown);
        let (lo, hi) = bounds(cluster.iter().map(|&j| grown[j]));
        let robot_inside = lo[0] < 0.0 && 0.0 < hi[0] && lo[1] < 0.0 && 0.0 < hi[1];
        let (lo, hi, around) = if robot_inside {
            let (c, h) = grown[i];
            (
                [c[0] - h[0], c[1] - h[1]],
                [c[0] + h[0], c[1] + h[1]],
                vec![i],
            )
        } else {
            (lo, hi, cluster)
        };
        let free = |p: [f32; 2]| {
            grown.iter().enumerate().all(|(j, &(c, h))| {
                around.contains(&j) || (p[0] - c[0]).abs() >= h[0] || (p[1] - c[1]).abs() >= h[1]
            })
        };
        let best = [
            [lo[0] - out, lo[1] - out],
            [hi[0] + out, lo[1] - out],
            [hi[0] + out, hi[1] + out],
            [lo[0] - out, hi[1] + out],
        ]
        .into_iter()
        // a corner the robot is at is passed: the next one is the way on
        .filter(|&p| norm(p) > 2.0 * out && inside_room(p) && free(p))
        .map(|p| (norm(p) + norm([goal[0] - p[0], goal[1] - p[1]]), p))
        .min_by(|a, b| a.0.total_cmp(&b.0));
        match best {
            Some((_, p)) => to = p,
            // boxed in on every side: the straight line, as before
            None => return goal,
        }
    }
    to
}

/// Indices of the grown boxes connected to box `i` by overlap (flood fill).
fn touching(i: usize, grown: &[([f32; 2], [f32; 2])]) -> Vec<usize> {
    let overlap = |a: ([f32; 2], [f32; 2]), b: ([f32; 2], [f32; 2])| {
        (a.0[0] - b.0[0]).abs() <= a.1[0] + b.1[0] && (a.0[1] - b.0[1]).abs() <= a.1[1] + b.1[1]
    };
    let mut cluster = vec![i];
    let mut k = 0;
    while k < cluster.len() {
        let a = grown[cluster[k]];
        for (j, &b) in grown.iter().enumerate() {
            if !cluster.contains(&j) && overlap(a, b) {
                cluster.push(j);
            }
        }
        k += 1;
    }
    cluster
}

/// Bounding box (min corner, max corner) of boxes given by centre and half size.
fn bounds(boxes: impl Iterator<Item = ([f32; 2], [f32; 2])>) -> ([f32; 2], [f32; 2]) {
    boxes.fold(
        ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]),
        |(lo, hi), (c, h)| {
            (
                [lo[0].min(c[0] - h[0]), lo[1].min(c[1] - h[1])],
                [hi[0].max(c[0] + h[0]), hi[1].max(c[1] + h[1])],
            )
        },
    )
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

    #[test]
    fn a_clear_line_goes_straight() {
        let boxes = [([0.0, 1.0], [0.1, 0.1])];
        assert_eq!(waypoint([1.0, 0.0], &boxes, 0.1, 0.05, ROOM), [1.0, 0.0]);
    }

    #[test]
    fn a_box_in_the_way_is_passed_at_its_nearer_corner() {
        // box centred on the line, a little above it: around below is shorter
        let boxes = [([1.0, 0.05], [0.2, 0.2])];
        let w = waypoint([2.0, 0.0], &boxes, 0.1, 0.08, ROOM);
        assert!(w[0] > 0.6 && w[0] < 0.8, "{w:?}");
        assert!(w[1] < -0.25, "below the box: {w:?}");
        // from there the line to the goal is clear of the grown box
        let from_w: Vec<_> = boxes
            .iter()
            .map(|&(c, h)| ([c[0] - w[0], c[1] - w[1]], h))
            .collect();
        let g = [2.0 - w[0], 0.0 - w[1]];
        let second = waypoint(g, &from_w, 0.1, 0.08, ROOM);
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
        let w = waypoint([0.5, 0.0], &boxes, 0.12, 0.05, ROOM);
        assert!(w[1].abs() > 0.1, "around the box: {w:?}");
    }

    #[test]
    fn a_gap_too_narrow_for_the_margin_is_not_taken() {
        // two boxes side by side with a 0.1 gap; margin 0.1 closes it. The goal is above
        // the gap; the robot is below the left box.
        let boxes = [([-0.2, 0.5], [0.15, 0.15]), ([0.2, 0.5], [0.15, 0.15])];
        let w = waypoint([0.0, 1.0], &boxes, 0.1, 0.05, ROOM);
        assert!(w[0].abs() > 0.45, "around the outside of the pair: {w:?}");
    }

    #[test]
    fn corners_outside_the_room_are_not_used() {
        // box against the left wall: only the right side is open
        let room = ([-0.7, 0.0], 1.0);
        let boxes = [([-0.1, 0.3], [0.2, 0.1])];
        let w = waypoint([-0.1, 0.6], &boxes, 0.1, 0.08, room);
        assert!(w[0] > 0.0, "right of the box: {w:?}");
    }
}
