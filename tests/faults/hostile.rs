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

#[test]
fn hostile_publisher_is_counted_and_the_fleet_keeps_working() {
    let domain = (std::process::id() % 40) as u16 + 160;
    let setup = "3.3_1";
    let mut bridge = Proc::spawn("sim_bridge", bridge_cmd(domain, setup, &[]));
    let mut robots: Vec<Proc> = (0..3)
        .map(|i| {
            let n = format!("robot_{i}");
            Proc::spawn(&n, robot_cmd(&n, domain, setup, &[]))
        })
        .collect();
    // clean phase
    sleep_s(12.0);
    let m_clean = bridge.last_json().expect("bridge metrics");
    let counters_clean: Vec<serde_json::Value> = robots
        .iter()
        .map(|r| r.last_json().unwrap_or_default())
        .collect();
    let rss_before: Vec<(String, u64)> = std::iter::once(&bridge)
        .chain(robots.iter())
        .map(|p| (p.name.clone(), p.rss_kb()))
        .collect();

    // hostile phase
    let ctx = Context::with_options(ContextOptions::new().domain_id(domain)).unwrap();
    let mut node = ctx
        .new_node(
            NodeName::new("/evil", "hostile").unwrap(),
            NodeOptions::new().enable_rosout(false),
        )
        .unwrap();
    let pose_t = PoseStamped::type_name();
    let twist_t = Twist::type_name();
    let nan_peer: Publisher<PoseStamped> = publisher(
        &mut node,
        "/robot_9/pose",
        pose_t.clone(),
        Profile::RobotStream,
    );
    let huge_machine: Publisher<PoseStamped> = publisher(
        &mut node,
        "/machine_7/pose",
        pose_t.clone(),
        Profile::LatchedPose,
    );
    let short_pose: Publisher<Short> = publisher(
        &mut node,
        "/robot_8/pose",
        pose_t.clone(),
        Profile::RobotStream,
    );
    let short_cmd: Publisher<Short> = publisher(
        &mut node,
        "/robot_2/cmd_vel",
        twist_t.clone(),
        Profile::RobotStream,
    );
    let nan_cmd: Publisher<Twist> =
        publisher(&mut node, "/robot_2/cmd_vel", twist_t, Profile::RobotStream);
    let flood: Publisher<PoseStamped> = publisher(
        &mut node,
        "/robot_0/pose",
        pose_t.clone(),
        Profile::RobotStream,
    );
    let impostor: Publisher<PoseStamped> =
        publisher(&mut node, "/robot_1/pose", pose_t, Profile::RobotStream);
    sleep_s(3.0); // matching
    let t0 = Instant::now();
    let hostile_s = 12.0;
    let stop = AtomicBool::new(false);
    let flood_sent = AtomicU64::new(0);
    let flood_fail = AtomicU64::new(0);
    let mut slow_sent = [0u64; 6];
    std::thread::scope(|s| {
        s.spawn(|| {
            // 10 kHz: 10 samples per millisecond, bounded by time
            let mut next = Instant::now();
            let mut k = 0u64;
            while !stop.load(Ordering::Relaxed) && t0.elapsed().as_secs_f64() < hostile_s {
                for _ in 0..10 {
                    let p = pose(f64::NAN, f64::NAN);
                    if flood.publish(p).is_ok() {
                        flood_sent.fetch_add(1, Ordering::Relaxed);
                    } else {
                        flood_fail.fetch_add(1, Ordering::Relaxed);
                    }
                }
                k += 1;
                next += Duration::from_millis(1);
                let now = Instant::now();
                if next > now {
                    std::thread::sleep(next - now);
                } else if now - next > Duration::from_millis(50) {
                    next = now; // do not burst after falling behind
                }
            }
            let _ = k;
        });
        // 20 Hz of everything else
        while t0.elapsed().as_secs_f64() < hostile_s {
            let ok = |r: bool, i: usize, c: &mut [u64; 6]| {
                if r {
                    c[i] += 1
                }
            };
            ok(
                nan_peer.publish(pose(f64::NAN, 0.1)).is_ok(),
                0,
                &mut slow_sent,
            );
            ok(
                huge_machine.publish(pose(1e30, -1e30)).is_ok(),
                1,
                &mut slow_sent,
            );
            ok(
                short_pose.publish(Short { a: 1, b: 2, c: 3 }).is_ok(),
                2,
                &mut slow_sent,
            );
            ok(
                short_cmd.publish(Short { a: 1, b: 2, c: 3 }).is_ok(),
                3,
                &mut slow_sent,
            );
            ok(
                nan_cmd
                    .publish(Twist::planar(f64::NAN, f64::INFINITY))
                    .is_ok(),
                4,
                &mut slow_sent,
            );
            // the impostor: a valid pose in a corner, claiming robot_1's name
            ok(
                impostor.publish(pose(-1.0, -1.0)).is_ok(),
                5,
                &mut slow_sent,
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        stop.store(true, Ordering::Relaxed);
    });
    sleep_s(1.0);
    let m_hostile = bridge.last_json().expect("bridge metrics");
    let rss_after: Vec<(String, u64)> = std::iter::once(&bridge)
        .chain(robots.iter())
        .map(|p| (p.name.clone(), p.rss_kb()))
        .collect();
    // recovery phase: hostile node gone
    drop(node);
    sleep_s(8.0);
    let m_end = bridge.last_json().expect("bridge metrics");

    let mut failures = Vec::new();
    let alive_bridge = bridge.alive();
    if !alive_bridge {
        failures.push("sim_bridge crashed".to_string());
    }
    for r in robots.iter_mut() {
        if !r.alive() {
            failures.push(format!("{} crashed", r.name));
        }
    }
    let robot_counters: Vec<serde_json::Value> = robots
        .iter()
        .map(|r| r.last_json().unwrap_or_default())
        .collect();
    assert!(
        bridge.stop(Duration::from_secs(5)),
        "bridge did not stop cleanly"
    );
    for r in robots.iter_mut() {
        assert!(
            r.stop(Duration::from_secs(5)),
            "{} did not stop cleanly",
            r.name
        );
    }
    let final_counters: Vec<serde_json::Value> = robots
        .iter()
        .map(|r| r.last_json().unwrap_or_default())
        .collect();

    let d = |m: &serde_json::Value| num(m, "parts_delivered");
    let clean_rate = d(&m_clean) / num(&m_clean, "sim_time");
    let hostile_parts = d(&m_hostile) - d(&m_clean);
    let recover_parts = d(&m_end) - d(&m_hostile);
    eprintln!(
        "delivered: clean {} in {:.1} s; during the hostile phase {hostile_parts}; after it {recover_parts}",
        d(&m_clean),
        num(&m_clean, "sim_time")
    );
    eprintln!(
        "hostile samples sent: flood {} (failed {}), others {slow_sent:?}",
        flood_sent.load(Ordering::Relaxed),
        flood_fail.load(Ordering::Relaxed)
    );
    for ((n, b), (_, a)) in rss_before.iter().zip(&rss_after) {
        eprintln!("RSS {n}: {b} kB -> {a} kB");
        if *a > 2 * b + 30_000 {
            failures.push(format!("{n}: RSS grew from {b} kB to {a} kB"));
        }
    }
    if hostile_parts < 1.0 {
        failures.push(format!(
            "no delivery during the hostile phase ({m_hostile})"
        ));
    }
    if recover_parts < 1.0 {
        failures.push("no delivery after the hostile phase".into());
    }
    let bd = num(&m_end, "cmds_dropped_decode");
    let bn = num(&m_end, "cmds_dropped_non_finite");
    eprintln!(
        "sim_bridge rejected: {bd} undecodable cmd_vel, {bn} non-finite cmd_vel; spawned {}",
        num(&m_end, "spawned")
    );
    if bd < 1.0 {
        failures.push("sim_bridge counted no undecodable cmd_vel".into());
    }
    if bn < 1.0 {
        failures.push("sim_bridge counted no non-finite cmd_vel".into());
    }
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
        // every robot sees the NaN peer, the huge machine and the short pose topic
        if !(dec >= 1.0 && nf >= 1.0 && oor >= 1.0) {
            failures.push(format!("robot_{i}: a rejection kind not counted: {c}"));
        }
    }
    // the impostor on /robot_1/pose: every robot reads that topic (robot_1 as its own
    // pose, the others as a peer's) and must refuse and count its samples
    let impostor_sent = slow_sent[5] as f64;
    let mut impostor_rows = Vec::new();
    for (i, (c, c0)) in final_counters.iter().zip(&counters_clean).enumerate() {
        let foreign = num(c, "dropped/foreign_writer");
        let changes = num(c, "writer_changes");
        eprintln!(
            "robot_{i}: dropped foreign_writer {foreign} of {impostor_sent} impostor samples, writer_changes {changes}"
        );
        impostor_rows.push(serde_json::json!({"robot": format!("robot_{i}"),
            "dropped_foreign_writer": foreign, "writer_changes": changes}));
        if !(foreign >= 0.8 * impostor_sent && foreign <= impostor_sent) {
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
    // robot_1 kept acting on the bridge's poses through the hostile phase: it commanded
    // (own data fresh) on nearly every tick, as in the clean phase
    let r1_hostile = &robot_counters[1];
    let r1_clean = &counters_clean[1];
    let ticks = num(r1_hostile, "ticks") - num(r1_clean, "ticks");
    let cmds = num(r1_hostile, "commands") - num(r1_clean, "commands");
    let stale = num(r1_hostile, "zero/own_stale") - num(r1_clean, "zero/own_stale");
    eprintln!("robot_1 during the hostile phase: {cmds} commands, {stale} own-stale zero ticks of {ticks} ticks");
    if !(ticks > 0.0 && cmds >= 0.9 * ticks) {
        failures.push(format!(
            "robot_1 commanded on only {cmds} of {ticks} ticks during the hostile phase ({stale} own stale)"
        ));
    }
    if num(&m_end, "robots") != 3.0 {
        failures.push(format!("the bridge lost a robot: {m_end}"));
    }
    let flood_n = flood_sent.load(Ordering::Relaxed);
    report(serde_json::json!({
        "fault": "hostile publisher",
        "clean_parts": d(&m_clean), "clean_s": num(&m_clean, "sim_time"),
        "clean_parts_per_s": clean_rate,
        "hostile_s": hostile_s, "hostile_parts": hostile_parts,
        "after_s": 8.0, "after_parts": recover_parts,
        "flood_sent": flood_n, "flood_rate_hz": flood_n as f64 / hostile_s,
        "other_sent": slow_sent.to_vec(),
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
