//! Fan-out: one process may host several robots (`-p robots:=robot_0..99`), all reading the
//! same topics. The node keeps ONE DDS reader per input topic; each sample is decoded once
//! and handed here, and every hosted robot's world model gets it ([`deliver`]): a robot's
//! own `pose`/`has_part` land in its own slot, the same sample is a peer's data for every
//! other hosted robot. Each robot keeps its own validation, writer pins
//! (docs/adr/0004-writer-pinning.md), staleness, counters, controller and `cmd_vel` writer,
//! so a process hosting one robot behaves exactly as before, and a process hosting N robots
//! behaves like N such processes fed the same samples, with N times fewer readers.
//!
//! DDS-free and deterministic, like [`crate::world`].

use std::sync::Arc;
use std::time::Duration;

use msgs::cells::Cell;
use msgs::{EntityTopic, PoseStamped};

use crate::cells::CellContent;
use crate::tick::Brain;
use crate::world::{Accepted, DropReason, WriterId};

/// One received sample, decoded once for every hosted robot.
#[derive(Debug, Clone, Copy)]
pub enum Incoming<'a> {
    Pose {
        msg: &'a PoseStamped,
        writer: WriterId,
    },
    /// `has_part` / `part_ready`, with the step stamp of its DDS source timestamp.
    Flag {
        value: bool,
        stamp: Option<i64>,
        writer: WriterId,
    },
    /// The reader could not decode it.
    Undecodable,
}

/// What one sample did across the hosted robots (for logging: counted per robot already).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Delivered {
    /// Robots that stored it.
    pub accepted: usize,
    /// Robots for which it moved the topic's pin to a new writer.
    pub new_writer: usize,
    /// Robots that refused it, and the reason (the first one; every robot applies the same
    /// rules to the same sample history, so the reasons agree).
    pub dropped: usize,
    pub reason: Option<DropReason>,
}

/// Hand one sample of `topic` to every robot in `brains`, counting in each robot's
/// counters what happened to it there (accepted / dropped by reason / writer changes).
pub fn deliver<'b>(
    brains: impl IntoIterator<Item = &'b mut Brain>,
    topic: &EntityTopic,
    sample: &Incoming<'_>,
    now: f64,
) -> Delivered {
    deliver_sized(brains, topic, sample, 0, now)
}

/// [`deliver`] a sample of `bytes` CDR payload bytes (counted by the robots that take it).
pub fn deliver_sized<'b>(
    brains: impl IntoIterator<Item = &'b mut Brain>,
    topic: &EntityTopic,
    sample: &Incoming<'_>,
    bytes: usize,
    now: f64,
) -> Delivered {
    let mut d = Delivered::default();
    for brain in brains {
        if !brain.world.reads_topics_of(&topic.entity) {
            continue; // cell mode: a fellow hosted robot is seen through the cells
        }
        let res = match *sample {
            Incoming::Pose { msg, writer } => brain.world.on_pose_from(topic, msg, writer, now),
            Incoming::Flag {
                value,
                stamp,
                writer,
            } => brain
                .world
                .on_flag_stamped(topic, value, stamp, writer, now),
            Incoming::Undecodable => Err(DropReason::Decode),
        };
        d.count(brain, res, bytes);
    }
    d
}

/// Hand one cell's state (cell mode, docs/adr/0038-cell-topics.md) to every hosted robot
/// that reads or keeps that cell; robots farther away ignore it, uncounted. A malformed
/// cell message is `content: Err(reason)`, dropped by every robot.
pub fn deliver_cell<'b>(
    brains: impl IntoIterator<Item = &'b mut Brain>,
    cell: Cell,
    content: &Result<Arc<CellContent>, DropReason>,
    writer: WriterId,
    now: f64,
) -> Delivered {
    let mut d = Delivered::default();
    for brain in brains {
        let res = match content {
            Ok(c) => brain.world.on_cell(cell, c, writer, now),
            Err(r) => Err(*r),
        };
        let bytes = content.as_ref().map_or(0, |c| c.bytes);
        match res {
            Ok(None) => {} // a cell this robot neither reads nor keeps
            Ok(Some(a)) => d.count(brain, Ok(a), bytes),
            Err(r) => d.count(brain, Err(r), bytes),
        }
    }
    d
}

