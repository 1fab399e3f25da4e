//! Is the fleet working? From the bridge's metrics lines: do the robots receive state and
//! act on it (`robots_on_state`), does the bridge step at its rate, and do its robots take
//! commands from their own nodes only (`cmds_foreign_writer`: a second writer on a robot's
//! cmd_vel is another fleet or node on the domain, ADR 0032). A run that loses its robots,
//! delivers nothing or was commanded by someone else says so and fails, instead of
//! exiting 0.

use std::time::Duration;

/// Time a problem must last before it counts (start-up transients, a restart).
pub const PERSIST: Duration = Duration::from_secs(5);
/// A realtime bridge stepping below this fraction of its rate is falling behind.
pub const MIN_RATE_FRACTION: f64 = 0.5;
/// A run at least this long (sim seconds) that delivered no part has failed.
pub const DELIVERY_EXPECTED_AFTER_S: f64 = 20.0;

/// What one metrics line says, with what the fleet expects at that moment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Wall time since the fleet started.
    pub wall: Duration,
    pub step: u64,
    pub sim_time: f64,
    pub robots_on_state: usize,
    /// Robots whose process has been up longer than the start-up grace.
    pub robots_expected: usize,
    pub delivered: u64,
    /// cmd_vel samples the bridge refused from a second writer on a robot's topic, so far.
    pub foreign_cmds: u64,
}

/// The current problems, empty when healthy.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Problems(pub Vec<String>);

impl std::fmt::Display for Problems {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.0.is_empty() {
            write!(f, "ok")
        } else {
            write!(f, "{}", self.0.join("; "))
        }
    }
}

/// Health over a run.
#[derive(Debug, Clone)]
pub struct Health {
    /// Realtime: the rate the bridge should step at (None in lockstep, which waits).
    rate_hz: Option<f64>,
    prev: Option<Sample>,
    last: Option<Sample>,
    /// Since when the current problems have lasted.
    bad_since: Option<Duration>,
    problems: Problems,
    /// Wall time the run was healthy / checked (after the first sample).
    healthy_for: Duration,
    checked_for: Duration,
    /// The worst stretch seen: longest unhealthy duration and its problems.
    worst: Option<(Duration, Problems)>,
    /// The most cmd_vel samples from second writers reported (the counter only grows).
    foreign_cmds: u64,
}

impl Health {
    pub fn new(rate_hz: Option<f64>) -> Self {
        Health {
            rate_hz,
            prev: None,
            last: None,
            bad_since: None,
            problems: Problems::default(),
            healthy_for: Duration::ZERO,
            checked_for: Duration::ZERO,
            worst: None,
            foreign_cmds: 0,
        }
    }

    /// Take a metrics line; returns the problems now (possibly not yet persistent).
    pub fn observe(&mut self, s: Sample) -> &Problems {
        let mut p = Vec::new();
        if s.robots_on_state < s.robots_expected {
            p.push(format!(
                "{}/{} robots not acting on the bridge's state",
                s.robots_expected - s.robots_on_state,
                s.robots_expected
            ));
        }
        self.foreign_cmds = self.foreign_cmds.max(s.foreign_cmds);
        if self.foreign_cmds > 0 {
            p.push(foreign_problem(self.foreign_cmds));
        }
        if let (Some(rate), Some(prev)) = (self.rate_hz, self.prev) {
            let dt = s.wall.saturating_sub(prev.wall).as_secs_f64();
            // At step 0 with robots missing the bridge is holding its first state until
            // they command (`wait_for_robots`): the robots' count above says so.
            let holding = s.step == 0 && s.robots_on_state < s.robots_expected.max(1);
            if dt > 0.5 && !holding {
                let hz = s.step.saturating_sub(prev.step) as f64 / dt;
                if hz < MIN_RATE_FRACTION * rate {
                    p.push(format!("bridge stepping at {hz:.1} Hz (want {rate})"));
                }
            }
        }
        if let Some(last) = self.last {
            let dt = s.wall.saturating_sub(last.wall);
            self.checked_for += dt;
            if p.is_empty() {
                self.healthy_for += dt;
            }
        }
        match (p.is_empty(), self.bad_since) {
            (true, _) => self.bad_since = None,
            (false, None) => self.bad_since = Some(s.wall),
            (false, Some(_)) => {}
        }
        self.problems = Problems(p);
        if let Some(since) = self.bad_since {
            let lasted = s.wall.saturating_sub(since);
            if self.worst.as_ref().is_none_or(|(d, _)| lasted > *d) {
                self.worst = Some((lasted, self.problems.clone()));
            }
        }
        // the rate is measured over at least a second of wall time
        if self
            .prev
            .is_none_or(|prev| s.wall.saturating_sub(prev.wall) >= Duration::from_secs(1))
        {
            self.prev = Some(s);
        }
        self.last = Some(s);
        &self.problems
    }

