//! Start-up / stall watchdog: a workaround for a RustDDS 0.15 deadlock (docs/bench/ros.md).
//!
//! About 1 in 20 processes started together hangs forever while creating DDS entities: the
//! RustDDS discovery thread holds the discovery-DB read lock while blocked on a full
//! channel, our thread waits for the write lock, the RustDDS event loop waits behind it.
//! Nothing in-process can undo that, so the watchdog ends the process with
//! [`EXIT_WATCHDOG`] (75, `EX_TEMPFAIL`) and a launcher (`tending fleet`) restarts it.
//!
//! The main path records its [`Stage`] and a heartbeat (two atomics): during start-up at
//! every stage, entity created and retry attempt (so a long but progressing start-up, e.g.
//! 100 robots in one process, is not cut short), once running every event-loop iteration; a helper thread checks them with [`verdict`] (a pure function
//! of the times, tested with a fake clock) and calls `std::process::exit` (the deadlocked
//! threads cannot be joined).

use std::sync::atomic::{AtomicU64, AtomicU8, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Exit code of a process the watchdog ended (`EX_TEMPFAIL`: try again).
pub const EXIT_WATCHDOG: i32 = 75;

/// Where the main path is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Stage {
    /// Loading the controller(s).
    Controller = 0,
    /// Creating the DDS context.
    Context = 1,
    /// Creating the ROS 2 node and its spinner.
    Node = 2,
    /// Creating the cmd_vel writer(s).
    Writers = 3,
    /// Creating the start-up subscriptions (own topics, /clock).
    Subscriptions = 4,
    /// Event loop running (heartbeat every iteration).
    Running = 5,
    /// Event loop running, creating a subscription to a discovered topic.
    DiscoveredSubscription = 6,
    /// Event loop left (shutting down): not watched.
    Done = 7,
}

impl Stage {
    fn from_u8(x: u8) -> Stage {
        match x {
            0 => Stage::Controller,
            1 => Stage::Context,
            2 => Stage::Node,
            3 => Stage::Writers,
            4 => Stage::Subscriptions,
            5 => Stage::Running,
            6 => Stage::DiscoveredSubscription,
            _ => Stage::Done,
        }
    }

    /// Before the first event-loop iteration.
    pub fn is_startup(self) -> bool {
        (self as u8) < (Stage::Running as u8)
    }

    pub fn describe(self) -> &'static str {
        match self {
            Stage::Controller => "loading the controller",
            Stage::Context => "creating the DDS context",
            Stage::Node => "creating the ROS 2 node",
            Stage::Writers => "creating the cmd_vel writer(s)",
            Stage::Subscriptions => "creating the start-up subscriptions",
            Stage::Running => "the control loop",
            Stage::DiscoveredSubscription => "creating a subscription to a discovered topic",
            Stage::Done => "shutdown",
        }
    }
}

/// Timeouts; zero disables the check.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Longest time without progress before the first event-loop iteration.
    pub startup: Duration,
    /// Longest time between two event-loop iterations.
    pub stall: Duration,
}

/// Why the watchdog fires.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stuck {
    pub stage: Stage,
    pub startup: bool,
    /// How long since the last progress / heartbeat.
    pub for_: Duration,
}

impl std::fmt::Display for Stuck {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.startup {
            write!(
                f,
                "start-up made no progress for {:.1} s, stuck {} (likely the RustDDS entity-creation deadlock); exiting with code {EXIT_WATCHDOG} so that the launcher restarts the node",
                self.for_.as_secs_f64(),
                self.stage.describe()
            )
        } else {
            write!(
                f,
                "control loop stalled for {:.1} s, stuck in {} (likely the RustDDS entity-creation deadlock); exiting with code {EXIT_WATCHDOG} so that the launcher restarts the node",
                self.for_.as_secs_f64(),
                self.stage.describe()
            )
        }
    }
}

/// The decision, from the stage and times measured from the watchdog's creation.
pub fn verdict(stage: Stage, now: Duration, last_beat: Duration, lim: &Limits) -> Option<Stuck> {
    if stage == Stage::Done {
        return None;
    }
    let startup = stage.is_startup();
    let limit = if startup { lim.startup } else { lim.stall };
    let since = now.saturating_sub(last_beat);
    if !limit.is_zero() && since >= limit {
        return Some(Stuck {
            stage,
            startup,
            for_: since,
        });
    }
    None
}

/// Shared state: the stage and the last heartbeat (µs since `t0`).
#[derive(Debug)]
pub struct Watchdog {
    t0: Instant,
    stage: AtomicU8,
    beat_us: AtomicU64,
    limits: Limits,
}

impl Watchdog {
    pub fn new(limits: Limits) -> Arc<Watchdog> {
        Arc::new(Watchdog {
            t0: Instant::now(),
            stage: AtomicU8::new(Stage::Controller as u8),
            beat_us: AtomicU64::new(0),
            limits,
        })
    }

    /// A watchdog nobody watches (for callers without one).
    pub fn disabled() -> Arc<Watchdog> {
        Self::new(Limits {
            startup: Duration::ZERO,
            stall: Duration::ZERO,
        })
    }