impl Delivered {
    /// What one robot did with the sample (`bytes` of payload), in its counters and here.
    fn count(&mut self, brain: &mut Brain, res: Result<Accepted, DropReason>, bytes: usize) {
        match res {
            Ok(a) => {
                brain.counters.accepted += 1;
                brain.counters.accepted_bytes += bytes as u64;
                self.accepted += 1;
                if a == Accepted::NewWriter {
                    brain.counters.writer_changes += 1;
                    self.new_writer += 1;
                }
            }
            Err(r) => {
                brain.counters.drop(r);
                self.dropped += 1;
                self.reason.get_or_insert(r);
            }
        }
    }
}

/// A newly subscribed entity: every hosted robot expects its data (lockstep's first state).
pub fn touch<'b>(brains: impl IntoIterator<Item = &'b mut Brain>, topic: &EntityTopic) {
    for b in brains {
        b.world.touch(&topic.entity);
    }
}

/// Wall-clock mode: the first tick of hosted robot `i` of `n`, after the loop's start.
/// Robots are spread evenly over one control period, so N robots do not all run their
/// controller and write `cmd_vel` in the same instant; one robot ticks at the start.
pub fn tick_offset(i: usize, n: usize, period: Duration) -> Duration {
    if n <= 1 {
        return Duration::ZERO;
    }
    period.mul_f64(i as f64 / n as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::controller::GreedyController;
    use crate::world::{World, WorldModelConfig};
    use msgs::topics::{machine, robot, storage};
    use msgs::{Leaf, RoomBounds, Time};

    fn brain(me: &str) -> Brain {
        let w = World::new(
            me,
            WorldModelConfig {
                stale_timeout_s: 1.0,
                static_stale_timeout_s: 1.0,
                room: RoomBounds::default(),
                bound: obs::Bound::EVERYTHING,
                cells: None,
            },
        );
        let gp = crate::controller::tests::params(0.5);
        Brain::new(w, Box::new(GreedyController::new(gp)), 0.5)
    }
    fn pose(x: f64, y: f64) -> PoseStamped {
        PoseStamped::planar(Time::default(), "map", x, y)
    }
    const BRIDGE: WriterId = [7; 16];
    const OTHER: WriterId = [9; 16];

    /// Feed the scene every hosted robot needs to act: each one's own pose/has_part, one
    /// machine, one storage, each through one `deliver` call for all robots.
    fn feed(brains: &mut [Brain], names: &[&str], t: f64) -> Vec<Delivered> {
        let mut out = Vec::new();
        let m = pose(0.5, -0.5);
        let s = pose(-0.5, 0.8);
        out.push(deliver(
            brains.iter_mut(),
            &machine(0, Leaf::Pose),
            &Incoming::Pose {
                msg: &m,
                writer: BRIDGE,
            },
            t,
        ));
        out.push(deliver(
            brains.iter_mut(),
            &machine(0, Leaf::PartReady),
            &Incoming::Flag {
                value: true,
                stamp: None,
                writer: BRIDGE,
            },
            t,
        ));
        out.push(deliver(
            brains.iter_mut(),
            &storage(0, Leaf::Pose),
            &Incoming::Pose {
                msg: &s,
                writer: BRIDGE,
            },
            t,
        ));
        for (i, n) in names.iter().enumerate() {
            let p = pose(-0.5, -0.5 + 0.3 * i as f64);
            out.push(deliver(
                brains.iter_mut(),
                &robot(n, Leaf::Pose),
                &Incoming::Pose {
                    msg: &p,
                    writer: BRIDGE,
                },
                t,
            ));
            out.push(deliver(
                brains.iter_mut(),
                &robot(n, Leaf::HasPart),
                &Incoming::Flag {
                    value: false,
                    stamp: None,
                    writer: BRIDGE,
                },
                t,
            ));
        }
        out
    }

    #[test]
    fn one_sample_reaches_every_hosted_robot_as_own_or_peer_data() {
        let names = ["robot_0", "robot_1", "robot_2"];
        let mut brains: Vec<Brain> = names.iter().map(|n| brain(n)).collect();
        let d = feed(&mut brains, &names, 0.0);
        // 3 entity topics + 2 per robot, each delivered once to all 3 robots
        assert_eq!(d.len(), 9);
        assert!(d.iter().all(|x| x.accepted == 3 && x.dropped == 0));
        for (i, b) in brains.iter().enumerate() {
            assert_eq!(b.counters.accepted, 9);
            let o = b.world.observation(0.1).unwrap();
            // its own pose is its own; the other two robots are its peers
            assert_eq!(o.own_pos, [-0.5, (-0.5 + 0.3 * i as f64) as f32]);
            assert_eq!(o.peers.len(), 2);
            assert_eq!((o.machines.len(), o.storages.len()), (1, 1));
            assert_eq!(b.world.known(), (1, 1, 2));
        }
        // robot_1's peers are robot_0 and robot_2, in natural order
        let o = brains[1].world.observation(0.1).unwrap();
        assert_eq!(o.peers[0].0, [-0.5, -0.5]);
        assert_eq!(o.peers[1].0, [-0.5, 0.1]);
    }

    #[test]
    fn rejections_and_pins_are_per_robot_and_agree() {
        let names = ["robot_0", "robot_1"];
        let mut brains: Vec<Brain> = names.iter().map(|n| brain(n)).collect();
        feed(&mut brains, &names, 0.0);
        // an impostor on robot_1's pose: refused and counted by both robots
        let fake = pose(-1.0, -1.0);
        let d = deliver(
            brains.iter_mut(),
            &robot("robot_1", Leaf::Pose),
            &Incoming::Pose {
                msg: &fake,
                writer: OTHER,
            },
            0.5,
        );
        assert_eq!(
            d,
            Delivered {
                accepted: 0,
                new_writer: 0,
                dropped: 2,
                reason: Some(DropReason::ForeignWriter)
            }
        );
        // undecodable and invalid samples are counted by every robot too
        deliver(
            brains.iter_mut(),
            &robot("robot_0", Leaf::Pose),
            &Incoming::Undecodable,
            0.5,
        );
        let mut nan = pose(0.0, 0.0);
        nan.pose.position.x = f64::NAN;
        deliver(
            brains.iter_mut(),
            &machine(0, Leaf::Pose),
            &Incoming::Pose {
                msg: &nan,
                writer: BRIDGE,
            },
            0.5,
        );
        for b in &brains {
            assert_eq!(b.counters.dropped_foreign_writer, 1);
            assert_eq!(b.counters.dropped_decode, 1);
            assert_eq!(b.counters.dropped_non_finite, 1);
            assert_eq!(b.counters.dropped(), 3);
        }
        assert_eq!(
            brains[1].world.observation(0.6).unwrap().own_pos,
            [-0.5, -0.2]
        );
        // the bridge is gone for > 1 s: a new writer takes robot_1's pose pin everywhere
        let p = pose(0.2, 0.2);
        let d = deliver(
            brains.iter_mut(),
            &robot("robot_1", Leaf::Pose),
            &Incoming::Pose {
                msg: &p,
                writer: OTHER,
            },
            1.5,
        );
        assert_eq!((d.accepted, d.new_writer), (2, 2));
        assert!(brains.iter().all(|b| b.counters.writer_changes == 1));
    }

    #[test]
    fn every_hosted_robot_acts_on_the_shared_samples() {
        let names = ["robot_0", "robot_1"];
        let mut brains: Vec<Brain> = names.iter().map(|n| brain(n)).collect();
        feed(&mut brains, &names, 0.0);
        // the nearest part-less robot claims the ready machine (+x); robot_1, farther and
        // seeing robot_0 as a peer, does something else
        let r0 = brains[0].tick(0.1);
        let r1 = brains[1].tick(0.1);
        assert_eq!(r0.velocity, [0.5, 0.0]);
        assert_ne!(r1.velocity, [0.5, 0.0]);
        assert_eq!(r0.counts.unwrap().peers, 1);
        assert_eq!(r1.counts.unwrap().peers, 1);
    }

    #[test]
    fn one_hosted_robot_is_the_single_robot_world() {
        // a hub of one behaves exactly like feeding the world directly
        let mut hub = [brain("robot_0")];
        let mut direct = brain("robot_0");
        let m = pose(0.5, -0.5);
        let fake = pose(-1.0, 0.0);
        let steps: Vec<(EntityTopic, Incoming, f64)> = vec![
            (
                robot("robot_0", Leaf::Pose),
                Incoming::Pose {
                    msg: &m,
                    writer: BRIDGE,
                },
                0.0,
            ),
            (
                robot("robot_0", Leaf::Pose),
                Incoming::Pose {
                    msg: &fake,
                    writer: OTHER,
                },
                0.1,
            ),
            (
                robot("robot_0", Leaf::HasPart),
                Incoming::Flag {
                    value: true,
                    stamp: Some(5),
                    writer: BRIDGE,
                },
                0.1,
            ),
            (robot("robot_3", Leaf::Pose), Incoming::Undecodable, 0.2),
        ];
        for (topic, s, t) in &steps {
            deliver(hub.iter_mut(), topic, s, *t);
            let res = match *s {
                Incoming::Pose { msg, writer } => direct.world.on_pose_from(topic, msg, writer, *t),
                Incoming::Flag {
                    value,
                    stamp,
                    writer,
                } => direct
                    .world
                    .on_flag_stamped(topic, value, stamp, writer, *t),
                Incoming::Undecodable => Err(DropReason::Decode),
            };
            match res {
                Ok(_) => direct.counters.accepted += 1,
                Err(r) => direct.counters.drop(r),
            }
        }
        assert_eq!(hub[0].counters, direct.counters);
        let (a, b) = (
            hub[0].world.observation(0.3).unwrap(),
            direct.world.observation(0.3).unwrap(),
        );
        assert_eq!((a.own_pos, a.has_part), (b.own_pos, b.has_part));
        assert_eq!(
            (a.machines, a.storages, a.peers),
            (b.machines, b.storages, b.peers)
        );
    }

    #[test]
    fn touch_reaches_every_robot() {
        let mut brains = [brain("robot_0"), brain("robot_1")];
        touch(brains.iter_mut(), &robot("robot_7", Leaf::Pose));
        touch(brains.iter_mut(), &machine(3, Leaf::Pose));
        // robot_1's own topics make robot_1 a peer of robot_0 only
        touch(brains.iter_mut(), &robot("robot_1", Leaf::Pose));
        assert_eq!(brains[0].world.known(), (1, 0, 2));
        assert_eq!(brains[1].world.known(), (1, 0, 1));
    }

    #[test]
    fn ticks_are_spread_over_one_period() {
        let p = Duration::from_millis(100);
        assert_eq!(tick_offset(0, 1, p), Duration::ZERO);
        assert_eq!(tick_offset(0, 4, p), Duration::ZERO);
        assert_eq!(tick_offset(1, 4, p), Duration::from_millis(25));
        assert_eq!(tick_offset(3, 4, p), Duration::from_millis(75));
        let last = tick_offset(99, 100, p);
        assert!(last < p && last >= Duration::from_millis(98));
    }
}