    /// The problems, once they have lasted [`PERSIST`]; empty otherwise.
    pub fn persistent(&self) -> Problems {
        match (self.bad_since, self.last) {
            (Some(since), Some(last)) if last.wall.saturating_sub(since) >= PERSIST => {
                self.problems.clone()
            }
            _ => Problems::default(),
        }
    }

    /// One line for the status: `ok`, or the problems and for how long.
    pub fn status(&self) -> String {
        match (self.bad_since, self.last) {
            (Some(since), Some(last)) => format!(
                "{} (for {:.0} s)",
                self.problems,
                last.wall.saturating_sub(since).as_secs_f64()
            ),
            _ => "ok".into(),
        }
    }

    /// The run's verdict: why it failed, or None.
    pub fn verdict(&self) -> Option<String> {
        let Some(last) = self.last else {
            return Some("no metrics from sim_bridge".into());
        };
        // however briefly: a robot of this fleet was commanded from outside it
        if self.foreign_cmds > 0 {
            return Some(foreign_problem(self.foreign_cmds));
        }
        let now = self.persistent();
        if !now.0.is_empty() {
            return Some(format!("unhealthy at the end of the run: {now}"));
        }
        if last.sim_time >= DELIVERY_EXPECTED_AFTER_S && last.delivered == 0 {
            return Some(format!(
                "no part delivered in {:.0} s of sim time",
                last.sim_time
            ));
        }
        if self.checked_for >= 2 * PERSIST && self.healthy_for * 2 < self.checked_for {
            let worst = self
                .worst
                .as_ref()
                .map(|(_, p)| format!(" (e.g. {p})"))
                .unwrap_or_default();
            return Some(format!(
                "healthy only {:.0} s of {:.0} s{worst}",
                self.healthy_for.as_secs_f64(),
                self.checked_for.as_secs_f64()
            ));
        }
        None
    }

    /// Summary for the final report.
    pub fn summary(&self) -> String {
        format!(
            "healthy {:.0} s of {:.0} s checked{}",
            self.healthy_for.as_secs_f64(),
            self.checked_for.as_secs_f64(),
            match &self.worst {
                Some((d, p)) if !d.is_zero() =>
                    format!("; longest problem {:.0} s: {p}", d.as_secs_f64()),
                _ => String::new(),
            }
        )
    }
}

