//! The preferred velocity of [`GreedyOrca`]: where the robot wants to go before ORCA
//! filters it. Greedy's box or a target action's (`crate::targets`), straight for a point
//! inside reach; with nowhere to go, out of an obstacle's margin or out of a storage
//! area's way (make-room); once stuck at a box, round it (`crate::detour`).

use super::{observed_boxes, GreedyOrca, DETOUR_STEPS, STUCK_BOX_RADII, STUCK_STEPS};
use crate::geom::{box_distance, nearest_on_box, norm};
use crate::greedy::{greedy_target, Target};
use crate::targets;

impl GreedyOrca {
    /// Greedy's preferred velocity: [`Self::preferred_towards`] the [`greedy_target`] box.
    pub fn greedy_preferred(
        &self,
        own: &[f32],
        machines: &[f32],
        storages: &[f32],
        peers: &[f32],
    ) -> [f32; 2] {
        let t = greedy_target(own, machines, storages, peers, &self.params.greedy);
        self.preferred_or_make_room(t, own, machines, storages)
    }

    /// A target action's preferred velocity (`crate::targets`): [`Self::preferred_towards`]
    /// the box it names on this row; zero for "stay" or a box that does not exist.
    pub fn target_preferred(
        &mut self,
        action: u8,
        own: &[f32],
        machines: &[f32],
        storages: &[f32],
        peers: &[f32],
    ) -> [f32; 2] {
        self.clock.update(own, machines, obs::MACHINE_DIM);
        let t = targets::target_kept(
            action,
            own,
            machines,
            storages,
            peers,
            &self.params.greedy,
            targets::PlannerMemory {
                storage: &mut self.storage_memory,
                ready_in: self.clock.ready_in(),
            },
        );
        let pref = self.preferred_or_make_room(t, own, machines, storages);
        self.note_progress(own, machines, storages, pref);
        pref
    }

    /// Once per step, after planning `pref`: count the steps the robot has not moved
    /// although it wanted to, at a box, and start a detour ([`crate::detour`]) after
    /// [`STUCK_STEPS`] of them.
    pub(super) fn note_progress(
        &mut self,
        own: &[f32],
        machines: &[f32],
        storages: &[f32],
        pref: [f32; 2],
    ) {
        let g = &self.params.greedy;
        let (r, k) = (g.robot_radius, g.k_speed);
        let pos = [own[0], own[1]];
        // a jump of more than two full steps is a reset or a teleport, not progress
        let moved = self
            .planned_from
            .map(|q| norm([pos[0] - q[0], pos[1] - q[1]]))
            .filter(|&d| d <= 2.0 * k * g.dt);
        self.planned_from = Some(pos);
        // stuck *at a box*: a robot held up by peers waits for them instead
        let at_box = || {
            let reach = r + self.box_clearance() + STUCK_BOX_RADII * r;
            observed_boxes(machines, storages, g)
                .any(|(c, h)| box_distance(c, h, [0.0, 0.0]) < reach)
        };
        let wanted = pref[0].is_finite() && pref[1].is_finite() && norm(pref) > 0.5 * k;
        if moved.is_some_and(|d| d < 0.1 * k * g.dt) && wanted && at_box() {
            self.stuck_steps += 1;
        } else {
            self.stuck_steps = 0;
        }
        if self.stuck_steps >= STUCK_STEPS {
            self.stuck_steps = 0;
            self.detour_left = DETOUR_STEPS;
        } else {
            self.detour_left = self.detour_left.saturating_sub(1);
        }
    }

    /// [`Self::preferred_towards`] `target`. With no target: out of an obstacle's margin
    /// first ([`Self::keep_off`]), else [`Self::make_room`]. The order matters in real
    /// time: backing out from a storage next to a wall, ORCA stops a robot at the wall's
    /// margin, a late command carries it on into contact, and make-room alone kept it
    /// pressed there for a whole main-job run.
    fn preferred_or_make_room(
        &self,
        target: Option<Target>,
        own: &[f32],
        machines: &[f32],
        storages: &[f32],
    ) -> [f32; 2] {
        match target {
            None => self
                .keep_off(own, machines, storages)
                .or_else(|| self.make_room(storages))
                .unwrap_or([0.0, 0.0]),
            t => self.preferred_towards(t, own, machines, storages),
        }
    }

