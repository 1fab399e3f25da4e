//! The numbers `tending sim` and `tending eval` report, one definition for both: parts,
//! contacts by kind (robot-robot, robot-machine, robot-storage, robot-wall), contacts per
//! robot-step, MU and team reward; the Markdown columns (the CSV record is
//! [`crate::EvalResultRecord`]).

use crate::stats::fmt_ms;
use sim::Metrics;

/// One run's (or one mean's) numbers. Contacts follow `sim::Metrics`: per robot per step,
/// a robot touching k bodies adds k, so a robot-robot contact adds 2.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Numbers {
    pub parts_delivered: f64,
    pub collisions: f64,
    pub collisions_robot_robot: f64,
    pub collisions_robot_machine: f64,
    pub collisions_robot_storage: f64,
    pub collisions_robot_wall: f64,
    /// Collision events (onsets: a robot starting to touch something), the paper's
    /// "collisions" read as events; a push held for 30 steps is one event, 30 contacts.
    pub collision_events: f64,
    /// collisions / (robots x steps): how often a robot touches something.
    pub contacts_per_robot_step: f64,
    /// robot-robot collisions / (robots x steps).
    pub robot_robot_per_robot_step: f64,
    pub mu: f64,
    pub team_reward: f64,
}

impl Numbers {
    /// One episode's numbers; `robots` is the fleet size (for the per-robot-step rates).
    pub fn of(m: &Metrics, robots: usize) -> Self {
        let robot_steps = (robots as f64 * m.steps as f64).max(1.0);
        Self {
            parts_delivered: m.parts_delivered as f64,
            collisions: m.collisions as f64,
            collisions_robot_robot: m.collisions_robot_robot as f64,
            collisions_robot_machine: m.collisions_robot_machine as f64,
            collisions_robot_storage: m.collisions_robot_storage as f64,
            collisions_robot_wall: m.collisions_robot_wall as f64,
            collision_events: m.collision_events as f64,
            contacts_per_robot_step: m.collisions as f64 / robot_steps,
            robot_robot_per_robot_step: m.collisions_robot_robot as f64 / robot_steps,
            mu: m.utilization(),
            team_reward: m.total_reward,
        }
    }

    /// Field-wise mean of several episodes (zeros for none).
    pub fn mean(xs: &[Numbers]) -> Self {
        let n = xs.len().max(1) as f64;
        let mut out = Self::default();
        for x in xs {
            for (o, v) in out.fields_mut().into_iter().zip(x.fields()) {
                *o += v / n;
            }
        }
        out
    }

    fn fields(&self) -> [f64; 11] {
        [
            self.parts_delivered,
            self.collisions,
            self.collisions_robot_robot,
            self.collisions_robot_machine,
            self.collisions_robot_storage,
            self.collisions_robot_wall,
            self.collision_events,
            self.contacts_per_robot_step,
            self.robot_robot_per_robot_step,
            self.mu,
            self.team_reward,
        ]
    }

    fn fields_mut(&mut self) -> [&mut f64; 11] {
        [
            &mut self.parts_delivered,
            &mut self.collisions,
            &mut self.collisions_robot_robot,
            &mut self.collisions_robot_machine,
            &mut self.collisions_robot_storage,
            &mut self.collisions_robot_wall,
            &mut self.collision_events,
            &mut self.contacts_per_robot_step,
            &mut self.robot_robot_per_robot_step,
            &mut self.mu,
            &mut self.team_reward,
        ]
    }
}

/// Markdown column names matching [`cells`].
pub const COLUMNS: [&str; 11] = [
    "parts delivered",
    "contacts",
    "robot-robot",
    "robot-machine",
    "robot-storage",
    "robot-wall",
    "collision events",
    "contacts / robot-step",
    "robot-robot / robot-step",
    "MU",
    "team reward",
];

/// "mean (std)" cells over `xs` (episodes, or per-seed means), in [`COLUMNS`] order.
pub fn cells(xs: &[Numbers]) -> Vec<String> {
    let col = |f: &dyn Fn(&Numbers) -> f64| xs.iter().map(f).collect::<Vec<_>>();
    vec![
        fmt_ms(&col(&|n| n.parts_delivered), 1),
        fmt_ms(&col(&|n| n.collisions), 1),
        fmt_ms(&col(&|n| n.collisions_robot_robot), 1),
        fmt_ms(&col(&|n| n.collisions_robot_machine), 1),
        fmt_ms(&col(&|n| n.collisions_robot_storage), 1),
        fmt_ms(&col(&|n| n.collisions_robot_wall), 1),
        fmt_ms(&col(&|n| n.collision_events), 1),
        fmt_ms(&col(&|n| n.contacts_per_robot_step), 4),
        fmt_ms(&col(&|n| n.robot_robot_per_robot_step), 4),
        fmt_ms(&col(&|n| n.mu), 2),
        fmt_ms(&col(&|n| n.team_reward), 1),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn metrics() -> Metrics {
        Metrics {
            parts_delivered: 3,
            parts_collected: 4,
            collisions: 10,
            collisions_robot_robot: 4,
            collisions_robot_machine: 3,
            collisions_robot_storage: 2,
            collisions_robot_wall: 1,
            collision_events: 2,
            p_max: 8,
            total_reward: 1.5,
            steps: 200,
        }
    }

    #[test]
    fn rates_are_per_robot_step() {
        let n = Numbers::of(&metrics(), 5);
        assert_eq!(n.contacts_per_robot_step, 10.0 / 1000.0);
        assert_eq!(n.robot_robot_per_robot_step, 4.0 / 1000.0);
        assert_eq!(n.mu, 0.5);
        let kinds = n.collisions_robot_robot
            + n.collisions_robot_machine
            + n.collisions_robot_storage
            + n.collisions_robot_wall;
        assert_eq!(kinds, n.collisions);
        assert_eq!(n.collision_events, 2.0);
    }

    #[test]
    fn mean_of_episodes() {
        let a = Numbers::of(&metrics(), 5);
        let mut m2 = metrics();
        m2.parts_delivered = 5;
        let b = Numbers::of(&m2, 5);
        assert_eq!(Numbers::mean(&[a, b]).parts_delivered, 4.0);
        assert_eq!(Numbers::mean(&[]), Numbers::default());
    }
}
