//! Many readers on one participant, created while its event loop gets no CPU (issue 46:
//! "the fleet itself stops near 150 robots").
//!
//! A sim_bridge creates one cmd_vel reader per robot in a tight loop, and a robot_node
//! one pose and one has_part reader per peer. RustDDS hands each new reader to its
//! participant's event loop thread on a channel of 100 slots. The published 0.15.1 used
//! `try_send` there: whenever the application got 100 readers ahead of the event loop,
//! `create_datareader` failed with `Poisoned { reason: "Cannot add DataReader. Error:
//! sending on a full channel" }` and the bridge exited. On this 2-core machine, shared
//! with a training job and the fleet's own robot processes, the event loop thread often
//! waits a few milliseconds for a core, which is as long as 100 readers take: 200 and 300
//! robots failed every time, 150 in one start of two. Writers already waited for a free
//! slot; the fix in third_party/rustdds (docs/upstream/rustdds/0020-*) makes readers wait
//! the same way.
//!
//! The test makes the starved event loop certain instead of likely: the participant's
//! threads share one CPU with the test thread, and its event loop thread runs under
//! SCHED_IDLE (only when nothing else on that CPU wants to), set with util-linux's
//! `taskset` and `chrt` on the threads' ids. The test thread never sleeps while it
//! creates readers, so before the fix the event loop never drains the channel and
//! reader 101 or so is refused; after it, the test thread waits at the full channel,
//! the event loop runs, and all readers exist.

use std::collections::BTreeSet;
use std::fs;
use std::process::Command;
use std::time::Instant;

use msgs::{Profile, Twist};
use ros::node::node;
use ros::{context_with, subscription, NodeSpec, Security};

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

#[test]
fn readers_created_faster_than_the_event_loop_runs_all_exist() {
    let d = test_domains::domain(0);

    // This thread, and the participant's threads it starts below (they inherit the
    // affinity), on one CPU.
    let cpu = first_allowed_cpu();
    run(
        "taskset",
        &["-p", "-c", &cpu.to_string(), &my_tid().to_string()],
    );

    const EVENT_LOOP: &str = "RustDDS Partici"; // "RustDDS Participant {id} event loop"
    let before = threads_named(EVENT_LOOP);
    let ctx = context_with(d, &Security::Off).expect("context");
    let mut n = node(
        &ctx,
        &NodeSpec {
            namespace: "/",
            name: "many_readers",
            enable_rosout: false,
        },
    )
    .expect("node");
    let ev_loop: Vec<u32> = threads_named(EVENT_LOOP)
        .difference(&before)
        .copied()
        .collect();
    assert_eq!(ev_loop.len(), 1, "one new event loop thread: {ev_loop:?}");
    let ev_loop = ev_loop[0].to_string();
    run("chrt", &["-i", "-p", "0", &ev_loop]);

    let t0 = Instant::now();
    let mut readers = Vec::with_capacity(READERS);
    let mut refused = None;
    for i in 0..READERS {
        let name = format!("/robot_{i}/cmd_vel");
        match subscription::<Twist>(&mut n, &name, Profile::RobotStream) {
            Ok(s) => readers.push(s),
            Err(e) => {
                refused = Some(format!(
                    "reader {i} of {READERS} refused after {:.3} s: {e:#}",
                    t0.elapsed().as_secs_f64()
                ));
                break;
            }
        }
    }
    // The event loop back to normal scheduling, so the participant shuts down promptly.
    run("chrt", &["-o", "-p", "0", &ev_loop]);
    if let Some(r) = refused {
        panic!("{r}");
    }
    eprintln!(
        "{READERS} readers created in {:.3} s with the event loop under SCHED_IDLE",
        t0.elapsed().as_secs_f64()
    );
    assert_eq!(readers.len(), READERS);
}