    /// Velocity straight away from the nearest wall or box while the robot's centre is
    /// closer to it than ORCA's obstacle margin (robot radius + box clearance), stopping
    /// at the margin; None when nothing is that close. For a robot with nowhere to go:
    /// ORCA only forbids moving *into* an obstacle, so a robot at rest inside the margin
    /// stays where it is; in a real-time fleet one that a late command had carried to
    /// touching a wall stayed touching it for the rest of the run (135 contact steps in
    /// about one main-job run of ten; never offline, where ORCA's stop is exact).
    pub fn keep_off(&self, own: &[f32], machines: &[f32], storages: &[f32]) -> Option<[f32; 2]> {
        let p = &self.params;
        let g = &p.greedy;
        let margin = g.robot_radius + self.box_clearance();
        // (centre-to-surface distance, unit direction away from the surface)
        let mut nearest: Option<(f32, [f32; 2])> = None;
        let mut consider = |d: f32, away: [f32; 2]| {
            if d < margin && nearest.is_none_or(|(b, _)| d < b) {
                nearest = Some((d, away));
            }
        };
        let (x, y) = (own[0], own[1]);
        consider(p.room_half - x, [-1.0, 0.0]);
        consider(p.room_half + x, [1.0, 0.0]);
        consider(p.room_half - y, [0.0, -1.0]);
        consider(p.room_half + y, [0.0, 1.0]);
        for (c, h) in observed_boxes(machines, storages, g) {
            let q = nearest_on_box(c, h, [0.0, 0.0]);
            let n = norm(q);
            // n ~ 0: the centre is on the box; the contact physics pushes it out first.
            if n > 1e-6 {
                consider(n, [-q[0] / n, -q[1] / n]);
            }
        }
        let (d, away) = nearest?;
        let speed = ((margin - d) / g.dt).min(g.k_speed);
        Some([away[0] * speed, away[1] * speed])
    }

    /// Velocity straight away from the nearest storage box while closer to it than
    /// `make_room` (at most K_speed, stopping at that distance); None when no storage box
    /// is that close (or the robot's centre is on one: no direction to back out along).
    pub fn make_room(&self, storages: &[f32]) -> Option<[f32; 2]> {
        let p = &self.params;
        let g = &p.greedy;
        if p.make_room <= 0.0 {
            return None;
        }
        let mut nearest: Option<([f32; 2], f32)> = None;
        for s in storages.chunks_exact(2) {
            let c = [s[0], s[1]];
            let d = box_distance(c, g.storage_half, [0.0, 0.0]);
            if d < p.make_room && nearest.is_none_or(|(_, b)| d < b) {
                nearest = Some((nearest_on_box(c, g.storage_half, [0.0, 0.0]), d));
            }
        }
        let (q, d) = nearest?;
        let n = norm(q);
        if n < 1e-6 {
            return None;
        }
        let speed = ((p.make_room - d) / g.dt).min(g.k_speed);
        Some([-q[0] / n * speed, -q[1] / n * speed])
    }

