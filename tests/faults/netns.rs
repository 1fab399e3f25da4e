//! Fault (b): message loss and delay between separate network stacks (the multi-host
//! proof). sim_bridge runs in one network namespace, the robot_nodes in another, joined by
//! a veth pair (10.200.<n>.0/24, multicast route for DDS discovery); both namespaces are
//! made and torn down here. Loss: `iptables -m statistic --mode random` DROP on the
//! robots' veth, both directions (tc netem is missing from these kernels). Delay, both
//! ways, injected by sim_bridge: `-p test_cmd_delay_ms` (every cmd_vel reaches the
//! simulator N ms late) and `-p test_state_delay_ms` (every state message, i.e. poses,
//! has_part, part_ready, /clock, markers, metrics, is published N ms after its step): a
//! `delayN` case adds 2N ms to the sense-act round trip.
//!
//! Needs root, `ip` and `iptables` (Debian package iptables). As root a missing capability
//! fails the test; not as root it fails when `CI` is set and is reported as skipped (on
//! stderr) otherwise.
//!
//! Cases: `TENDING_NETNS_CASES` (default `clean,loss30,delay200`; bench/faults/run.sh runs
//! `clean,loss10,loss30,delay50,delay200`), each `TENDING_NETNS_S` seconds (default 15),
//! once per bridge seed of `TENDING_NETNS_SEEDS` (default `0`; run.sh: `0,1,2`). Runs go
//! seed-major (every case of seed 0, then of seed 1, ...), so a slow drift of the machine's
//! background load touches every case alike. One `RUN i/n ...` progress line per run on
//! stderr.

mod common;
use common::*;

use std::process::Command;
use std::time::Duration;

