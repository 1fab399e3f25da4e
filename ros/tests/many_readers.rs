//! Many readers on one participant, created faster than its threads run (issue 46: "the
//! fleet itself stops near 150 robots").
//!
//! A sim_bridge creates one cmd_vel reader per robot in a tight loop, and a robot_node
//! one pose and one has_part reader per entity of the floor. RustDDS passes each new
//! reader through two bounded queues, and the published 0.15.1 used `try_send` on both:
//!
//! 1. to the participant's event loop thread (100 slots): whenever the application got
//!    100 readers ahead of the event loop, `create_datareader` failed with `Poisoned {
//!    reason: "Cannot add DataReader. Error: sending on a full channel" }` and the bridge
//!    exited. On this 2-core machine, shared with a training job and the fleet's own
//!    robot processes, the event loop thread often waits a few milliseconds for a core,
//!    which is as long as 100 readers take: 200 and 300 robots failed every time, 150 in
//!    one start of two. Writers already waited for a free slot; readers now do too
//!    (docs/upstream/rustdds/0020-*).
//! 2. from the event loop to the Discovery thread (1024 slots, two commands per reader:
//!    AddTopic and AddLocalReader): once that was fixed, a 500-robot fleet's processes
//!    lost hundreds of AddLocalReader commands ("Failed to inform Discovery about the new
//!    endpoint: sending on a full channel"), and those readers were never announced, so
//!    no remote writer ever matched them. The channel is unbounded now
//!    (docs/upstream/rustdds/0021-*).
//!
//! Each test makes the starved thread certain instead of likely: the participant's
//! threads share one CPU with the test thread, and the thread under test runs under
//! SCHED_IDLE (only when nothing else on that CPU wants to), set with util-linux's
//! `taskset` and `chrt` on the threads' ids. The test thread never sleeps while it
//! creates readers (in the second test a spinning thread also keeps that CPU busy while
//! the test thread waits for the event loop), so before the fixes the starved thread
//! never drains its queue in time.

use std::collections::BTreeSet;
use std::fs;
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use msgs::{Profile, Twist};
use ros::node::node;
use ros::{context_with, subscription, NodeSpec, Security};
use ros2_client::dds::Context;
use ros2_client::Node;

/// Readers created back to back: a 300-robot bridge's cmd_vel readers, three times the
/// channel's 100 slots.
const READERS: usize = 300;

/// Thread ids of this process whose name (`comm`, 15 bytes) starts with `prefix`.
fn threads_named(prefix: &str) -> BTreeSet<u32> {
    fs::read_dir("/proc/self/task")
        .expect("/proc/self/task")
        .filter_map(|e| {
            let e = e.ok()?;
            let comm = fs::read_to_string(e.path().join("comm")).ok()?;
            comm.starts_with(prefix)
                .then(|| e.file_name().to_str()?.parse().ok())
                .flatten()
        })
        .collect()
}

/// The id of the calling thread (`/proc/thread-self` links to `<pid>/task/<tid>`).
fn my_tid() -> u32 {
    let link = fs::read_link("/proc/thread-self").expect("/proc/thread-self");
    link.file_name()
        .and_then(|s| s.to_str())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("thread id from {}", link.display()))
}

/// The first CPU the calling thread may run on.
fn first_allowed_cpu() -> u32 {
    let status = fs::read_to_string("/proc/thread-self/status").expect("thread status");
    let list = status
        .lines()
        .find_map(|l| l.strip_prefix("Cpus_allowed_list:"))
        .expect("Cpus_allowed_list in /proc/thread-self/status")
        .trim();
    list.split([',', '-'])
        .next()
        .and_then(|c| c.parse().ok())
        .unwrap_or_else(|| panic!("CPU list {list:?}"))
}

/// Back to SCHED_OTHER. Best effort: an unprivileged thread may leave SCHED_IDLE only
/// within its RLIMIT_NICE; staying idle only slows the participant's shutdown.
fn unstarve(tid: &str) {
    let _ = Command::new("chrt").args(["-o", "-p", "0", tid]).output();
}

