//! `ros_bench`: robot_node latency benchmark over real DDS on loopback.
//!
//! ```text
//! ros_bench latency --robot-node PATH [--policy CKPT] [--n 200] [--interval-ms 100]
//!                   [--peers 5] [--machines 4] [--storages 2] [--domain D]
//! ros_bench echo --domain D          (helper process: /bench/ping -> /bench/pong)
//! ros_bench mkpolicy PATH            (random-weights SMAPPO checkpoint)
//! ```
//!
//! `latency` plays the simulator bridge for `/robot_0` in lockstep mode
//! (docs/adr/0003-lockstep.md): every state k is published with stamp k (pose header stamp
//! and DDS source timestamp), and the robot's `cmd_vel` answering it carries k as its source
//! timestamp, so each reply is matched to the state that caused it. Interleaved with each
//! state, one bare DDS round trip to a separate `echo` process (same writer kind, same QoS)
//! is measured, so both numbers come from the same run under the same load. One JSON line
//! with the summary goes to stdout.

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context as _, Result};
use msgs::topics::{self, Leaf};
use msgs::{Bool, PoseStamped, Profile, Time, Twist};
use ros::{stamp_key_info, subscription, StampedWriter};
use ros2_client::dds::rustdds::mio1::{Events, Interest, Poll, Token};
use ros2_client::dds::{Context, Node, Subscription};

const PING: &str = "/bench/ping";
const PONG: &str = "/bench/pong";

/// A node nobody spins: the benchmark needs no graph events, only its endpoints.
fn node(domain: u16, name: &str) -> Result<(Context, Node)> {
    let ctx = ros::context(domain)?;
    let spec = ros::NodeSpec {
        namespace: "/",
        name,
        enable_rosout: false,
    };
    let node = ros::node::node(&ctx, &spec)?;
    Ok((ctx, node))
}

fn arg<T: std::str::FromStr>(args: &[String], flag: &str, default: T) -> Result<T> {
    match args.iter().position(|a| a == flag) {
        Some(i) => args
            .get(i + 1)
            .ok_or_else(|| anyhow!("{flag} needs a value"))?
            .parse()
            .map_err(|_| anyhow!("bad value for {flag}")),
        None => Ok(default),
    }
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("echo") => echo(
            arg(&args, "--domain", 0u16)?,
            arg(&args, "--max-s", 600.0f64)?,
        ),
        Some("latency") => latency(&args),
        Some("mkpolicy") => {
            let path = args.get(1).ok_or_else(|| anyhow!("mkpolicy PATH"))?;
            let actor = policy::Actor::new(policy::ArchConfig::smappo(), 1);
            policy::checkpoint::save_policy(
                std::path::Path::new(path),
                &actor,
                serde_json::json!({"note": "random weights (ros_bench mkpolicy), seed 1"}),
            )
            .map_err(|e| anyhow!("{e}"))?;
            eprintln!("wrote random-weights SMAPPO checkpoint {path}");
            Ok(())
        }
        _ => bail!("usage: ros_bench latency|echo|mkpolicy ... (see the source header)"),
    }
}

/// Reply to every ping with a pong carrying the same source timestamp. Bounded in time.
fn echo(domain: u16, max_s: f64) -> Result<()> {
    let (ctx, mut node) = node(domain, "bench_echo")?;
    let mut ping = subscription::<Twist>(&mut node, PING, Profile::RobotStream)?;
    let pong = StampedWriter::<Twist>::new(&ctx, &node, PONG, Profile::RobotStream)?;
    let mut poll = Poll::new()?;
    poll.registry()
        .register(&mut ping, Token(0), Interest::READABLE)?;
    let mut events = Events::with_capacity(16);
    let t0 = Instant::now();
    while t0.elapsed().as_secs_f64() < max_s {
        poll.poll(&mut events, Some(Duration::from_millis(100)))
            .ok();
        while let Ok(Some((m, info))) = ping.take() {
            let ns = stamp_key_info(&info).map(|us| us * 1000);
            pong.write(m, ns).ok();
        }
    }
    Ok(())
}

