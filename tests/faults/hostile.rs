//! Fault (c): a hostile publisher on the fleet's domain (this test process, over DDS):
//! NaN poses, huge poses, wrong-length CDR payloads (on a pose topic and on a cmd_vel
//! topic), NaN cmd_vel, a 10 kHz flood of NaN poses on a real robot's own pose topic, and
//! a foreign publisher claiming `/robot_1/pose`. Nothing may crash, RSS stays bounded,
//! the fleet keeps delivering, and every rejection is counted (robot_node's `dropped`
//! counters, sim_bridge's `cmds_dropped_*`). The impostor's *valid* poses come from
//! another DDS writer than the bridge's, which every robot_node has pinned the topic to
//! (docs/adr/0004-writer-pinning.md): they are refused and counted as
//! `dropped/foreign_writer` by all three robots, no pin changes hands, and robot_1 keeps
//! acting on its real pose.
//!
//! With DDS Security on (`TENDING_FAULTS_SECURE=1`, common/mod.rs) the hostile node is an
//! outsider without an enclave, as an attacker on the network would be: none of its
//! samples may reach an application (every rejection counter stays 0, the impostor is
//! never seen), and the fleet keeps delivering as before.

mod common;
use common::*;

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use msgs::{PoseStamped, Profile, RosMessage, Time, Twist};
use ros2_client::{Context, ContextOptions, Name, NodeName, NodeOptions, Publisher};
use serde::Serialize;

/// 3 bytes where a PoseStamped or Twist is expected.
#[derive(Serialize)]
struct Short {
    a: u8,
    b: u8,
    c: u8,
}

fn publisher<M: Serialize>(
    node: &mut ros2_client::Node,
    name: &str,
    ty: ros2_client::MessageTypeName,
    profile: Profile,
) -> Publisher<M> {
    let qos = profile.qos();
    let t = node
        .create_topic(&Name::parse(name).unwrap(), ty, &qos)
        .unwrap();
    node.create_publisher(&t, Some(qos)).unwrap()
}

fn pose(x: f64, y: f64) -> PoseStamped {
    PoseStamped::planar(Time::from_secs_f64(0.0), "map", x, y)
}

/// How long the hostile node publishes, s.
const HOSTILE_S: f64 = 12.0;
/// How long the fleet runs after the hostile node is gone, s.
const AFTER_S: f64 = 8.0;

type Json = serde_json::Value;

/// The bridge and three robot nodes of setup 3.3_1.
struct Fleet {
    bridge: Proc,
    robots: Vec<Proc>,
}

impl Fleet {
    fn start(domain: u16, setup: &str) -> Self {
        let bridge = Proc::spawn("sim_bridge", bridge_cmd(domain, setup, &[]));
        let robots = (0..3)
            .map(|i| {
                let n = format!("robot_{i}");
                Proc::spawn(&n, robot_cmd(&n, domain, setup, &[]))
            })
            .collect();
        Self { bridge, robots }
    }

    fn robot_counters(&self) -> Vec<Json> {
        self.robots
            .iter()
            .map(|r| r.last_json().unwrap_or_default())
            .collect()
    }

    fn rss(&self) -> Vec<(String, u64)> {
        std::iter::once(&self.bridge)
            .chain(self.robots.iter())
            .map(|p| (p.name.clone(), p.rss_kb()))
            .collect()
    }

    /// Crashes into `failures`; the robots' counters before and after a clean stop
    /// (asserted).
    fn stop(&mut self, failures: &mut Vec<String>) -> (Vec<Json>, Vec<Json>) {
        if !self.bridge.alive() {
            failures.push("sim_bridge crashed".to_string());
        }
        for r in self.robots.iter_mut() {
            if !r.alive() {
                failures.push(format!("{} crashed", r.name));
            }
        }
        let running = self.robot_counters();
        assert!(
            self.bridge.stop(Duration::from_secs(5)),
            "bridge did not stop cleanly"
        );
        for r in self.robots.iter_mut() {
            assert!(
                r.stop(Duration::from_secs(5)),
                "{} did not stop cleanly",
                r.name
            );
        }
        (running, self.robot_counters())
    }
}

/// Samples the hostile node got out: the flood (and its failed sends), and per slow
/// publisher (NaN peer, huge machine, short pose, short cmd_vel, NaN cmd_vel, impostor).
struct Sent {
    flood: u64,
    flood_fail: u64,
    slow: [u64; 6],
}

