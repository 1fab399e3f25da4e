//! Start-up / stall watchdog for a node process.
//!
//! A node records the [`NodeStage`] it is in and a heartbeat (two atomics): during start-up at
//! every stage, entity created and retry attempt (so a long but progressing start-up, e.g.
//! 100 robots in one process, is not cut short), once running every event-loop iteration.
//! A helper thread checks them with [`verdict`] (a pure function of the times, tested with
//! a fake clock) and calls `on_stuck`, which normally logs and exits the process with
//! [`EXIT_WATCHDOG`]: a thread stuck inside a library cannot be joined or cancelled.
//!
//! It was written for a RustDDS 0.15 discovery deadlock (fixed at its root in
//! `third_party/rustdds`, ADR 0005); it stays as the net under anything else that could
//! hang a node, so that `tending fleet` can restart it instead of running a dead fleet.

use std::fmt;
use std::marker::PhantomData;
use std::sync::atomic::{AtomicU64, AtomicU8, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Exit code of a process the watchdog ended (`EX_TEMPFAIL`: try again).
pub const EXIT_WATCHDOG: i32 = 75;

/// The stages of one kind of node (an enum with a `u8` representation): where its main
/// path is, for the watchdog (not a curriculum stage of training, `learn::Stage`).
pub trait NodeStage: Copy + Eq + fmt::Debug + Send + Sync + 'static {
    /// The stage a new watchdog starts in.
    const FIRST: Self;
    fn to_u8(self) -> u8;
    /// Unknown values must map to a stage (e.g. the done stage).
    fn from_u8(x: u8) -> Self;
    /// Before the first event-loop iteration (the start-up limit applies).
    fn is_startup(self) -> bool;
    /// Shutting down: not watched any more.
    fn is_done(self) -> bool;
    /// What the node is doing, for the message ("creating the DDS context").
    fn describe(self) -> &'static str;
}

