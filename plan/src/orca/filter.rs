//! ORCA proper (van den Berg et al. 2011, the `dodgy_2d` port of RVO2): the velocity
//! nearest to the preferred one that avoids the observed peers, boxes and walls over the
//! horizons, with the velocity estimates it needs (the observation has no velocities).

use super::{observed_boxes, GreedyOrca, ALONE_RADII, GREEDY_ORCA_CLEARANCE};
use crate::geom::{box_distance, norm};
use dodgy_2d::{Agent, AvoidanceOptions, Obstacle, Vec2};
use std::borrow::Cow;

impl GreedyOrca {
    /// The filter's margin to boxes and walls on this step: [`Self::box_clearance`], but
    /// no more than greedy-ORCA's own clearance while no observed peer is within
    /// [`ALONE_RADII`] radii. A wider berth around boxes is there for when a peer can
    /// squeeze the robot against one; alone, it only slows the robot between machines
    /// (robot-poor setups: 2.8_1 23.5 -> 24.3 parts on the tuning seeds 7-8, 5.10_2 54.2 ->
    /// 55.0, 30.6_1's contacts unchanged; at 25 mm whatever the peers, 30.6_1's contacts
    /// doubled). docs/RESULTS.md 7.7. A no-op for greedy-ORCA, whose clearance is that.
    fn box_clearance_among(&self, peers: &[f32]) -> f32 {
        let near = ALONE_RADII * self.params.greedy.robot_radius;
        let alone = peers
            .chunks_exact(3)
            .all(|q| q[0] * q[0] + q[1] * q[1] >= near * near);
        if alone {
            self.box_clearance().min(GREEDY_ORCA_CLEARANCE)
        } else {
            self.box_clearance()
        }
    }
    /// ORCA as a safety filter: the velocity nearest to `pref` (m/s) that avoids the
    /// observed peers, boxes and walls over the horizons. Call once per period (it records
    /// the observation to estimate velocities next time).
    pub fn filter(
        &mut self,
        own: &[f32],
        machines: &[f32],
        storages: &[f32],
        peers: &[f32],
        pref: [f32; 2],
    ) -> [f32; 2] {
        let p = self.params;
        let g = &p.greedy;
        let (r, k, dt) = (g.robot_radius, g.k_speed, g.dt);
        let pos = [own[0], own[1]];
        let box_clearance = self.box_clearance_among(peers);
        // A jump of more than two full steps is a reset or a teleport, not motion.
        let max_jump = 2.0 * k * dt;
        let vel_of = |now: [f32; 2], prev: [f32; 2]| {
            let d = [now[0] - prev[0], now[1] - prev[1]];
            if norm(d) <= max_jump {
                [d[0] / dt, d[1] / dt]
            } else {
                [0.0, 0.0]
            }
        };
        let own_vel = self.prev_own.map_or([0.0, 0.0], |q| vel_of(pos, q));
        self.peers_now.clear();
        self.peers_now.extend(
            peers
                .chunks_exact(3)
                .map(|q| [pos[0] + q[0], pos[1] + q[1]]),
        );
        let pref = if pref[0].is_finite() && pref[1].is_finite() {
            pref
        } else {
            [0.0, 0.0]
        };

        // Each robot's radius carries half its speed-dependent clearance, so a pair keeps
        // the mean of the two (dodgy_2d sums the radii).
        let radius_at = |v: [f32; 2]| r + 0.5 * p.clearance_at(norm(v));
        let me = Agent {
            position: Vec2::ZERO,
            velocity: Vec2::from(own_vel),
            radius: radius_at(own_vel),
            avoidance_responsibility: 1.0,
        };
        // Nearest peers first; each gets the velocity of the previous peer nearest to it.
        let mut near: Vec<(f32, usize)> = peers
            .chunks_exact(3)
            .enumerate()
            .map(|(i, q)| (q[0] * q[0] + q[1] * q[1], i))
            .collect();
        let keep = p.max_neighbours.min(near.len());
        if keep < near.len() {
            near.select_nth_unstable_by(keep, |a, b| a.0.total_cmp(&b.0));
            near.truncate(keep);
        }
        let neighbours: Vec<Cow<Agent>> = near
            .iter()
            .map(|&(_, i)| {
                let now = self.peers_now[i];
                let v = self
                    .matched_prev(i, now, max_jump)
                    .map_or([0.0, 0.0], |q| vel_of(now, q));
                Cow::Owned(Agent {
                    position: Vec2::new(peers[i * 3], peers[i * 3 + 1]),
                    velocity: Vec2::from(v),
                    radius: radius_at(v),
                    avoidance_responsibility: 1.0,
                })
            })
            .collect();

        // Boxes (counter-clockwise: solid inside) within reach of the obstacle horizon,
        // and the room (clockwise: keeps the robot in).
        let horizon = k * p.obstacle_time_horizon + r + box_clearance;
        let mut obstacles: Vec<Cow<Obstacle>> = Vec::new();
        for (c, h) in observed_boxes(machines, storages, g) {
            if box_distance(c, h, [0.0, 0.0]) <= horizon {
                obstacles.push(Cow::Owned(Obstacle::Closed {
                    vertices: vec![
                        Vec2::new(c[0] - h[0], c[1] - h[1]),
                        Vec2::new(c[0] + h[0], c[1] - h[1]),
                        Vec2::new(c[0] + h[0], c[1] + h[1]),
                        Vec2::new(c[0] - h[0], c[1] + h[1]),
                    ],
                }));
            }
        }
        let (lo, hi) = (
            [-p.room_half - pos[0], -p.room_half - pos[1]],
            [p.room_half - pos[0], p.room_half - pos[1]],
        );
        obstacles.push(Cow::Owned(Obstacle::Closed {
            vertices: vec![
                Vec2::new(lo[0], lo[1]),
                Vec2::new(lo[0], hi[1]),
                Vec2::new(hi[0], hi[1]),
                Vec2::new(hi[0], lo[1]),
            ],
        }));

        let v = me.compute_avoiding_velocity(
            &neighbours,
            &obstacles,
            Vec2::from(pref),
            k,
            dt,
            &AvoidanceOptions {
                obstacle_margin: r + box_clearance,
                time_horizon: p.time_horizon,
                obstacle_time_horizon: p.obstacle_time_horizon,
            },
        );

        self.prev_own = Some(pos);
        std::mem::swap(&mut self.prev_peers, &mut self.peers_now);
        if v.is_finite() {
            [v.x, v.y]
        } else {
            [0.0, 0.0]
        }
    }