/// The hostile node's publishers. They outlive the node (dropped with the test, as DDS
/// writers of the test's context), so only the publishing stops after the hostile phase.
struct Hostile {
    nan_peer: Publisher<PoseStamped>,
    huge_machine: Publisher<PoseStamped>,
    short_pose: Publisher<Short>,
    short_cmd: Publisher<Short>,
    nan_cmd: Publisher<Twist>,
    flood: Publisher<PoseStamped>,
    impostor: Publisher<PoseStamped>,
}

impl Hostile {
    fn new(node: &mut ros2_client::Node) -> Self {
        let pose_t = PoseStamped::type_name();
        let twist_t = Twist::type_name();
        let rs = Profile::RobotStream;
        Self {
            nan_peer: publisher(node, "/robot_9/pose", pose_t.clone(), rs),
            huge_machine: publisher(
                node,
                "/machine_7/pose",
                pose_t.clone(),
                Profile::LatchedPose,
            ),
            short_pose: publisher(node, "/robot_8/pose", pose_t.clone(), rs),
            short_cmd: publisher(node, "/robot_2/cmd_vel", twist_t.clone(), rs),
            nan_cmd: publisher(node, "/robot_2/cmd_vel", twist_t, rs),
            flood: publisher(node, "/robot_0/pose", pose_t.clone(), rs),
            impostor: publisher(node, "/robot_1/pose", pose_t, rs),
        }
    }