/// Defines a node's stage enum and its [`NodeStage`] implementation from one list: each stage
/// with its description, in order: the start-up stages (the start-up limit applies), the
/// running ones (the stall limit applies), and the done stage (not watched).
///
/// ```
/// ros::watchdog_stages! {
///     /// Where the example node is.
///     pub enum NodeStage {
///         startup { Context => "creating the DDS context", }
///         running { Running => "in the event loop", }
///         done Done => "in shutdown",
///     }
/// }
/// use ros::watchdog::NodeStage as _;
/// assert!(NodeStage::Context.is_startup() && !NodeStage::Running.is_startup());
/// assert!(NodeStage::Done.is_done());
/// assert_eq!(NodeStage::from_u8(1), NodeStage::Running);
/// ```
#[macro_export]
macro_rules! watchdog_stages {
    (
        $(#[$meta:meta])*
        pub enum $name:ident {
            startup {
                $( $(#[$smeta:meta])* $start:ident => $sdesc:literal, )+
            }
            running {
                $(#[$lmeta:meta])* $first_loop:ident => $ldesc:literal,
                $( $(#[$rmeta:meta])* $rest:ident => $rdesc:literal, )*
            }
            $(#[$dmeta:meta])* done $done:ident => $ddesc:literal $(,)?
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        #[repr(u8)]
        pub enum $name {
            $( $(#[$smeta])* $start, )+
            $(#[$lmeta])* $first_loop,
            $( $(#[$rmeta])* $rest, )*
            $(#[$dmeta])* $done,
        }

        impl $name {
            const ALL: &'static [$name] =
                &[$( $name::$start, )+ $name::$first_loop, $( $name::$rest, )* $name::$done];
        }

        impl $crate::watchdog::NodeStage for $name {
            const FIRST: Self = Self::ALL[0];

            fn to_u8(self) -> u8 {
                self as u8
            }

            /// Unknown values are the last (done) stage.
            fn from_u8(x: u8) -> Self {
                Self::ALL
                    .get(x as usize)
                    .copied()
                    .unwrap_or($name::$done)
            }

            fn is_startup(self) -> bool {
                (self as u8) < ($name::$first_loop as u8)
            }

            fn is_done(self) -> bool {
                self == $name::$done
            }

            fn describe(self) -> &'static str {
                match self {
                    $( $name::$start => $sdesc, )+
                    $name::$first_loop => $ldesc,
                    $( $name::$rest => $rdesc, )*
                    $name::$done => $ddesc,
                }
            }
        }
    };
}

/// Timeouts; zero disables the check.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Longest time without progress before the first event-loop iteration.
    pub startup: Duration,
    /// Longest time between two event-loop iterations.
    pub stall: Duration,
}

impl Limits {
    pub const DISABLED: Limits = Limits {
        startup: Duration::ZERO,
        stall: Duration::ZERO,
    };

    /// From seconds as given on the command line (`startup_timeout_s`, `stall_timeout_s`).
    pub fn from_secs(startup: f64, stall: f64) -> Limits {
        Limits {
            startup: Duration::from_secs_f64(startup),
            stall: Duration::from_secs_f64(stall),
        }
    }
}

/// Why the watchdog fires.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stuck<S> {
    pub stage: S,
    pub startup: bool,
    /// How long since the last progress / heartbeat.
    pub for_: Duration,
}

impl<S: NodeStage> fmt::Display for Stuck<S> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let what = if self.startup {
            "start-up made no progress"
        } else {
            "the event loop stalled"
        };
        write!(
            f,
            "{what} for {:.1} s, stuck {}; exiting with code {EXIT_WATCHDOG} so that the launcher restarts the process",
            self.for_.as_secs_f64(),
            self.stage.describe()
        )
    }
}

/// The decision, from the stage and times measured from the watchdog's creation.
pub fn verdict<S: NodeStage>(
    stage: S,
    now: Duration,
    last_beat: Duration,
    lim: &Limits,
) -> Option<Stuck<S>> {
    if stage.is_done() {
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
pub struct Watchdog<S: NodeStage> {
    t0: Instant,
    stage: AtomicU8,
    beat_us: AtomicU64,
    limits: Limits,
    _stage: PhantomData<S>,
}

impl<S: NodeStage> Watchdog<S> {
    pub fn new(limits: Limits) -> Arc<Self> {
        Arc::new(Watchdog {
            t0: Instant::now(),
            stage: AtomicU8::new(S::FIRST.to_u8()),
            beat_us: AtomicU64::new(0),
            limits,
            _stage: PhantomData,
        })
    }

    /// A watchdog nobody watches (for callers without one).
    pub fn disabled() -> Arc<Self> {
        Self::new(Limits::DISABLED)
    }

    /// Enter a stage (also a heartbeat).
    pub fn stage(&self, s: S) {
        self.beat();
        self.stage.store(s.to_u8(), Ordering::SeqCst);
    }

    /// Progress (start-up) or the event loop is alive.
    pub fn beat(&self) {
        let us = self.t0.elapsed().as_micros() as u64;
        self.beat_us.store(us, Ordering::SeqCst);
    }

    pub fn current_stage(&self) -> S {
        S::from_u8(self.stage.load(Ordering::SeqCst))
    }

    /// The verdict now.
    pub fn check(&self) -> Option<Stuck<S>> {
        let last = Duration::from_micros(self.beat_us.load(Ordering::SeqCst));
        verdict(self.current_stage(), self.t0.elapsed(), last, &self.limits)
    }

    /// Start the watching thread (nothing if both limits are zero). On a verdict it calls
    /// `on_stuck` (which normally logs and exits the process); if that returns, the thread
    /// ends.
    pub fn spawn(
        self: &Arc<Self>,
        on_stuck: impl FnOnce(Stuck<S>) + Send + 'static,
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
                if wd.current_stage().is_done() {
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

    crate::watchdog_stages! {
        pub enum Test {
            startup {
                Context => "creating the DDS context",
                Writers => "creating the writers",
            }
            running {
                Running => "the event loop",
            }
            done Done => "shutdown",
        }
    }

    #[test]
    fn the_macro_numbers_stages_in_order_and_maps_unknown_values_to_done() {
        for (i, st) in [Test::Context, Test::Writers, Test::Running, Test::Done]
            .into_iter()
            .enumerate()
        {
            assert_eq!(st.to_u8(), i as u8);
            assert_eq!(Test::from_u8(i as u8), st);
            assert_eq!(st.is_startup(), i < 2, "{st:?}");
            assert_eq!(st.is_done(), i == 3, "{st:?}");
        }
        assert_eq!(Test::from_u8(200), Test::Done);
        assert_eq!(Test::FIRST, Test::Context);
    }

    const fn s(x: u64) -> Duration {
        Duration::from_secs(x)
    }
    const LIM: Limits = Limits {
        startup: Duration::from_secs(10),
        stall: Duration::from_secs(5),
    };

    #[test]
    fn startup_timeout_names_the_stage() {
        assert_eq!(verdict(Test::Context, s(9), s(0), &LIM), None);
        let v = verdict(Test::Context, s(12), s(2), &LIM).unwrap();
        assert!(v.startup);
        assert_eq!(v.stage, Test::Context);
        assert_eq!(v.for_, s(10));
        let msg = v.to_string();
        assert!(msg.contains("creating the DDS context"), "{msg}");
        assert!(msg.contains("75"), "{msg}");
        // a long start-up that keeps making progress is fine; start-up uses its own limit
        assert_eq!(verdict(Test::Writers, s(60), s(55), &LIM), None);
        assert_eq!(verdict(Test::Writers, s(60), s(52), &LIM), None);
        assert!(verdict(Test::Running, s(60), s(52), &LIM).is_some());
    }

    #[test]
    fn stall_after_startup() {
        assert_eq!(verdict(Test::Running, s(100), s(97), &LIM), None);
        let v = verdict(Test::Running, s(100), s(95), &LIM).unwrap();
        assert!(!v.startup);
        assert_eq!(v.for_, s(5));
        assert!(v.to_string().contains("event loop stalled"));
        assert_eq!(verdict(Test::Done, s(1000), s(0), &LIM), None);
    }

    #[test]
    fn zero_disables() {
        assert_eq!(
            verdict(Test::Context, s(1000), s(0), &Limits::DISABLED),
            None
        );
        assert_eq!(
            verdict(Test::Running, s(1000), s(0), &Limits::DISABLED),
            None
        );
        assert!(Watchdog::<Test>::disabled()
            .spawn(|_| ())
            .unwrap()
            .is_none());
    }

    #[test]
    fn thread_fires_on_a_stuck_stage_and_not_on_a_live_loop() {
        // stuck in start-up: fires (bounds generous: 50 ms limit, 20 s to notice)
        let wd = Watchdog::<Test>::new(Limits {
            startup: Duration::from_millis(50),
            stall: Duration::ZERO,
        });
        wd.stage(Test::Writers);
        let (tx, rx) = std::sync::mpsc::channel();
        let h = wd.spawn(move |st| tx.send(st).unwrap()).unwrap().unwrap();
        let st = rx.recv_timeout(s(20)).expect("watchdog did not fire");
        assert_eq!(st.stage, Test::Writers);
        assert!(st.startup);
        h.join().unwrap();

        // running and beating, then done: never fires
        let wd = Watchdog::<Test>::new(Limits {
            startup: s(30),
            stall: s(30),
        });
        wd.stage(Test::Running);
        let (tx, rx) = std::sync::mpsc::channel::<Stuck<Test>>();
        let h = wd.spawn(move |st| tx.send(st).unwrap()).unwrap().unwrap();
        wd.beat();
        wd.stage(Test::Done);
        h.join().unwrap();
        assert!(rx.try_recv().is_err());
    }
}