/// The problem of cmd_vel from second writers.
fn foreign_problem(n: u64) -> String {
    format!(
        "{n} cmd_vel samples from a second writer on a robot's topic (another fleet or node \
         on this ROS domain commands robots of the same names)"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(wall_s: u64, step: u64, on: usize, expected: usize, delivered: u64) -> Sample {
        Sample {
            wall: Duration::from_secs(wall_s),
            step,
            sim_time: step as f64 * 0.1,
            robots_on_state: on,
            robots_expected: expected,
            delivered,
            foreign_cmds: 0,
        }
    }

    #[test]
    fn a_working_fleet_is_healthy_and_passes() {
        let mut h = Health::new(Some(10.0));
        for t in 0..30 {
            assert!(h.observe(at(t, t * 10, 6, 6, t / 5)).0.is_empty());
        }
        assert_eq!(h.verdict(), None);
        assert_eq!(h.status(), "ok");
    }

    #[test]
    fn robots_that_never_receive_state_fail_the_run() {
        // the 50-robot case: robots up, but none acting on state, nothing delivered
        let mut h = Health::new(Some(10.0));
        for t in 0..8 {
            h.observe(at(t, t * 10, 0, 50, 0));
        }
        assert!(
            h.persistent().0[0].contains("50/50 robots"),
            "{:?}",
            h.persistent()
        );
        let v = h.verdict().unwrap();
        assert!(v.contains("unhealthy at the end"), "{v}");
    }

    #[test]
    fn a_stalled_bridge_is_reported() {
        let mut h = Health::new(Some(10.0));
        for t in 0..7 {
            h.observe(at(t, t * 10, 20, 20, 1));
        }
        // the step counter stops at 62
        for t in 7..20 {
            h.observe(at(t, 62, 20, 20, 1));
        }
        let p = h.persistent();
        assert!(
            p.0.iter().any(|x| x.contains("bridge stepping at 0.0 Hz")),
            "{p:?}"
        );
        assert!(h.verdict().is_some());
    }

    #[test]
    fn a_bridge_holding_for_missing_robots_is_not_a_stall_but_the_robots_are() {
        let mut h = Health::new(Some(10.0));
        for t in 0..8 {
            h.observe(at(t, 0, 18, 20, 0));
        }
        let p = h.persistent();
        assert_eq!(p.0.len(), 1, "{p:?}");
        assert!(p.0[0].contains("2/20 robots"), "{p:?}");
        // every robot on state and still step 0: the bridge is stuck
        let mut h = Health::new(Some(10.0));
        for t in 0..8 {
            h.observe(at(t, 0, 20, 20, 0));
        }
        let p = h.persistent();
        assert!(p.0.iter().any(|x| x.contains("0.0 Hz")), "{p:?}");
    }

    #[test]
    fn short_problems_do_not_fail_but_a_mostly_sick_run_does() {
        let mut h = Health::new(Some(10.0));
        // a 3 s dip (e.g. a robot restarted) in a healthy run
        for t in 0..30 {
            let on = if (10..13).contains(&t) { 5 } else { 6 };
            h.observe(at(t, t * 10, on, 6, 3));
        }
        assert_eq!(h.verdict(), None, "{}", h.summary());
        // sick 20 s of 30, healthy at the very end
        let mut h = Health::new(Some(10.0));
        for t in 0..30 {
            let on = if t < 20 { 0 } else { 6 };
            h.observe(at(t, t * 10, on, 6, 3));
        }
        let v = h.verdict().unwrap();
        assert!(v.contains("healthy only"), "{v}");
    }

    #[test]
    fn nothing_delivered_in_a_long_run_fails_lockstep_has_no_rate() {
        let mut h = Health::new(None);
        for t in 0..30 {
            h.observe(at(t, t * 10, 6, 6, 0)); // lockstep: no rate check
        }
        assert_eq!(h.persistent(), Problems::default());
        assert!(h.verdict().unwrap().contains("no part delivered"));
        assert!(Health::new(None).verdict().unwrap().contains("no metrics"));
    }

    #[test]
    fn commands_from_a_second_writer_fail_the_run_at_once() {
        let mut h = Health::new(Some(10.0));
        for t in 0..30 {
            let mut s = at(t, t * 10, 6, 6, t / 5);
            // one burst of 4 foreign commands at 10 s; the counter stays
            s.foreign_cmds = if t >= 10 { 4 } else { 0 };
            let p = h.observe(s);
            assert_eq!(p.0.is_empty(), t < 10, "{t}: {p}");
        }
        assert!(h
            .status()
            .contains("4 cmd_vel samples from a second writer"));
        let v = h.verdict().unwrap();
        assert!(v.contains("another fleet"), "{v}");
    }
}