fn run(cmd: &str, args: &[&str]) {
    let out = Command::new(cmd)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("{cmd} (util-linux) {args:?}: {e}"));
    assert!(
        out.status.success(),
        "{cmd} {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The tests in this file one at a time: each finds the threads its participant started
/// by name, and pins its own thread.
static SERIAL: Mutex<()> = Mutex::new(());

const EVENT_LOOP: &str = "RustDDS Partici"; // "RustDDS Participant {id} event loop"
const DISCOVERY: &str = "RustDDS discove"; // "RustDDS discovery thread"

/// A participant on `d` with one node, its threads on the calling thread's CPU, and the
/// id of its thread named `starve` (put under SCHED_IDLE).
fn starved_participant(d: u16, name: &str, starve: &str) -> (Context, Node, String) {
    // This thread, and the participant's threads it starts below (they inherit the
    // affinity), on one CPU.
    let cpu = first_allowed_cpu();
    run(
        "taskset",
        &["-p", "-c", &cpu.to_string(), &my_tid().to_string()],
    );
    let before = threads_named(starve);
    let ctx = context_with(d, &Security::Off).expect("context");
    let n = node(
        &ctx,
        &NodeSpec {
            namespace: "/",
            name,
            enable_rosout: false,
        },
    )
    .expect("node");
    let new: Vec<u32> = threads_named(starve).difference(&before).copied().collect();
    assert_eq!(new.len(), 1, "one new thread named {starve}: {new:?}");
    let tid = new[0].to_string();
    run("chrt", &["-i", "-p", "0", &tid]);
    (ctx, n, tid)
}

/// A thread that keeps the calling thread's CPU busy (it inherits the affinity) until
/// dropped, so that a SCHED_IDLE thread there does not run even while the test thread
/// waits (for a lock, or at the event loop's full queue).
struct Busy(Arc<AtomicBool>, Option<std::thread::JoinHandle<()>>);

impl Busy {
    fn start() -> Self {
        let on = Arc::new(AtomicBool::new(true));
        let flag = on.clone();
        let h = std::thread::spawn(move || {
            while flag.load(Ordering::Relaxed) {
                std::hint::spin_loop();
            }
        });
        Busy(on, Some(h))
    }
}

impl Drop for Busy {
    fn drop(&mut self) {
        self.0.store(false, Ordering::Relaxed);
        if let Some(h) = self.1.take() {
            let _ = h.join();
        }
    }
}

/// Create `count` readers on `n` back to back (topics `/robot_{i}/cmd_vel`); the error
/// of the first refused one.
fn create_readers(n: &mut Node, count: usize, t0: Instant) -> Result<Vec<impl Sized>, String> {
    let mut readers = Vec::with_capacity(count);
    for i in 0..count {
        let name = format!("/robot_{i}/cmd_vel");
        match subscription::<Twist>(n, &name, Profile::RobotStream) {
            Ok(s) => readers.push(s),
            Err(e) => {
                return Err(format!(
                    "reader {i} of {count} refused after {:.3} s: {e:#}",
                    t0.elapsed().as_secs_f64()
                ))
            }
        }
    }
    Ok(readers)
}

#[test]
fn readers_created_faster_than_the_event_loop_runs_all_exist() {
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let d = test_domains::domain(0);
    let (_ctx, mut n, ev_loop) = starved_participant(d, "many_readers", EVENT_LOOP);
    let t0 = Instant::now();
    let made = create_readers(&mut n, READERS, t0);
    // The event loop back to normal scheduling, so the participant shuts down promptly.
    unstarve(&ev_loop);
    let readers = made.unwrap_or_else(|e| panic!("{e}"));
    eprintln!(
        "{READERS} readers created in {:.3} s with the event loop under SCHED_IDLE",
        t0.elapsed().as_secs_f64()
    );
    assert_eq!(readers.len(), READERS);
}

/// Readers for the second test: 2,400 commands to Discovery, over its old 1,024 slots.
const ANNOUNCED: usize = 1200;

#[test]
fn readers_created_faster_than_discovery_runs_are_all_announced() {
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let d = test_domains::domain(1);
    // The observer: a second participant on the domain, which must discover every reader.
    let observer = context_with(d, &Security::Off).expect("observer context");
    let (_ctx, mut n, discovery) = starved_participant(d, "many_readers", DISCOVERY);
    let t0 = Instant::now();
    let busy = Busy::start();
    let made = create_readers(&mut n, ANNOUNCED, t0);
    drop(busy);
    let created = t0.elapsed().as_secs_f64();
    unstarve(&discovery);
    let _readers = made.unwrap_or_else(|e| panic!("{e}"));

    let announced = |dp: &ros2_client::dds::rustdds::DomainParticipant| {
        dp.discovered_readers()
            .iter()
            .filter(|r| {
                let t = r.subscription_topic_data.topic_name();
                t.starts_with("rt/robot_") && t.ends_with("/cmd_vel")
            })
            .count()
    };
    let dp = observer.domain_participant();
    let deadline = Instant::now() + Duration::from_secs(30);
    let mut seen = announced(&dp);
    while seen < ANNOUNCED && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(200));
        seen = announced(&dp);
    }
    eprintln!(
        "{ANNOUNCED} readers created in {created:.3} s with Discovery under SCHED_IDLE; \
         the observer discovered {seen} within {:.1} s",
        t0.elapsed().as_secs_f64()
    );
    assert_eq!(
        seen, ANNOUNCED,
        "readers never announced to the other participant (Discovery dropped their commands)"
    );
}
