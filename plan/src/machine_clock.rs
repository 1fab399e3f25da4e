//! Steps until each observed machine's part is ready, tracked from its ready flag.
//!
//! The observation carries only a ready flag per machine, but a machine's preparation is
//! deterministic: once its part is picked it is ready again exactly `prep_steps` steps
//! later (sim `TaskConfig::prep_steps`; robot_node's `prep_steps` parameter). A robot that
//! watches a flag fall therefore knows that machine's timer, with no wire change. Machines
//! start an episode ready, so a robot that observes from the first step knows every timer;
//! one that joins later (or sees a machine appear busy) does not, and reports `None` for it
//! until its next pick.
//!
//! Machines are keyed by absolute centre (own position + relative offset), not by their
//! index in the observation, so that live additions and removals (which shift indices in
//! both the simulator and robot_node) do not hand one machine's timer to another.

/// Two centres closer than this (m) are the same machine. Machines are static boxes at
/// least a box apart, and positions travel as f32.
const SAME_MACHINE: f32 = 0.01;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Seen {
    Ready,
    /// Busy with this many steps left, counted from a fall of the flag that was seen.
    Busy(u32),
    /// Busy since before the robot watched it.
    Unknown,
}

#[derive(Debug, Clone, Default)]
pub struct MachineClock {
    prep_steps: u32,
    centres: Vec<[f32; 2]>,
    seen: Vec<Seen>,
    /// Per observation index, filled by [`Self::update`].
    ready_in: Vec<Option<u32>>,
}

impl MachineClock {
    pub fn new(prep_steps: u32) -> Self {
        Self {
            prep_steps,
            ..Self::default()
        }
    }

    /// Forget every machine (a new episode, or inputs that jumped).
    pub fn reset(&mut self) {
        self.centres.clear();
        self.seen.clear();
        self.ready_in.clear();
    }

    /// Advance by one step on this observation row (`own`: absolute x, y, ...; `machines`:
    /// rows of `dim` floats starting dx, dy, ready flag). Call once per step.
    pub fn update(&mut self, own: &[f32], machines: &[f32], dim: usize) {
        self.ready_in.clear();
        for (j, m) in machines.chunks_exact(dim).enumerate() {
            let centre = [own[0] + m[0], own[1] + m[1]];
            let ready = m[2] > 0.5;
            let k = self.slot(j, centre, ready);
            let next = match (self.seen[k], ready) {
                (_, true) => Seen::Ready,
                // the flag fell since the last step: a fresh preparation
                (Seen::Ready, false) => Seen::Busy(self.prep_steps),
                // Due now but still busy: it was made and picked within one step (the
                // simulator readies a part before the step's picks), so the flag never
                // showed it.
                (Seen::Busy(t), false) if t <= 1 => Seen::Busy(self.prep_steps),
                (Seen::Busy(t), false) => Seen::Busy(t - 1),
                (Seen::Unknown, false) => Seen::Unknown,
            };
            self.seen[k] = next;
            self.ready_in.push(match next {
                Seen::Ready => Some(0),
                Seen::Busy(t) => Some(t),
                Seen::Unknown => None,
            });
        }
    }

    /// Count `n` steps that passed unobserved (a real-time robot that missed states), before
    /// the next [`Self::update`]. A busy machine's count goes down by `n`; one that ran out
    /// meanwhile made its part, which the flag still being down at the next update says
    /// was picked at once (as [`Self::update`] reads it), so the count restarts from the
    /// preparation time for the steps left over. A flag that fell while unobserved is seen
    /// falling at the next update, as if it fell then: up to `n` steps later than it did.
    pub fn skip(&mut self, n: u32) {
        let prep = self.prep_steps.max(1);
        for s in &mut self.seen {
            if let Seen::Busy(t) = *s {
                *s = Seen::Busy(if t > n { t - n } else { prep - (n - t) % prep });
            }
        }
    }

    /// Steps until machine `j` (observation index at the last [`Self::update`]) has a part
    /// ready: 0 when ready now, None when not known.
    pub fn ready_in(&self) -> &[Option<u32>] {
        &self.ready_in
    }