    /// Straight for a point just inside reach of `target`, at most K_speed, around any box
    /// in the way ([`crate::detour`]); zero with no target or once there.
    pub fn preferred_towards(
        &self,
        target: Option<Target>,
        own: &[f32],
        machines: &[f32],
        storages: &[f32],
    ) -> [f32; 2] {
        let p = &self.params;
        let g = &p.greedy;
        let (r, k, dt) = (g.robot_radius, g.k_speed, g.dt);
        let Some(t) = target else {
            return [0.0, 0.0];
        };
        let q = nearest_on_box(t.rel, t.half, [0.0, 0.0]);
        let d = norm(q);
        // Stop between the box clearance ORCA keeps and the reach: close enough to pick
        // or place, not so close that ORCA holds the robot off.
        let stand_off = r + 0.5 * (self.box_clearance() + p.reach);
        // Closer than the clearance ORCA keeps (a peer pushed it in, or a late command in
        // real time carried it past its stop): back out to the stand-off instead of
        // resting against the box, where every waiting step would count as a contact.
        // Between the clearance and the stand-off: stay.
        let inner = r + self.box_clearance();
        if (inner..=stand_off).contains(&d) || d < 1e-6 {
            // d ~ 0: the centre is on or in the box, no direction to back out along;
            // the contact physics pushes it out first.
            return [0.0, 0.0];
        }
        if p.detour && self.detour_left > 0 && d > stand_off {
            // the stand-off point is outside the target's grown box, so only other boxes
            // can be in the way
            let goal = crate::detour::Goal {
                point: [q[0] * (d - stand_off) / d, q[1] * (d - stand_off) / d],
                target: (t.rel, t.half),
                stand_off,
            };
            let boxes: Vec<_> = observed_boxes(machines, storages, g).collect();
            let w =
                crate::detour::waypoint(goal, &boxes, inner, r, ([own[0], own[1]], p.room_half));
            if w != goal.point {
                let n = norm(w);
                return [w[0] / n * k, w[1] / n * k];
            }
        }
        // negative inside `inner`: away from the box
        let go = (d - stand_off) / d;
        let v = [q[0] * go / dt, q[1] * go / dt];
        let s = norm(v);
        if s > k {
            [v[0] * k / s, v[1] * k / s]
        } else {
            v
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::greedy::GreedyParams;
    use crate::orca::OrcaParams;

    fn params() -> OrcaParams {
        OrcaParams::new(GreedyParams::default(), 2.3, 0.08)
    }

    /// At the stand-off the robot waits; pushed inside the box clearance it backs out
    /// (away from the box, back to the stand-off in one step), so a robot waiting at a
    /// machine does not rest in contact with it.
    #[test]
    fn backs_out_when_closer_than_the_box_clearance() {
        let c = GreedyOrca::new(params()).unwrap();
        let half = [0.12, 0.12];
        let stand_off = 0.08 + 0.5 * (c.box_clearance() + 0.08);
        // machine to the right, its surface `gap` beyond the robot centre
        let at = |gap: f32| {
            c.preferred_towards(
                Some(Target {
                    rel: [gap + half[0], 0.0],
                    half,
                }),
                &[0.0, 0.0, 0.0],
                &[],
                &[],
            )
        };
        assert_eq!(at(stand_off), [0.0, 0.0]);
        assert_eq!(at(0.08 + c.box_clearance() + 0.001), [0.0, 0.0]);
        let v = at(0.085); // 5 mm from touching
        assert!(v[0] < 0.0 && v[1].abs() < 1e-6, "{v:?}");
        assert!((v[0] * 0.1 + (stand_off - 0.085)).abs() < 1e-5, "{v:?}");
        let far = at(1.0);
        assert!(far[0] > 0.49, "{far:?}");
    }

    /// A carrier beside the machine it picked from, its storage straight through that
    /// machine: ORCA holds it at the face. After [`STUCK_STEPS`] steps without moving it
    /// heads round a corner of the box ([`crate::detour`]); with `detour` off it stays.
    #[test]
    fn a_robot_stuck_against_a_box_goes_round_it() {
        let half = GreedyParams::default().machine_half;
        // machine face 0.1 m right of the robot centre (robot radius 0.08), storage beyond
        let machines = [0.1 + half[0], 0.0, 0.0];
        let storages = [0.9, 0.0];
        let own = [-0.3, 0.1, 1.0];
        for detour in [true, false] {
            let mut c = GreedyOrca::new(OrcaParams { detour, ..params() }).unwrap();
            let mut sideways = Vec::new();
            for _ in 0..STUCK_STEPS + 2 {
                // the robot does not move: same observation every step
                c.velocity(&own, &machines, &storages, &[]);
                let pref = c.greedy_preferred(&own, &machines, &storages, &[]);
                sideways.push(pref[1].abs() / norm(pref));
            }
            assert!(sideways[0] < 1e-3, "straight at first: {sideways:?}");
            let last = *sideways.last().unwrap();
            if detour {
                assert!(last > 0.3, "round the box once stuck: {sideways:?}");
            } else {
                assert!(last < 1e-3, "detour off: {sideways:?}");
            }
        }
    }

    /// An idle robot (no ready machine, no part) next to a storage box backs straight out,
    /// at most K_speed, and stops at `make_room` from the box; with `make_room` 0 it stays.
    #[test]
    fn idle_robot_makes_room_at_a_storage() {
        let c = GreedyOrca::new(params()).unwrap();
        let busy = [0.8, 0.0, 0.0];
        // storage half size [0.15, 0.08]; its centre 0.1 m above the robot, so its
        // surface is 0.02 m away
        let half = params().greedy.storage_half;
        let near = [0.0, 0.1];
        let v = c.greedy_preferred(&[0.0, 0.0, 0.0], &busy, &near, &[]);
        assert!(v[1] < -0.49 && v[0].abs() < 1e-6, "{v:?}");
        // just inside make_room: one step's worth of the remaining gap, no more
        let m = params().make_room;
        let d = m - 0.01;
        let v = c.greedy_preferred(&[0.0, 0.0, 0.0], &busy, &[0.0, half[1] + d], &[]);
        assert!((v[1] + 0.01 / 0.1).abs() < 1e-4, "{v:?}");
        // beyond it: stay
        let far = [0.0, half[1] + m + 0.01];
        assert_eq!(
            c.greedy_preferred(&[0.0, 0.0, 0.0], &busy, &far, &[]),
            [0.0, 0.0]
        );
        // off: no berth, only keep_off's (out of the box's contact margin)
        let mut p = params();
        p.make_room = 0.0;
        let off = GreedyOrca::new(p).unwrap();
        let v = off.greedy_preferred(&[0.0, 0.0, 0.0], &busy, &near, &[]);
        assert!(v[1] < 0.0 && v[0].abs() < 1e-6, "{v:?}");
        let margin = p.greedy.robot_radius + p.clearance.min(0.4 * p.reach);
        let clear = [0.0, half[1] + margin + 0.01];
        assert_eq!(
            off.greedy_preferred(&[0.0, 0.0, 0.0], &busy, &clear, &[]),
            [0.0, 0.0]
        );
    }

    /// Inside a wall's margin, getting out of it comes before making room: next to the top
    /// wall, backing away from a storage below would press up into the wall; the robot
    /// moves down out of the margin instead, and makes room once outside it.
    #[test]
    fn out_of_a_wall_margin_before_making_room() {
        let p = params();
        let c = GreedyOrca::new(p).unwrap();
        let r = p.greedy.robot_radius;
        let margin = r + p.clearance.min(0.4 * p.reach);
        let busy_far = [-0.8, -0.8, 0.0];
        let storage = [0.0, -0.3];
        let open = c.greedy_preferred(&[0.0, 0.0, 0.0], &busy_far, &storage, &[]);
        assert!(open[1] > 0.0, "make room: up, {open:?}");
        let inside = p.room_half - r - 0.003;
        let v = c.greedy_preferred(&[0.0, inside, 0.0], &busy_far, &storage, &[]);
        assert!(v[1] < 0.0, "out of the wall's margin: down, {v:?}");
        let outside = p.room_half - margin - 0.001;
        let v = c.greedy_preferred(&[0.0, outside, 0.0], &busy_far, &storage, &[]);
        assert!(v[1] > 0.0, "outside it, make room again: {v:?}");
    }

    /// A robot with nowhere to go that rests inside ORCA's obstacle margin of a wall or a
    /// box it is not heading for backs straight out to the margin, no farther; ORCA alone
    /// would let it rest there (it only forbids moving in).
    #[test]
    fn a_robot_with_nowhere_to_go_keeps_off_walls_and_boxes() {
        let p = params();
        let mut c = GreedyOrca::new(p).unwrap();
        let r = p.greedy.robot_radius;
        let margin = r + p.clearance.min(0.4 * p.reach);
        let busy_far = [-0.8, 0.0, 0.0];
        // 4 mm from the right wall (room half 1.15): straight left, the gap in one step.
        let x = p.room_half - r - 0.004;
        let v = c.greedy_preferred(&[x, 0.0, 0.0], &busy_far, &[], &[]);
        let want = (margin - (r + 0.004)) / p.greedy.dt;
        assert!((v[0] + want).abs() < 1e-4 && v[1].abs() < 1e-6, "{v:?}");
        // Beyond the margin it stays.
        let x = p.room_half - margin - 0.001;
        assert_eq!(
            c.greedy_preferred(&[x, 0.0, 0.0], &busy_far, &[], &[]),
            [0.0, 0.0]
        );
        // A busy machine 3 mm below (greedy has no task): up, away from it.
        let h = p.greedy.machine_half;
        let below = [0.0, -(h[1] + r + 0.003), 0.0];
        let v = c.greedy_preferred(&[0.0, 0.0, 0.0], &below, &[], &[]);
        assert!(v[1] > 0.0 && v[0].abs() < 1e-6, "{v:?}");
        // The right wall 1 mm away as well: the nearer surface wins.
        let x = p.room_half - r - 0.001;
        let v = c.greedy_preferred(&[x, 0.0, 0.0], &below, &[], &[]);
        assert!(v[0] < 0.0 && v[1].abs() < 1e-6, "{v:?}");
        // A policy asking to stay keeps off the same way.
        let x = p.room_half - r - 0.004;
        let v = c.target_preferred(0, &[x, 0.0, 0.0], &busy_far, &[], &[]);
        assert!(v[0] < 0.0, "{v:?}");
    }

    /// Only a robot with nowhere to go makes room: one with a task heads for it, and a
    /// target policy's "stay" makes room like greedy's idle robot.
    #[test]
    fn make_room_only_without_a_target() {
        let mut c = GreedyOrca::new(params()).unwrap();
        let near = [0.0, 0.1];
        // a ready machine to the right: greedy heads there, storage or not
        let v = c.greedy_preferred(&[0.0, 0.0, 0.0], &[0.8, 0.0, 1.0], &near, &[]);
        assert!(v[0] > 0.49, "{v:?}");
        // with a part: towards the storage, even from inside make_room
        let mid = [0.0, 0.3];
        let v = c.greedy_preferred(&[0.0, 0.0, 1.0], &[0.8, 0.0, 0.0], &mid, &[]);
        assert!(v[1] > 0.49, "{v:?}");
        let v = c.greedy_preferred(&[0.0, 0.0, 0.0], &[0.8, 0.0, 0.0], &mid, &[]);
        assert!(v[1] < -0.49, "{v:?}");
        let stay = c.target_preferred(0, &[0.0, 0.0, 0.0], &[0.8, 0.0, 1.0], &near, &[]);
        assert!(stay[1] < -0.49, "{stay:?}");
    }
}
