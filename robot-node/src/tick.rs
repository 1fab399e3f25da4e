//! One control step: world -> observation -> controller -> velocity command.

use crate::controller::Controller;
use crate::world::{Counters, OwnStale, World};

/// What a tick decided.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// The controller's command.
    Command,
    /// Own inputs unusable: zero velocity.
    OwnStale(OwnStale),
    /// The observation failed validation: zero velocity.
    ObsInvalid(String),
    /// The controller failed: zero velocity.
    ControllerError(String),
    /// The controller returned a non-finite velocity: zero velocity.
    BadOutput,
}

impl Outcome {
    /// Same kind (ignoring messages), for logging transitions only.
    pub fn same_kind(&self, other: &Outcome) -> bool {
        std::mem::discriminant(self) == std::mem::discriminant(other)
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct TickResult {
    /// (vx, vy) m/s to publish as Twist linear.x / linear.y.
    pub velocity: [f64; 2],
    pub outcome: Outcome,
    /// Entity counts in the observation (machines, storages, peers), if one was built.
    pub counts: Option<obs::Counts>,
}

/// World model + controller + counters: everything a tick needs, no DDS.
pub struct Brain {
    pub world: World,
    pub controller: Box<dyn Controller>,
    pub k_speed: f64,
    pub counters: Counters,
    own_ok: bool,
    /// Realtime: the state (own pose stamp) the last command was computed from, and it.
    last_command: Option<(i64, [f64; 2])>,
}

impl Brain {
    pub fn new(world: World, controller: Box<dyn Controller>, k_speed: f64) -> Self {
        Self {
            world,
            controller,
            k_speed,
            counters: Counters::default(),
            own_ok: false,
            last_command: None,
        }
    }

    /// Reset the controller state (e.g. sim time went backwards: new episode).
    pub fn reset(&mut self) {
        self.controller.reset();
        self.last_command = None;
    }

    pub fn tick(&mut self, now: f64) -> TickResult {
        let obs = self.world.observation(now);
        self.tick_on(obs)
    }

    /// Real time: act once per state, and the stamp of the own pose the command answers
    /// (None when it was not computed from state). The control timer and the bridge's step
    /// run on separate clocks, so a tick sometimes finds no new state; acting on it again
    /// would feed the planner the same positions twice (its velocity estimates read zero,
    /// then double, and a robot looks stuck to the detour rule, `plan::detour`) and step a
    /// recurrent policy twice on one observation, unlike training. Such a tick sends the
    /// last command again instead, while its state is fresh (counted in `ticks`,
    /// `commands` and `repeated_commands`).
    pub fn tick_once_per_state(&mut self, now: f64) -> (TickResult, Option<i64>) {
        let stamp = self.world.own_pose_stamp();
        if stamp.is_some() && stamp == self.last_stamp() {
            if let Some(r) = self.repeat_last(now) {
                return r;
            }
        }
        self.act_now(now)
    }

    /// The stamp of the state the last command answers (real time).
    pub fn last_stamp(&self) -> Option<i64> {
        self.last_command.map(|(s, _)| s)
    }

    /// Real time: the last command again, while the robot's own inputs are fresh (counted
    /// in `ticks`, `commands` and `repeated_commands`); None when there is none to repeat.
    pub fn repeat_last(&mut self, now: f64) -> Option<(TickResult, Option<i64>)> {
        let (s, v) = self.last_command?;
        self.world.own_inputs(now).ok()?;
        self.counters.ticks += 1;
        self.counters.commands += 1;
        self.counters.repeated_commands += 1;
        let r = TickResult {
            velocity: v,
            outcome: Outcome::Command,
            counts: None,
        };
        Some((r, Some(s)))
    }

    /// Real time: act on the newest data now, and the stamp of the own pose the command
    /// answers (None when it was not computed from state).
    pub fn act_now(&mut self, now: f64) -> (TickResult, Option<i64>) {
        let stamp = self.world.own_pose_stamp();
        if let (Some(s), Some(l)) = (stamp, self.last_stamp()) {
            if s > l {
                self.controller.state_gap((s - l) as f64 * 1e-6);
            }
        }
        if let Some(s) = stamp {
            let (n, off) = self.world.peers_off_stamp(s, now);
            self.counters.peer_poses_used += n as u64;
            self.counters.peer_poses_off_stamp += off as u64;
        }
        let r = self.tick(now);
        let stamp = match r.outcome {
            Outcome::Command => stamp,
            _ => None,
        };
        self.last_command = stamp.map(|s| (s, r.velocity));
        (r, stamp)
    }

    /// Lockstep: act on simulator state `stamp` (only data carrying that stamp).
    pub fn tick_lockstep(&mut self, stamp: i64) -> TickResult {
        let obs = self.world.observation_at(stamp);
        self.tick_on(obs)
    }

    fn tick_on(&mut self, obs: Result<obs::ObsBuilder, OwnStale>) -> TickResult {
        self.counters.ticks += 1;
        let zero = |outcome, counts| TickResult {
            velocity: [0.0, 0.0],
            outcome,
            counts,
        };
        let builder = match obs {
            Ok(b) => b,
            Err(s) => {
                self.own_ok = false;
                self.counters.zero_own_stale += 1;
                return zero(Outcome::OwnStale(s), None);
            }
        };
        if !self.own_ok {
            // own inputs are back (or first arrived): start from a fresh controller state
            self.controller.reset();
            self.own_ok = true;
        }
        let batch = match builder.build() {
            Ok(b) => b,
            Err(e) => {
                self.counters.zero_obs_invalid += 1;
                return zero(Outcome::ObsInvalid(e.to_string()), None);
            }
        };
        let counts = Some(batch.counts);
        let v = match self.controller.act(&batch) {
            Ok(v) => v,
            Err(e) => {
                self.counters.zero_controller_error += 1;
                return zero(Outcome::ControllerError(format!("{e:#}")), counts);
            }
        };
        if !v.iter().all(|x| x.is_finite()) {
            self.counters.zero_bad_output += 1;
            return zero(Outcome::BadOutput, counts);
        }
        let k = self.k_speed;
        self.counters.commands += 1;
        TickResult {
            velocity: [(v[0] as f64).clamp(-k, k), (v[1] as f64).clamp(-k, k)],
            outcome: Outcome::Command,
            counts,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::controller::GreedyController;
    use crate::world::WorldModelConfig;
    use msgs::topics::{machine, robot, storage};
    use msgs::{Leaf, PoseStamped, RoomBounds, Time};

    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Arc;

    struct Fixed(Result<[f32; 2], String>, Arc<AtomicUsize>);
    impl Controller for Fixed {
        fn reset(&mut self) {
            self.1.fetch_add(1, Ordering::SeqCst);
        }
        fn act(&mut self, _: &obs::ObsBatch) -> anyhow::Result<[f32; 2]> {
            self.0.clone().map_err(|e| anyhow::anyhow!(e))
        }
        fn name(&self) -> &'static str {
            "fixed"
        }
    }

    fn world() -> World {
        World::new(
            "robot_0",
            WorldModelConfig {
                stale_timeout_s: 1.0,
                static_stale_timeout_s: 1.0,
                room: RoomBounds::default(),
                bound: obs::Bound::EVERYTHING,
                cells: None,
            },
        )
    }
    fn p(x: f64, y: f64) -> PoseStamped {
        PoseStamped::planar(Time::default(), "map", x, y)
    }
    fn feed(w: &mut World, t: f64) {
        w.on_pose(&robot("robot_0", Leaf::Pose), &p(-0.5, -0.5), t)
            .unwrap();
        w.on_flag(&robot("robot_0", Leaf::HasPart), false, t)
            .unwrap();
        w.on_pose(&machine(0, Leaf::Pose), &p(0.5, -0.5), t)
            .unwrap();
        w.on_flag(&machine(0, Leaf::PartReady), true, t).unwrap();
        w.on_pose(&storage(0, Leaf::Pose), &p(-0.5, 0.8), t)
            .unwrap();
    }

    #[test]
    fn greedy_heads_to_machine_then_stops_when_stale() {
        let gp = crate::controller::tests::params(0.5);
        let mut b = Brain::new(world(), Box::new(GreedyController::new(gp)), 0.5);
        let r = b.tick(0.0);
        assert_eq!(r.outcome, Outcome::OwnStale(OwnStale::NoPose));
        assert_eq!(r.velocity, [0.0, 0.0]);
        feed(&mut b.world, 0.0);
        let r = b.tick(0.1);
        assert_eq!(r.outcome, Outcome::Command);
        assert_eq!(r.velocity, [0.5, 0.0]);
        assert_eq!(
            r.counts,
            Some(obs::Counts {
                machines: 1,
                storages: 1,
                peers: 0
            })
        );
        let r = b.tick(1.5);
        assert_eq!(r.outcome, Outcome::OwnStale(OwnStale::PoseStale));
        assert_eq!(r.velocity, [0.0, 0.0]);
        assert_eq!(b.counters.commands, 1);
        assert_eq!(b.counters.zero_own_stale, 2);
    }

    /// Counts its `act` calls; commands (0.1 x calls, 0).
    struct Counting(usize);
    impl Controller for Counting {
        fn reset(&mut self) {}
        fn act(&mut self, _: &obs::ObsBatch) -> anyhow::Result<[f32; 2]> {
            self.0 += 1;
            Ok([0.1 * self.0 as f32, 0.0])
        }
        fn name(&self) -> &'static str {
            "counting"
        }
    }

    #[test]
    fn real_time_acts_once_per_state_and_repeats_the_command_between() {
        let mut b = Brain::new(world(), Box::new(Counting(0)), 0.5);
        let own = |w: &mut World, stamp: f64, at: f64| {
            let pose = PoseStamped::planar(Time::from_secs_f64(stamp), "map", -0.5, -0.5);
            w.on_pose(&robot("robot_0", Leaf::Pose), &pose, at).unwrap();
        };
        feed(&mut b.world, 0.0);
        own(&mut b.world, 0.1, 0.0);
        let (r, s1) = b.tick_once_per_state(0.05);
        assert_eq!(
            (r.velocity, r.outcome.clone()),
            ([0.1f32 as f64, 0.0], Outcome::Command)
        );
        assert!(s1.is_some());
        // no new state: the same command and stamp, the controller not called
        let (r, s) = b.tick_once_per_state(0.1);
        assert_eq!((r.velocity, s), ([0.1f32 as f64, 0.0], s1));
        assert_eq!(b.counters.repeated_commands, 1);
        // a new state: acted on
        feed(&mut b.world, 0.2);
        own(&mut b.world, 0.2, 0.2);
        let (r, s2) = b.tick_once_per_state(0.25);
        assert_eq!(r.velocity, [0.2f32 as f64, 0.0]);
        assert!(s2 > s1);
        // the state goes stale: zero, not the last command
        let (r, s) = b.tick_once_per_state(5.0);
        assert_eq!((r.velocity, s), ([0.0, 0.0], None));
        assert!(matches!(r.outcome, Outcome::OwnStale(_)));
        assert_eq!((b.counters.ticks, b.counters.commands), (4, 3));
    }

    /// Records the state gaps it is told of.
    struct Gaps(Arc<std::sync::Mutex<Vec<f64>>>);
    impl Controller for Gaps {
        fn reset(&mut self) {}
        fn act(&mut self, _: &obs::ObsBatch) -> anyhow::Result<[f32; 2]> {
            Ok([0.0, 0.0])
        }
        fn name(&self) -> &'static str {
            "gaps"
        }
        fn state_gap(&mut self, gap_s: f64) {
            self.0.lock().unwrap().push(gap_s);
        }
    }

    #[test]
    fn real_time_tells_the_controller_how_far_apart_states_were() {
        let gaps = Arc::new(std::sync::Mutex::new(Vec::new()));
        let mut b = Brain::new(world(), Box::new(Gaps(gaps.clone())), 0.5);
        // states at 0.1, 0.2, then 0.5 (two missed); a repeat of 0.5 is no new state
        for (stamp, at) in [(0.1, 0.1), (0.2, 0.2), (0.5, 0.5), (0.5, 0.55)] {
            feed(&mut b.world, at);
            let pose = PoseStamped::planar(Time::from_secs_f64(stamp), "map", -0.5, -0.5);
            b.world
                .on_pose(&robot("robot_0", Leaf::Pose), &pose, at)
                .unwrap();
            b.tick_once_per_state(at);
        }
        let gaps = gaps.lock().unwrap().clone();
        assert_eq!(gaps.len(), 2, "{gaps:?}");
        assert!(
            (gaps[0] - 0.1).abs() < 1e-6 && (gaps[1] - 0.3).abs() < 1e-6,
            "{gaps:?}"
        );
    }

    #[test]
    fn controller_failures_give_zero() {
        let mut b = Brain::new(
            world(),
            Box::new(Fixed(Err("boom".into()), Default::default())),
            0.5,
        );
        feed(&mut b.world, 0.0);
        let r = b.tick(0.0);
        assert!(matches!(r.outcome, Outcome::ControllerError(ref s) if s.contains("boom")));
        assert_eq!(r.velocity, [0.0, 0.0]);
        let mut b = Brain::new(
            world(),
            Box::new(Fixed(Ok([f32::NAN, 0.0]), Default::default())),
            0.5,
        );
        feed(&mut b.world, 0.0);
        assert_eq!(b.tick(0.0).outcome, Outcome::BadOutput);
        let mut b = Brain::new(
            world(),
            Box::new(Fixed(Ok([3.0, -3.0]), Default::default())),
            0.5,
        );
        feed(&mut b.world, 0.0);
        assert_eq!(b.tick(0.0).velocity, [0.5, -0.5]);
    }

    #[test]
    fn controller_reset_when_own_inputs_return() {
        let resets = Arc::new(AtomicUsize::new(0));
        let mut b = Brain::new(
            world(),
            Box::new(Fixed(Ok([0.0, 0.0]), resets.clone())),
            0.5,
        );
        feed(&mut b.world, 0.0);
        b.tick(0.0); // first fresh: reset #1
        b.tick(0.5);
        b.tick(2.0); // stale
        feed(&mut b.world, 2.0);
        b.tick(2.1); // back: reset #2
        assert_eq!(resets.load(Ordering::SeqCst), 2);
        assert_eq!(b.counters.ticks, 4);
        assert_eq!(b.counters.commands, 3);
    }
}