    /// The slot of the machine at `centre`, likely at index `j` (same order as last step),
    /// created when new: ready if seen ready, else of unknown timer.
    fn slot(&mut self, j: usize, centre: [f32; 2], ready: bool) -> usize {
        let same = |c: &[f32; 2]| {
            (c[0] - centre[0]).abs() < SAME_MACHINE && (c[1] - centre[1]).abs() < SAME_MACHINE
        };
        if self.centres.get(j).is_some_and(same) {
            return j;
        }
        if let Some(k) = self.centres.iter().position(same) {
            return k;
        }
        self.centres.push(centre);
        self.seen
            .push(if ready { Seen::Ready } else { Seen::Unknown });
        self.centres.len() - 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(ready: &[bool]) -> Vec<f32> {
        // machines at x = 0.5, 1.0, ... relative to a robot at the origin
        ready
            .iter()
            .enumerate()
            .flat_map(|(j, &r)| [0.5 * (j as f32 + 1.0), 0.0, if r { 1.0 } else { 0.0 }])
            .collect()
    }

    #[test]
    fn a_fallen_flag_counts_down_from_the_preparation_time() {
        let mut c = MachineClock::new(20);
        c.update(&[0.0, 0.0, 0.0], &row(&[true, true]), 3);
        assert_eq!(c.ready_in(), &[Some(0), Some(0)]);
        c.update(&[0.0, 0.0, 0.0], &row(&[false, true]), 3);
        assert_eq!(c.ready_in(), &[Some(20), Some(0)]);
        for left in (1..20).rev() {
            c.update(&[0.0, 0.0, 0.0], &row(&[false, true]), 3);
            assert_eq!(c.ready_in()[0], Some(left));
        }
        c.update(&[0.0, 0.0, 0.0], &row(&[true, true]), 3);
        assert_eq!(c.ready_in()[0], Some(0));
    }

    #[test]
    fn a_part_made_and_picked_in_one_step_restarts_the_count() {
        let mut c = MachineClock::new(3);
        c.update(&[0.0, 0.0, 0.0], &row(&[true]), 3);
        for want in [3, 2, 1, 3, 2] {
            c.update(&[0.0, 0.0, 0.0], &row(&[false]), 3);
            assert_eq!(c.ready_in(), &[Some(want)]);
        }
    }

    #[test]
    fn skipped_steps_count_down_as_observed_ones_do() {
        // a clock that sees every step, and one that misses some (across a restart, too)
        let flags = [
            true, false, false, false, false, false, false, false, false, false, false,
        ];
        for seen_by_some in [&[0, 1, 2, 5, 6, 10][..], &[0, 1, 2, 4, 9]] {
            let (mut all, mut some) = (MachineClock::new(5), MachineClock::new(5));
            let mut last = 0;
            for (t, &f) in flags.iter().enumerate() {
                all.update(&[0.0, 0.0, 0.0], &row(&[f]), 3);
                if seen_by_some.contains(&t) {
                    if t > last + 1 {
                        some.skip((t - last - 1) as u32);
                    }
                    some.update(&[0.0, 0.0, 0.0], &row(&[f]), 3);
                    assert_eq!(
                        some.ready_in(),
                        all.ready_in(),
                        "step {t} of {seen_by_some:?}"
                    );
                    last = t;
                }
            }
        }
    }

    #[test]
    fn a_machine_first_seen_busy_is_unknown_until_its_next_pick() {
        let mut c = MachineClock::new(20);
        c.update(&[0.0, 0.0, 0.0], &row(&[false]), 3);
        assert_eq!(c.ready_in(), &[None]);
        c.update(&[0.0, 0.0, 0.0], &row(&[true]), 3);
        c.update(&[0.0, 0.0, 0.0], &row(&[false]), 3);
        assert_eq!(c.ready_in(), &[Some(20)]);
    }

    #[test]
    fn timers_follow_machines_when_indices_shift_and_the_robot_moves() {
        let mut c = MachineClock::new(20);
        c.update(&[0.0, 0.0, 0.0], &row(&[true, true]), 3);
        c.update(&[0.0, 0.0, 0.0], &row(&[true, false]), 3);
        assert_eq!(c.ready_in(), &[Some(0), Some(20)]);
        // machine 0 removed; the robot moved 0.25 m right: machine 1 is now index 0 at 0.75
        c.update(&[0.25, 0.0, 0.0], &[0.75, 0.0, 0.0], 3);
        assert_eq!(c.ready_in(), &[Some(19)]);
    }
}