fn sh(args: &[&str]) -> Result<(), String> {
    let out = Command::new(args[0])
        .args(&args[1..])
        .output()
        .map_err(|e| format!("{}: {e}", args.join(" ")))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "`{}` failed: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

/// Two namespaces joined by veth; deleted on drop.
struct Net {
    bridge_ns: String,
    robots_ns: String,
}

impl Net {
    fn new(tag: u32) -> Result<Net, String> {
        let n = Net {
            bridge_ns: format!("tfb{tag}"),
            robots_ns: format!("tfr{tag}"),
        };
        let (b, r) = (n.bridge_ns.as_str(), n.robots_ns.as_str());
        let (vb, vr) = (format!("vb{tag}"), format!("vr{tag}"));
        let sub = 10 + tag % 200;
        let (ab, ar) = (format!("10.200.{sub}.1/24"), format!("10.200.{sub}.2/24"));
        sh(&["ip", "netns", "add", b])?;
        sh(&["ip", "netns", "add", r])?;
        sh(&[
            "ip", "link", "add", &vb, "type", "veth", "peer", "name", &vr,
        ])?;
        sh(&["ip", "link", "set", &vb, "netns", b])?;
        sh(&["ip", "link", "set", &vr, "netns", r])?;
        for (ns, dev, addr) in [(b, &vb, &ab), (r, &vr, &ar)] {
            sh(&["ip", "-n", ns, "addr", "add", addr, "dev", dev])?;
            sh(&["ip", "-n", ns, "link", "set", "lo", "up"])?;
            sh(&["ip", "-n", ns, "link", "set", dev, "up", "multicast", "on"])?;
            sh(&["ip", "-n", ns, "route", "add", "239.255.0.0/16", "dev", dev])?;
        }
        Ok(n)
    }
    fn loss(&self, p: f64) -> Result<(), String> {
        let r = self.robots_ns.as_str();
        let ps = format!("{p}");
        let dev = format!("vr{}", &r[3..]);
        for (chain, dir) in [("INPUT", "-i"), ("OUTPUT", "-o")] {
            sh(&[
                "ip",
                "netns",
                "exec",
                r,
                "iptables",
                "-A",
                chain,
                dir,
                &dev,
                "-m",
                "statistic",
                "--mode",
                "random",
                "--probability",
                &ps,
                "-j",
                "DROP",
            ])?;
        }
        Ok(())
    }
}

impl Drop for Net {
    fn drop(&mut self) {
        let _ = sh(&["ip", "netns", "del", &self.bridge_ns]);
        let _ = sh(&["ip", "netns", "del", &self.robots_ns]);
    }
}

fn in_ns(ns: &str, mut c: Command) -> Command {
    let mut w = Command::new("ip");
    w.args(["netns", "exec", ns]).arg(c.get_program());
    w.args(c.get_args());
    for (k, v) in c.get_envs() {
        if let Some(v) = v {
            w.env(k, v);
        }
    }
    let _ = &mut c;
    w
}

/// Modification time of a binary next to sim_bridge (Unix seconds).
fn bin_mtime(name: &str) -> u64 {
    std::fs::metadata(bin(name))
        .and_then(|m| m.modified())
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map_or(0, |d| d.as_secs())
}

fn run_case(case: &str, secs: f64, seed: u64, k: u32) -> serde_json::Value {
    let tag = (std::process::id() % 1000) * 100 + k % 100;
    let net = Net::new(tag)
        .unwrap_or_else(|e| panic!("network namespaces unavailable although running as root: {e}"));
    let (loss, delay) = match case {
        "clean" => (0.0, 0.0),
        c if c.starts_with("loss") => (c[4..].parse::<f64>().unwrap() / 100.0, 0.0),
        c if c.starts_with("delay") => (0.0, c[5..].parse::<f64>().unwrap()),
        c => panic!("unknown case {c}"),
    };
    if loss > 0.0 {
        net.loss(loss).unwrap_or_else(|e| {
            panic!("iptables statistic DROP failed (apt-get install iptables): {e}")
        });
    }
    let domain = test_domains::domain(0);
    let setup = "3.3_1";
    // both ways: commands into the simulator and state out of it
    let cmd_delay = format!("test_cmd_delay_ms:={delay}");
    let state_delay = format!("test_state_delay_ms:={delay}");
    let seed_arg = format!("seed:={seed}"); // after bridge_cmd's seed:=0: the last -p wins
    let mut bridge = Proc::spawn(
        "sim_bridge",
        in_ns(
            &net.bridge_ns,
            bridge_cmd(domain, setup, &[&cmd_delay, &state_delay, &seed_arg]),
        ),
    );
    let mut robots: Vec<Proc> = (0..3)
        .map(|i| {
            let n = format!("robot_{i}");
            Proc::spawn(&n, in_ns(&net.robots_ns, robot_cmd(&n, domain, setup, &[])))
        })
        .collect();
    sleep_s(secs);
    let m = bridge.last_json();
    let mut crashed: Vec<String> = Vec::new();
    if !bridge.alive() {
        crashed.push("sim_bridge".into());
    }
    for r in robots.iter_mut() {
        if !r.alive() {
            crashed.push(r.name.clone());
        }
    }
    bridge.stop(Duration::from_secs(5));
    for r in robots.iter_mut() {
        r.stop(Duration::from_secs(5));
    }
    let counters: Vec<serde_json::Value> = robots
        .iter()
        .map(|r| r.last_json().unwrap_or_default())
        .collect();
    drop(net);
    let m = m.unwrap_or_default();
    let v = serde_json::json!({
        "fault": "netns", "case": case, "seed": seed, "loss": loss, "cmd_delay_ms": delay,
        "state_delay_ms": delay, "seconds": secs, "steps": num(&m, "step"),
        "parts_delivered": num(&m, "parts_delivered"), "collisions": num(&m, "collisions"),
        "mu": num(&m, "mu"), "robots": num(&m, "robots"), "cmds_accepted": num(&m, "cmds_accepted"),
        "spawned": num(&m, "spawned"), "despawned": num(&m, "despawned"),
        "robot_zero_own_stale": counters.iter().map(|c| num(c, "zero/own_stale")).sum::<f64>(),
        "robot_ticks": counters.iter().map(|c| num(c, "ticks")).sum::<f64>(),
        "robot_ticks_missed": counters.iter().map(|c| num(c, "ticks_missed")).sum::<f64>(),
        "robot_writer_changes": counters.iter().map(|c| num(c, "writer_changes")).sum::<f64>(),
        "crashed": crashed,
        // which builds ran (the target directory is shared: a rebuild mid-bench shows here)
        "robot_node_mtime": bin_mtime("robot_node"), "sim_bridge_mtime": bin_mtime("sim_bridge"),
    });
    report(v.clone());
    v
}

#[test]
fn fleet_across_network_namespaces_survives_loss_and_delay() {
    // SAFETY: plain getter
    let root = unsafe { libc::geteuid() } == 0;
    if !root {
        if std::env::var_os("CI").is_some() {
            panic!("faults_netns needs root (ip netns, veth, iptables) and CI runs as root");
        }
        eprintln!("SKIPPED faults_netns: not root (ip netns / veth / iptables need root)");
        return;
    }
    if Command::new("iptables").arg("--version").output().is_err() {
        panic!("iptables not installed: apt-get update && apt-get install -y iptables");
    }
    let cases =
        std::env::var("TENDING_NETNS_CASES").unwrap_or_else(|_| "clean,loss30,delay200".into());
    let secs: f64 = std::env::var("TENDING_NETNS_S")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(15.0);
    let seeds: Vec<u64> = std::env::var("TENDING_NETNS_SEEDS")
        .unwrap_or_else(|_| "0".into())
        .split(',')
        .map(|s| s.trim().parse().expect("TENDING_NETNS_SEEDS: integers"))
        .collect();
    let runs: Vec<(u64, &str)> = seeds
        .iter()
        .flat_map(|&s| cases.split(',').map(move |c| (s, c)))
        .collect();
    let t0 = std::time::Instant::now();
    let mut failures = Vec::new();
    for (k, &(seed, case)) in runs.iter().enumerate() {
        let v = run_case(case, secs, seed, k as u32);
        eprintln!(
            "RUN {}/{} {case} seed {seed}: parts {:.0} collisions {:.0} MU {:.3} robots {:.0} \
             own-stale zero ticks {:.0}/{:.0} crashed [{}] ({:.0} s elapsed)",
            k + 1,
            runs.len(),
            num(&v, "parts_delivered"),
            num(&v, "collisions"),
            num(&v, "mu"),
            num(&v, "robots"),
            num(&v, "robot_zero_own_stale"),
            num(&v, "robot_ticks"),
            v["crashed"]
                .as_array()
                .unwrap()
                .iter()
                .filter_map(|c| c.as_str())
                .collect::<Vec<_>>()
                .join(","),
            t0.elapsed().as_secs_f64()
        );
        if !v["crashed"].as_array().unwrap().is_empty() {
            failures.push(format!("{case} seed {seed}: crashed {}", v["crashed"]));
        }
        // discovery and traffic across the two stacks: every robot's commands reach the
        // bridge and the fleet delivers
        if num(&v, "robots") != 3.0 {
            failures.push(format!(
                "{case} seed {seed}: bridge has {} robots, want 3",
                v["robots"]
            ));
        }
        if num(&v, "parts_delivered") < 1.0 {
            failures.push(format!("{case} seed {seed}: no part delivered"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