    /// The hostile phase: a 10 kHz NaN flood on `/robot_0/pose` on a thread, and 20 Hz of
    /// every other hostile sample, for [`HOSTILE_S`] after 3 s of matching.
    fn run(&self) -> Sent {
        let Self {
            nan_peer,
            huge_machine,
            short_pose,
            short_cmd,
            nan_cmd,
            flood,
            impostor,
        } = self;
        sleep_s(3.0); // matching
        let t0 = Instant::now();
        let stop = AtomicBool::new(false);
        let flood_sent = AtomicU64::new(0);
        let flood_fail = AtomicU64::new(0);
        let mut slow = [0u64; 6];
        std::thread::scope(|s| {
            s.spawn(|| {
                // 10 kHz: 10 samples per millisecond, bounded by time
                let mut next = Instant::now();
                while !stop.load(Ordering::Relaxed) && t0.elapsed().as_secs_f64() < HOSTILE_S {
                    for _ in 0..10 {
                        let p = pose(f64::NAN, f64::NAN);
                        if flood.publish(p).is_ok() {
                            flood_sent.fetch_add(1, Ordering::Relaxed);
                        } else {
                            flood_fail.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                    next += Duration::from_millis(1);
                    let now = Instant::now();
                    if next > now {
                        std::thread::sleep(next - now);
                    } else if now - next > Duration::from_millis(50) {
                        next = now; // do not burst after falling behind
                    }
                }
            });
            // 20 Hz of everything else
            while t0.elapsed().as_secs_f64() < HOSTILE_S {
                let short = || Short { a: 1, b: 2, c: 3 };
                let ok = [
                    nan_peer.publish(pose(f64::NAN, 0.1)).is_ok(),
                    huge_machine.publish(pose(1e30, -1e30)).is_ok(),
                    short_pose.publish(short()).is_ok(),
                    short_cmd.publish(short()).is_ok(),
                    nan_cmd
                        .publish(Twist::planar(f64::NAN, f64::INFINITY))
                        .is_ok(),
                    // the impostor: a valid pose in a corner, claiming robot_1's name
                    impostor.publish(pose(-1.0, -1.0)).is_ok(),
                ];
                for (c, ok) in slow.iter_mut().zip(ok) {
                    *c += ok as u64;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            stop.store(true, Ordering::Relaxed);
        });
        Sent {
            flood: flood_sent.load(Ordering::Relaxed),
            flood_fail: flood_fail.load(Ordering::Relaxed),
            slow,
        }
    }
}

/// A rejection counter as the mode expects it: open, the hostile samples arrived and were
/// counted (at least one); secure, none got through DDS Security to be counted.
fn check_count(what: &str, n: f64, failures: &mut Vec<String>) {
    if secure() && n != 0.0 {
        failures.push(format!(
            "{what}: {n} hostile samples got through DDS Security"
        ));
    } else if !secure() && n < 1.0 {
        failures.push(format!("{what}: not counted"));
    }
}

/// Every robot counted each rejection kind (it sees the NaN peer, the huge machine and
/// the short pose topic), or none reached it with security on; one report row per robot.
fn check_robot_rejections(final_counters: &[Json], failures: &mut Vec<String>) -> Vec<Json> {
    let mut rows = Vec::new();
    for (i, c) in final_counters.iter().enumerate() {
        let (dec, nf, oor) = (
            num(c, "dropped/decode"),
            num(c, "dropped/non_finite"),
            num(c, "dropped/out_of_room"),
        );
        eprintln!("robot_{i}: dropped decode {dec}, non_finite {nf}, out_of_room {oor}, accepted {}, zero(own_stale) {}", num(c, "accepted"), num(c, "zero/own_stale"));
        rows.push(
            serde_json::json!({"robot": format!("robot_{i}"), "dropped_decode": dec,
            "dropped_non_finite": nf, "dropped_out_of_room": oor,
            "accepted": num(c, "accepted"), "zero_own_stale": num(c, "zero/own_stale")}),
        );
        for (kind, n) in [("decode", dec), ("non_finite", nf), ("out_of_room", oor)] {
            check_count(&format!("robot_{i} dropped/{kind}"), n, failures);
        }
    }
    rows
}

/// The impostor on /robot_1/pose: every robot reads that topic (robot_1 as its own pose,
/// the others as a peer's) and must refuse and count its samples; one row per robot.
fn check_impostor(
    final_counters: &[Json],
    counters_clean: &[Json],
    impostor_sent: f64,
    failures: &mut Vec<String>,
) -> Vec<Json> {
    let mut rows = Vec::new();
    for (i, (c, c0)) in final_counters.iter().zip(counters_clean).enumerate() {
        let foreign = num(c, "dropped/foreign_writer");
        let changes = num(c, "writer_changes");
        eprintln!(
            "robot_{i}: dropped foreign_writer {foreign} of {impostor_sent} impostor samples, writer_changes {changes}"
        );
        rows.push(serde_json::json!({"robot": format!("robot_{i}"),
            "dropped_foreign_writer": foreign, "writer_changes": changes}));
        if secure() {
            check_count(
                &format!("robot_{i} dropped/foreign_writer"),
                foreign,
                failures,
            );
        } else if !(foreign >= 0.8 * impostor_sent && foreign <= impostor_sent) {
            failures.push(format!(
                "robot_{i}: {foreign} foreign-writer drops for {impostor_sent} impostor samples"
            ));
        }
        // the impostor never took over a pin (that would need the bridge silent for the
        // whole stale timeout)
        if changes != 0.0 {
            failures.push(format!("robot_{i}: {changes} pinned writers replaced"));
        }
        if num(c0, "dropped/foreign_writer") != 0.0 {
            failures.push(format!(
                "robot_{i}: foreign-writer drops before any impostor: {c0}"
            ));
        }
    }
    rows
}

/// Robot_1 kept acting on the bridge's poses through the hostile phase: it commanded (own
/// data fresh) on nearly every tick, as in the clean phase. Returns (ticks, commands,
/// own-stale ticks) of the hostile phase.
fn check_robot_1(r1_hostile: &Json, r1_clean: &Json, failures: &mut Vec<String>) -> [f64; 3] {
    let ticks = num(r1_hostile, "ticks") - num(r1_clean, "ticks");
    let cmds = num(r1_hostile, "commands") - num(r1_clean, "commands");
    let stale = num(r1_hostile, "zero/own_stale") - num(r1_clean, "zero/own_stale");
    eprintln!("robot_1 during the hostile phase: {cmds} commands, {stale} own-stale zero ticks of {ticks} ticks");
    if !(ticks > 0.0 && cmds >= 0.9 * ticks) {
        failures.push(format!(
            "robot_1 commanded on only {cmds} of {ticks} ticks during the hostile phase ({stale} own stale)"
        ));
    }
    [ticks, cmds, stale]
}

/// RSS stayed bounded: at most twice the clean phase's plus 30 MB.
fn check_rss(before: &[(String, u64)], after: &[(String, u64)], failures: &mut Vec<String>) {
    for ((n, b), (_, a)) in before.iter().zip(after) {
        eprintln!("RSS {n}: {b} kB -> {a} kB");
        if *a > 2 * b + 30_000 {
            failures.push(format!("{n}: RSS grew from {b} kB to {a} kB"));
        }
    }
}

/// The bridge counted undecodable and non-finite cmd_vel; returns both counts.
fn check_bridge_rejections(m_end: &Json, failures: &mut Vec<String>) -> (f64, f64) {
    let bd = num(m_end, "cmds_dropped_decode");
    let bn = num(m_end, "cmds_dropped_non_finite");
    eprintln!(
        "sim_bridge rejected: {bd} undecodable cmd_vel, {bn} non-finite cmd_vel; spawned {}",
        num(m_end, "spawned")
    );
    check_count("sim_bridge cmds_dropped_decode", bd, failures);
    check_count("sim_bridge cmds_dropped_non_finite", bn, failures);
    (bd, bn)
}

#[test]
fn hostile_publisher_is_counted_and_the_fleet_keeps_working() {
    let domain = test_domains::domain(0);
    let mut fleet = Fleet::start(domain, "3.3_1");
    // clean phase
    sleep_s(12.0);
    let m_clean = fleet.bridge.last_json().expect("bridge metrics");
    let counters_clean = fleet.robot_counters();
    let rss_before = fleet.rss();

    // hostile phase
    let ctx = Context::with_options(ContextOptions::new().domain_id(domain)).unwrap();
    let mut node = ctx
        .new_node(
            NodeName::new("/evil", "hostile").unwrap(),
            NodeOptions::new().enable_rosout(false),
        )
        .unwrap();
    let hostile = Hostile::new(&mut node);
    let sent = hostile.run();
    sleep_s(1.0);
    let m_hostile = fleet.bridge.last_json().expect("bridge metrics");
    let rss_after = fleet.rss();
    // recovery phase: hostile node gone
    drop(node);
    sleep_s(AFTER_S);
    let m_end = fleet.bridge.last_json().expect("bridge metrics");

    let mut failures = Vec::new();
    let (robot_counters, final_counters) = fleet.stop(&mut failures);
    let d = |m: &Json| num(m, "parts_delivered");
    let clean_rate = d(&m_clean) / num(&m_clean, "sim_time");
    let hostile_parts = d(&m_hostile) - d(&m_clean);
    let recover_parts = d(&m_end) - d(&m_hostile);
    eprintln!(
        "delivered: clean {} in {:.1} s; during the hostile phase {hostile_parts}; after it {recover_parts}",
        d(&m_clean),
        num(&m_clean, "sim_time")
    );
    eprintln!(
        "hostile samples sent: flood {} (failed {}), others {:?}",
        sent.flood, sent.flood_fail, sent.slow
    );
    check_rss(&rss_before, &rss_after, &mut failures);
    if hostile_parts < 1.0 {
        failures.push(format!(
            "no delivery during the hostile phase ({m_hostile})"
        ));
    }
    if recover_parts < 1.0 {
        failures.push("no delivery after the hostile phase".into());
    }
    let (bd, bn) = check_bridge_rejections(&m_end, &mut failures);
    let rows = check_robot_rejections(&final_counters, &mut failures);
    let impostor_sent = sent.slow[5] as f64;
    let impostor_rows = check_impostor(
        &final_counters,
        &counters_clean,
        impostor_sent,
        &mut failures,
    );
    let [ticks, cmds, stale] = check_robot_1(&robot_counters[1], &counters_clean[1], &mut failures);
    if num(&m_end, "robots") != 3.0 {
        failures.push(format!("the bridge lost a robot: {m_end}"));
    }
    report(serde_json::json!({
        "fault": "hostile publisher",
        "clean_parts": d(&m_clean), "clean_s": num(&m_clean, "sim_time"),
        "clean_parts_per_s": clean_rate,
        "hostile_s": HOSTILE_S, "hostile_parts": hostile_parts,
        "after_s": AFTER_S, "after_parts": recover_parts,
        "flood_sent": sent.flood, "flood_rate_hz": sent.flood as f64 / HOSTILE_S,
        "other_sent": sent.slow.to_vec(),
        "bridge_dropped_decode": bd, "bridge_dropped_non_finite": bn,
        "bridge_spawned": num(&m_end, "spawned"),
        "robots": rows,
        "impostor_sent": impostor_sent, "impostor": impostor_rows,
        "robot_1_hostile_ticks": ticks, "robot_1_hostile_commands": cmds,
        "robot_1_hostile_own_stale": stale,
        "rss_kb_before": rss_before, "rss_kb_after": rss_after,
        "collisions_clean": num(&m_clean, "collisions"),
        "collisions_end": num(&m_end, "collisions"),
    }));
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
