//! Fault (c): a hostile publisher on the fleet's domain (this test process, over DDS):
//! NaN poses, huge poses, wrong-length CDR payloads (on a pose topic and on a cmd_vel
//! topic), NaN cmd_vel, a 10 kHz flood of NaN poses on a real robot's own pose topic, and
//! a foreign publisher claiming `/robot_1/pose`. Nothing may crash, RSS stays bounded,
//! the fleet keeps delivering, and every rejection is counted (robot_node's `dropped`
//! counters, sim_bridge's `cmds_dropped_*`). The impostor's *valid* poses cannot be told
//! apart from the bridge's and are not rejected: its effect is measured and reported.

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
    let _ = robot_counters;
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
        "rss_kb_before": rss_before, "rss_kb_after": rss_after,
        "collisions_clean": num(&m_clean, "collisions"),
        "collisions_end": num(&m_end, "collisions"),
    }));
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