struct Kill(Child);
impl Drop for Kill {
    fn drop(&mut self) {
        // SIGINT first so robot_node prints its final stats line, then kill
        unsafe_sigint(self.0.id());
        let t = Instant::now();
        while t.elapsed() < Duration::from_secs(3) {
            if let Ok(Some(_)) = self.0.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn unsafe_sigint(pid: u32) {
    // no libc dependency: use the kill(1) command
    let _ = Command::new("kill")
        .args(["-INT", &pid.to_string()])
        .status();
}

fn pct(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let i = ((v.len() - 1) as f64 * q).round() as usize;
    v[i]
}

fn latency(args: &[String]) -> Result<()> {
    let robot_node: String = arg(
        args,
        "--robot-node",
        "target/release/robot_node".to_string(),
    )?;
    let policy_path: String = arg(args, "--policy", String::new())?;
    let n: usize = arg(args, "--n", 200)?;
    let interval = Duration::from_millis(arg(args, "--interval-ms", 100u64)?);
    let warmup_s: f64 = arg(args, "--warmup-s", 5.0)?;
    let peers: u32 = arg(args, "--peers", 5)?;
    let machines: u32 = arg(args, "--machines", 4)?;
    let storages: u32 = arg(args, "--storages", 2)?;
    let domain: u16 = arg(args, "--domain", 100 + (std::process::id() % 100) as u16)?;
    let reply_timeout = Duration::from_secs(1);
    // every run is bounded: warm-up + n slots + slack
    let max_s = warmup_s + n as f64 * interval.as_secs_f64() * 1.5 + 30.0;

    let me = "robot_0";
    let (ctx, mut node) = node(domain, "bench_bridge")?;
    // the bridge's side of the contract
    let own_pose = StampedWriter::<PoseStamped>::new(
        &ctx,
        &node,
        &topics::robot(me, Leaf::Pose).ros_name(),
        Profile::RobotStream,
    )?;
    let own_part = StampedWriter::<Bool>::new(
        &ctx,
        &node,
        &topics::robot(me, Leaf::HasPart).ros_name(),
        Profile::RobotStream,
    )?;
    let mut flags: Vec<(StampedWriter<Bool>, bool)> = Vec::new();
    let mut poses: Vec<(StampedWriter<PoseStamped>, f64, f64)> = Vec::new();
    for j in 0..machines {
        let x = -0.8 + 1.6 * j as f64 / (machines.max(2) - 1) as f64;
        poses.push((
            StampedWriter::new(
                &ctx,
                &node,
                &topics::machine(j, Leaf::Pose).ros_name(),
                Profile::LatchedPose,
            )?,
            x,
            0.9,
        ));
        flags.push((
            StampedWriter::new(
                &ctx,
                &node,
                &topics::machine(j, Leaf::PartReady).ros_name(),
                Profile::PartReady,
            )?,
            j % 2 == 0,
        ));
    }
    for k in 0..storages {
        let x = -0.6 + 1.2 * k as f64 / (storages.max(2) - 1) as f64;
        poses.push((
            StampedWriter::new(
                &ctx,
                &node,
                &topics::storage(k, Leaf::Pose).ros_name(),
                Profile::LatchedPose,
            )?,
            x,
            -0.95,
        ));
    }
    for p in 1..=peers {
        let name = format!("robot_{p}");
        let x = -0.9 + 1.8 * p as f64 / (peers + 1) as f64;
        poses.push((
            StampedWriter::new(
                &ctx,
                &node,
                &topics::robot(&name, Leaf::Pose).ros_name(),
                Profile::RobotStream,
            )?,
            x,
            0.2,
        ));
        flags.push((
            StampedWriter::new(
                &ctx,
                &node,
                &topics::robot(&name, Leaf::HasPart).ros_name(),
                Profile::RobotStream,
            )?,
            p % 3 == 0,
        ));
    }
    let mut cmd = subscription::<Twist>(
        &mut node,
        &topics::robot(me, Leaf::CmdVel).ros_name(),
        Profile::RobotStream,
    )?;
    let ping = StampedWriter::<Twist>::new(&ctx, &node, PING, Profile::RobotStream)?;
    let mut pong = subscription::<Twist>(&mut node, PONG, Profile::RobotStream)?;
    let mut poll = Poll::new()?;
    poll.registry()
        .register(&mut cmd, Token(0), Interest::READABLE)?;
    poll.registry()
        .register(&mut pong, Token(1), Interest::READABLE)?;
    let mut events = Events::with_capacity(16);

    let exe = std::env::current_exe()?;
    let _echo = Kill(
        Command::new(&exe)
            .args([
                "echo",
                "--domain",
                &domain.to_string(),
                "--max-s",
                &format!("{}", max_s + 10.0),
            ])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .spawn()
            .context("starting the echo process")?,
    );
    let mut rn = Command::new(&robot_node);
    rn.env("ROS_DOMAIN_ID", domain.to_string())
        .env("RUST_LOG", "warn")
        .args([
            "--ros-args",
            "-r",
            "__ns:=/robot_0",
            "-p",
            "lockstep:=true",
            "-p",
            "stats_json:=true",
        ])
        .args([
            "-p",
            "stats_period_s:=3600",
            "-p",
            "discovery_period_s:=0.5",
        ])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
    if !policy_path.is_empty() {
        rn.args(["-p", &format!("policy:={policy_path}")]);
    }
    let mut robot = Kill(
        rn.spawn()
            .with_context(|| format!("starting {robot_node}"))?,
    );
    let robot_pid = robot.0.id();
    let robot_out = robot.0.stdout.take().expect("piped");

    let t_start = Instant::now();
    let mut k: i64 = 0;
    // publish state k; returns the time after the last write
    let publish_state = |k: i64| -> Instant {
        let st = Time::from_secs_f64(k as f64 * 0.1);
        let ns = Some(k * 100_000_000);
        for (w, x, y) in &poses {
            w.write(PoseStamped::planar(st, "map", *x, *y), ns).ok();
        }
        for (w, b) in &flags {
            w.write(Bool { data: *b }, ns).ok();
        }
        own_part.write(Bool { data: false }, ns).ok();
        own_pose
            .write(PoseStamped::planar(st, "map", -0.5, -0.5), ns)
            .ok();
        Instant::now()
    };
    // wait for the reply carrying `want` (a stamp key in us) on `sub`; returns arrival time
    let mut wait_reply = |sub_token: usize,
                          want: i64,
                          cmd: &Subscription<Twist>,
                          pong: &Subscription<Twist>|
     -> Option<Instant> {
        let deadline = Instant::now() + reply_timeout;
        loop {
            let sub = if sub_token == 0 { cmd } else { pong };
            while let Ok(Some((_, info))) = sub.take() {
                if stamp_key_info(&info) == Some(want) {
                    return Some(Instant::now());
                }
            }
            let now = Instant::now();
            if now >= deadline {
                return None;
            }
            poll.poll(&mut events, Some(deadline - now)).ok();
        }
    };

    // ---- warm-up: discovery on both sides, the robot acting on complete states
    let mut warm_ok = 0;
    while t_start.elapsed().as_secs_f64() < warmup_s || warm_ok < 10 {
        if t_start.elapsed().as_secs_f64() > warmup_s + 30.0 {
            bail!("robot_node never answered during warm-up ({warm_ok} replies)");
        }
        k += 1;
        publish_state(k);
        if wait_reply(0, k * 100_000, &cmd, &pong).is_some() {
            warm_ok += 1;
        }
        ping.write(Twist::planar(0.0, 0.0), Some(k * 1000)).ok();
        wait_reply(1, k, &cmd, &pong);
        std::thread::sleep(interval);
    }
    let pid_stat = |pid: u32| -> Option<u64> {
        let s = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
        let rest = &s[s.rfind(')')? + 2..];
        let f: Vec<&str> = rest.split_whitespace().collect();
        Some(f[11].parse::<u64>().ok()? + f[12].parse::<u64>().ok()?)
    };
    let cpu0 = pid_stat(robot_pid);
    let tm0 = Instant::now();

    // ---- measurement: per slot one bare round trip, then one state
    let (mut bare, mut first, mut last) = (Vec::new(), Vec::new(), Vec::new());
    let (mut lost_state, mut lost_bare) = (0usize, 0usize);
    let mut next = Instant::now();
    for i in 0..n {
        if t_start.elapsed().as_secs_f64() > max_s {
            bail!("time bound reached after {i} states");
        }
        k += 1;
        let t = Instant::now();
        ping.write(Twist::planar(0.0, 0.0), Some(k * 1000)).ok();
        match wait_reply(1, k, &cmd, &pong) {
            Some(r) => bare.push((r - t).as_secs_f64() * 1e6),
            None => lost_bare += 1,
        }
        std::thread::sleep(interval / 2);
        let t_first = Instant::now();
        let t_last = publish_state(k);
        match wait_reply(0, k * 100_000, &cmd, &pong) {
            Some(r) => {
                first.push((r - t_first).as_secs_f64() * 1e6);
                last.push((r - t_last).as_secs_f64() * 1e6);
            }
            None => lost_state += 1,
        }
        next += interval;
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        } else {
            next = now;
        }
    }
    let window = tm0.elapsed().as_secs_f64();
    let cpu1 = pid_stat(robot_pid);
    let tck = 100.0; // USER_HZ
    let cpu_pct = match (cpu0, cpu1) {
        (Some(a), Some(b)) => (b - a) as f64 / tck / window * 100.0,
        _ => f64::NAN,
    };
    let rss_kb = std::fs::read_to_string(format!("/proc/{robot_pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
        });
    drop(robot); // SIGINT: robot_node prints its final stats line
    let mut robot_final = serde_json::Value::Null;
    {
        use std::io::BufRead;
        for line in std::io::BufReader::new(robot_out)
            .lines()
            .map_while(Result::ok)
        {
            if let Ok(v) = serde_json::from_str::<serde_json::Value>(&line) {
                if v["final"] == true {
                    robot_final = v;
                }
            }
        }
    }
    let summary = serde_json::json!({
        "controller": if policy_path.is_empty() { "greedy".to_string() } else { format!("policy:{policy_path}") },
        "n": n,
        "interval_ms": interval.as_millis() as u64,
        "entities": {"machines": machines, "storages": storages, "peers": peers},
        "samples_per_state": 2 + 2 * machines + storages + 2 * peers,
        "state_first_write_to_cmd_us": {"p50": pct(&mut first, 0.5), "p99": pct(&mut first, 0.99), "max": pct(&mut first, 1.0), "count": first.len()},
        "state_last_write_to_cmd_us": {"p50": pct(&mut last, 0.5), "p99": pct(&mut last, 0.99), "max": pct(&mut last, 1.0)},
        "bare_round_trip_us": {"p50": pct(&mut bare, 0.5), "p99": pct(&mut bare, 0.99), "max": pct(&mut bare, 1.0), "count": bare.len()},
        "lost_states": lost_state,
        "lost_bare": lost_bare,
        "robot_node_cpu_pct_one_core": cpu_pct,
        "robot_node_window_s": window,
        "robot_node_rss_kb": rss_kb,
        "robot_final_counters": robot_final,
    });
    println!("{summary}");
    Ok(())
}