    /// Previous position of peer `i`: same index if it moved at most `max_jump` (the
    /// simulator and robot_node keep peer order while the fleet is unchanged), else the
    /// nearest previous peer within `max_jump`.
    fn matched_prev(&self, i: usize, now: [f32; 2], max_jump: f32) -> Option<[f32; 2]> {
        let d = |q: &[f32; 2]| norm([now[0] - q[0], now[1] - q[1]]);
        if let Some(q) = self.prev_peers.get(i).filter(|q| d(q) <= max_jump) {
            return Some(*q);
        }
        self.prev_peers
            .iter()
            .map(|q| (d(q), *q))
            .filter(|(dist, _)| *dist <= max_jump)
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, q)| q)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::greedy::GreedyParams;
    use crate::orca::{OrcaParams, FILTER_CLEARANCE, FILTER_REST_CLEARANCE, OBSTACLE_HORIZON};

    fn params() -> OrcaParams {
        OrcaParams::new(GreedyParams::default(), 2.3, 0.08)
    }

    #[test]
    fn yields_to_a_peer_coming_head_on() {
        let mut c = GreedyOrca::new(params()).unwrap();
        // Target straight right; a peer 0.3 m right, last seen 0.05 m further (so coming
        // at 0.5 m/s) and I moved 0.05 m right (0.5 m/s).
        let m = [1.0, 0.0, 1.0];
        let s = [-1.0, 0.9];
        c.velocity(&[-0.05, 0.0, 0.0], &[1.05, 0.0, 1.0], &s, &[0.4, 0.0, 0.0]);
        let v = c.velocity(&[0.0, 0.0, 0.0], &m, &s, &[0.3, 0.0, 1.0]);
        assert!(
            v[1].abs() > 0.1 || v[0] < 0.2,
            "should swerve or slow: {v:?}"
        );
    }

    /// A carrier driving at full speed straight for its storage, 0.12 m from touching it:
    /// greedy-ORCA's 0.3 s obstacle horizon already brakes it there, the policy filter's
    /// 0.15 s lets it keep full speed into the reach, where it places.
    #[test]
    fn the_policy_filter_brakes_later_for_a_box_ahead() {
        let g = GreedyParams::default();
        let gap = 0.12;
        let ahead = g.robot_radius + g.storage_half[0] + gap;
        let speed_towards = |p: OrcaParams| {
            let mut c = GreedyOrca::new(p).unwrap();
            let step = g.k_speed * g.dt;
            // one step earlier, one step farther: the filter estimates full speed
            c.filter(
                &[-0.5, 0.0, 1.0],
                &[],
                &[ahead + step, 0.0],
                &[],
                [g.k_speed, 0.0],
            );
            c.filter(
                &[-0.5 + step, 0.0, 1.0],
                &[],
                &[ahead, 0.0],
                &[],
                [g.k_speed, 0.0],
            )[0]
        };
        let script = speed_towards(params());
        let filter =
            speed_towards(params().for_policy_filter(FILTER_CLEARANCE, FILTER_REST_CLEARANCE));
        assert_eq!(params().obstacle_time_horizon, OBSTACLE_HORIZON);
        assert!(script < 0.8 * g.k_speed, "greedy-ORCA brakes: {script}");
        assert!(
            filter > 0.99 * g.k_speed,
            "the filter does not yet: {filter}"
        );
        // and the filter still brakes once the box is within its horizon
        let mut c =
            GreedyOrca::new(params().for_policy_filter(FILTER_CLEARANCE, FILTER_REST_CLEARANCE))
                .unwrap();
        let near = g.robot_radius + g.storage_half[0] + 0.06;
        let v = c.filter(&[0.0, 0.0, 1.0], &[], &[near, 0.0], &[], [g.k_speed, 0.0]);
        assert!(v[0] < 0.8 * g.k_speed, "{v:?}");
    }

    /// Alone, the filter keeps greedy-ORCA's clearance to boxes; with a peer near, its own.
    #[test]
    fn wider_box_margin_only_with_a_peer_near() {
        let c = GreedyOrca::new(params().for_policy(Some(FILTER_CLEARANCE))).unwrap();
        let r = c.params.greedy.robot_radius;
        let wide = c.box_clearance();
        assert!(wide > GREEDY_ORCA_CLEARANCE, "{wide}");
        assert_eq!(c.box_clearance_among(&[]), GREEDY_ORCA_CLEARANCE);
        let far = [ALONE_RADII * r + 0.01, 0.0, 0.0];
        assert_eq!(c.box_clearance_among(&far), GREEDY_ORCA_CLEARANCE);
        let near = [ALONE_RADII * r - 0.01, 0.0, 0.0];
        assert_eq!(c.box_clearance_among(&near), wide);
        // greedy-ORCA's own margin does not change.
        let script = GreedyOrca::new(params()).unwrap();
        assert_eq!(
            script.box_clearance_among(&near),
            script.box_clearance_among(&[])
        );
    }

    /// Two robots at rest 35 mm apart (surface to surface): inside a fixed 40 mm clearance
    /// the filter pushes them apart; with 30 mm at rest they may stand there, as in a queue.
    #[test]
    fn robots_at_rest_may_stand_closer_than_moving_ones() {
        let r = params().greedy.robot_radius;
        let peer = [2.0 * r + 0.035, 0.0, 0.0];
        let own = [0.0, 0.0, 0.0];
        let mut fixed = GreedyOrca::new(params().with_clearance(FILTER_CLEARANCE)).unwrap();
        let v = fixed.filter(&own, &[], &[], &peer, [0.0, 0.0]);
        assert!(v[0] < -0.01, "fixed 40 mm backs off: {v:?}");
        let mut adaptive = GreedyOrca::new(params().for_policy(Some(FILTER_CLEARANCE))).unwrap();
        let v = adaptive.filter(&own, &[], &[], &peer, [0.0, 0.0]);
        assert!(norm(v) < 1e-4, "30 mm at rest stays: {v:?}");
    }
}
