//! The fleet's child processes: what runs, signals, stopping with a grace period, and the
//! watchdog restart rule (a child that exits with [`EXIT_WATCHDOG`] is restarted, at most
//! [`MAX_RESTARTS`] times; any other early exit fails the run).

use std::collections::BTreeMap;
use std::process::{Child, ChildStdin, ExitStatus};
use std::time::{Duration, Instant};

use super::{Fleet, BRIDGE};

/// A child's exit code when its watchdog ended it (`ros::watchdog::EXIT_WATCHDOG`).
const EXIT_WATCHDOG: i32 = 75;
/// Watchdog restarts allowed per process.
const MAX_RESTARTS: u32 = 3;
/// How long a stopped child may take to exit before it is killed.
pub(super) const STOP_GRACE: Duration = Duration::from_secs(5);
/// One robot_node process and the robots it hosts.
pub(super) struct RobotProc {
    pub(super) robots: Vec<String>,
    pub(super) label: String,
    pub(super) child: Child,
    pub(super) started: Instant,
}

pub(super) struct BridgeProc {
    pub(super) child: Child,
    pub(super) stdin: ChildStdin,
    pub(super) started: Instant,
}

/// Restart a process that exited with `code` after `restarts` restarts already?
fn should_restart(code: Option<i32>, restarts: u32) -> bool {
    code == Some(EXIT_WATCHDOG) && restarts < MAX_RESTARTS
}

/// `robot_3 x1, robot_7 x2`, or `none`.
pub(super) fn restarts_summary(r: &BTreeMap<String, u32>) -> String {
    if r.is_empty() {
        return "none".into();
    }
    r.iter()
        .map(|(n, k)| format!("{n} x{k}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// What a child's early exit means after `done` restarts: None to restart it, else the
/// run's failure.
fn exit_failure(label: &str, s: ExitStatus, done: u32) -> Option<String> {
    if should_restart(s.code(), done) {
        return None;
    }
    Some(match s.code() {
        Some(EXIT_WATCHDOG) => format!("{label} hung ({s}: watchdog) after {done} restarts"),
        _ => format!("{label} exited early ({s})"),
    })
}

pub(super) fn signal(pid: u32, sig: i32) {
    // SAFETY: plain kill(2) on a child we spawned and have not reaped yet.
    unsafe {
        libc::kill(pid as i32, sig);
    }
}

/// Wait up to `grace` for `child` to exit, then SIGKILL it. None if it had to be killed.
pub(super) fn wait_or_kill(child: &mut Child, grace: Duration) -> Option<ExitStatus> {
    let until = Instant::now() + grace;
    loop {
        match child.try_wait() {
            Ok(Some(s)) => return Some(s),
            Ok(None) if Instant::now() < until => std::thread::sleep(Duration::from_millis(20)),
            _ => {
                let _ = child.kill();
                let _ = child.wait();
                return None;
            }
        }
    }
}

/// SIGINT every child still running, the bridge first, wait for each up to
/// [`STOP_GRACE`], kill the rest. Returns the children that failed or had to be killed.
///
/// The bridge first: stopped the other way round, the bridge stepped on for the 0.1-0.5 s
/// the robots took to leave, with robots that had stopped commanding beside robots still
/// moving, and that teardown showed as contacts in the run's final metrics (10 contact
/// steps after every robot's zero command in a recorded main-job run, docs/RESULTS.md
/// 7.9). The bridge's last metrics line is the run's state when the stop began.
pub(super) fn stop_all(robots: &mut [RobotProc], bridge: &mut BridgeProc) -> Vec<String> {
    interrupt(&mut bridge.child);
    let mut failed: Vec<String> = stopped(BRIDGE, &mut bridge.child).into_iter().collect();
    for p in robots.iter_mut() {
        interrupt(&mut p.child);
    }
    failed.extend(
        robots
            .iter_mut()
            .filter_map(|p| stopped(&p.label, &mut p.child)),
    );
    failed
}

/// SIGINT `child` unless it has exited.
fn interrupt(child: &mut Child) {
    if let Ok(None) = child.try_wait() {
        signal(child.id(), libc::SIGINT);
    }
}

/// Wait for an interrupted child; how it failed, if it did.
fn stopped(label: &str, child: &mut Child) -> Option<String> {
    match wait_or_kill(child, STOP_GRACE) {
        Some(s) if !s.success() => Some(format!("{label} ({s})")),
        Some(_) => None,
        None => Some(format!("{label} (killed after {STOP_GRACE:?})")),
    }
}

impl Fleet {
    /// The bridge exited by itself: finished (lockstep), hung (restart) or failed.
    pub(super) fn check_bridge(&mut self) {
        let Ok(Some(s)) = self.bridge.child.try_wait() else {
            return;
        };
        if s.success() {
            self.bridge_finished = true;
            return;
        }
        let done = self.restarts.get(BRIDGE).copied().unwrap_or(0);
        if let Some(why) = exit_failure(BRIDGE, s, done) {
            self.failure = Some(why);
            return;
        }
        let at = self.at();
        match self.plan.spawn_bridge(true, self.metrics_tx.clone()) {
            Ok(b) => {
                println!(
                    "fleet: t={at:.1}s {BRIDGE} (pid {}) hung and was ended by its watchdog ({s}): restarted as pid {} (restart {}/{MAX_RESTARTS}; a new episode)",
                    self.bridge.child.id(),
                    b.child.id(),
                    done + 1
                );
                self.restarts.insert(BRIDGE.into(), done + 1);
                self.bridge = b;
            }
            Err(e) => self.failure = Some(format!("{BRIDGE} hung ({s}); restart failed: {e:#}")),
        }
    }

    /// A robot process that exits by itself before the end failed, unless its watchdog
    /// ended it (code 75): then it is restarted, up to MAX_RESTARTS times.
    pub(super) fn check_robots(&mut self) {
        for i in 0..self.robots.len() {
            let Ok(Some(s)) = self.robots[i].child.try_wait() else {
                continue;
            };
            let label = self.robots[i].label.clone();
            let done = self.restarts.get(&label).copied().unwrap_or(0);
            if let Some(why) = exit_failure(&label, s, done) {
                self.failure = Some(why);
                return;
            }
            let at = self.at();
            let robots = self.robots[i].robots.clone();
            match self.plan.spawn_robots(&robots, true) {
                Ok(p) => {
                    println!(
                        "fleet: t={at:.1}s {label} (pid {}) hung and was ended by its watchdog ({s}): restarted as pid {} (restart {}/{MAX_RESTARTS})",
                        self.robots[i].child.id(),
                        p.child.id(),
                        done + 1
                    );
                    self.restarts.insert(label, done + 1);
                    self.robots[i] = p;
                }
                Err(e) => {
                    self.failure = Some(format!("{label} hung ({s}); restart failed: {e:#}"));
                    return;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn restart_only_watchdog_exits_up_to_the_cap() {
        assert!(should_restart(Some(EXIT_WATCHDOG), 0));
        assert!(should_restart(Some(75), MAX_RESTARTS - 1));
        assert!(!should_restart(Some(75), MAX_RESTARTS));
        for other in [Some(0), Some(1), Some(2), None] {
            assert!(!should_restart(other, 0), "{other:?}");
        }
        let mut r = BTreeMap::new();
        assert_eq!(restarts_summary(&r), "none");
        r.insert("robot_7".to_string(), 2);
        r.insert("robot_3".to_string(), 1);
        assert_eq!(restarts_summary(&r), "robot_3 x1, robot_7 x2");
    }
}