    /// Enter a stage (also a heartbeat).
    pub fn stage(&self, s: Stage) {
        self.beat();
        self.stage.store(s as u8, Ordering::SeqCst);
    }

    /// Progress (start-up) or the event loop is alive.
    pub fn beat(&self) {
        let us = self.t0.elapsed().as_micros() as u64;
        self.beat_us.store(us, Ordering::SeqCst);
    }

    pub fn current_stage(&self) -> Stage {
        Stage::from_u8(self.stage.load(Ordering::SeqCst))
    }

    /// The verdict now.
    pub fn check(&self) -> Option<Stuck> {
        let stage = self.current_stage();
        let last = Duration::from_micros(self.beat_us.load(Ordering::SeqCst));
        verdict(stage, self.t0.elapsed(), last, &self.limits)
    }

    /// Start the watching thread (nothing if both limits are zero). On a verdict it calls
    /// `on_stuck` (which normally logs and exits the process); if that returns, the thread
    /// ends.
    pub fn spawn(
        self: &Arc<Self>,
        on_stuck: impl FnOnce(Stuck) + Send + 'static,
    ) -> std::io::Result<Option<std::thread::JoinHandle<()>>> {
        if self.limits.startup.is_zero() && self.limits.stall.is_zero() {
            return Ok(None);
        }
        let wd = self.clone();
        let shortest = [self.limits.startup, self.limits.stall]
            .into_iter()
            .filter(|d| !d.is_zero())
            .min()
            .unwrap_or(Duration::from_secs(1));
        let period = (shortest / 10).clamp(Duration::from_millis(1), Duration::from_millis(250));
        std::thread::Builder::new()
            .name("watchdog".into())
            .spawn(move || loop {
                std::thread::sleep(period);
                if wd.current_stage() == Stage::Done {
                    return;
                }
                if let Some(s) = wd.check() {
                    on_stuck(s);
                    return;
                }
            })
            .map(Some)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const fn s(x: u64) -> Duration {
        Duration::from_secs(x)
    }
    const LIM: Limits = Limits {
        startup: Duration::from_secs(10),
        stall: Duration::from_secs(5),
    };

    #[test]
    fn startup_timeout_names_the_stage() {
        assert_eq!(verdict(Stage::Node, s(9), s(0), &LIM), None);
        let v = verdict(Stage::Node, s(12), s(2), &LIM).unwrap();
        assert!(v.startup);
        assert_eq!(v.stage, Stage::Node);
        assert_eq!(v.for_, s(10));
        let msg = v.to_string();
        assert!(msg.contains("creating the ROS 2 node"), "{msg}");
        assert!(msg.contains("75"), "{msg}");
        // a long start-up that keeps making progress (e.g. 100 robots) is fine; start-up
        // uses its own limit, not the stall one
        assert_eq!(verdict(Stage::Writers, s(60), s(55), &LIM), None);
        assert_eq!(verdict(Stage::Writers, s(60), s(52), &LIM), None);
        assert!(verdict(Stage::Running, s(60), s(52), &LIM).is_some());
    }

    #[test]
    fn stall_after_startup() {
        // running long after the start-up limit, heartbeats recent: fine
        assert_eq!(verdict(Stage::Running, s(100), s(97), &LIM), None);
        let v = verdict(Stage::DiscoveredSubscription, s(100), s(95), &LIM).unwrap();
        assert!(!v.startup);
        assert_eq!(v.for_, s(5));
        assert!(v.to_string().contains("discovered topic"));
        assert_eq!(verdict(Stage::Done, s(1000), s(0), &LIM), None);
    }

    #[test]
    fn zero_disables() {
        let off = Limits {
            startup: Duration::ZERO,
            stall: Duration::ZERO,
        };
        assert_eq!(verdict(Stage::Context, s(1000), s(0), &off), None);
        assert_eq!(verdict(Stage::Running, s(1000), s(0), &off), None);
        assert!(Watchdog::disabled().spawn(|_| ()).unwrap().is_none());
    }

    #[test]
    fn thread_fires_on_a_stuck_stage_and_not_on_a_live_loop() {
        // stuck in start-up: fires (bounds generous: 50 ms limit, 20 s to notice)
        let wd = Watchdog::new(Limits {
            startup: Duration::from_millis(50),
            stall: Duration::ZERO,
        });
        wd.stage(Stage::Writers);
        let (tx, rx) = std::sync::mpsc::channel();
        let h = wd.spawn(move |st| tx.send(st).unwrap()).unwrap().unwrap();
        let st = rx.recv_timeout(s(20)).expect("watchdog did not fire");
        assert_eq!(st.stage, Stage::Writers);
        assert!(st.startup);
        h.join().unwrap();

        // running and beating, then done: never fires
        let wd = Watchdog::new(Limits {
            startup: s(30),
            stall: s(30),
        });
        wd.stage(Stage::Running);
        let (tx, rx) = std::sync::mpsc::channel::<Stuck>();
        let h = wd.spawn(move |st| tx.send(st).unwrap()).unwrap().unwrap();
        wd.beat();
        wd.stage(Stage::Done);
        h.join().unwrap();
        assert!(rx.try_recv().is_err());
    }
}
