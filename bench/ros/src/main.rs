//! `ros_bench`: robot_node latency benchmark over real DDS on loopback.
//!
//! ```text
//! ros_bench latency --robot-node PATH [--policy CKPT] [--n 200] [--interval-ms 100]
//!                   [--peers 5] [--machines 4] [--storages 2] [--domain D] [--keystore KS]
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
//!
//! `--keystore KS`: the same with DDS Security (Enforce): KS is created if missing (as
//! `tending security create`), robot_node runs in enclave `/tending/robot_0`, this process
//! and the echo helper in `/bench/driver` (the bridge's topics plus `/bench/*`).

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

/// The enclave of this process and the echo helper when `--keystore` is given.
const BENCH_ENCLAVE: &str = "/bench/driver";
const ROBOT_ENCLAVE: &str = "/tending/robot_0";

/// Open (or create) keystore `root` with the benchmark's two enclaves.
fn bench_keystore(root: &str) -> Result<keystore::Keystore> {
    let ks = if std::path::Path::new(root)
        .join("public/ca.cert.pem")
        .is_file()
    {
        keystore::Keystore::open(root)?
    } else {
        keystore::Keystore::create(root)?
    };
    let v = keystore::Validity::days_from_now(1);
    // The bridge's side (as a player: the world state out) plus cmd_vel in and the
    // bare round trip's topics both ways.
    let mut g = keystore::Role::Player.grant();
    g.subscribe.push("rt/*/cmd_vel".into());
    for t in [PING, PONG] {
        g.publish.push(keystore::policy::dds_topic(t));
        g.subscribe.push(keystore::policy::dds_topic(t));
    }
    ks.create_enclave_with_grant(BENCH_ENCLAVE, &g, v)?;
    ks.create_enclave(
        ROBOT_ENCLAVE,
        &keystore::Role::Robots(vec!["robot_0".into()]),
        v,
    )?;
    Ok(ks)
}

/// A node nobody spins: the benchmark needs no graph events, only its endpoints.
/// Security from the environment (`ROS_SECURITY_*`), or `sec` if given.
fn node(domain: u16, name: &str) -> Result<(Context, Node)> {
    node_with(domain, name, None)
}

fn node_with(domain: u16, name: &str, sec: Option<&ros::Security>) -> Result<(Context, Node)> {
    let ctx = match sec {
        Some(s) => ros::context_with(domain, s)?,
        None => ros::context(domain, None)?,
    };
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

/// `ros_bench latency`'s options.
struct LatencyArgs {
    robot_node: String,
    policy: String,
    n: usize,
    interval: Duration,
    warmup_s: f64,
    peers: u32,
    machines: u32,
    storages: u32,
    domain: u16,
    /// DDS Security with this keystore (empty: off).
    keystore: String,
}

impl LatencyArgs {
    fn parse(args: &[String]) -> Result<Self> {
        Ok(Self {
            robot_node: arg(
                args,
                "--robot-node",
                "target/release/robot_node".to_string(),
            )?,
            policy: arg(args, "--policy", String::new())?,
            n: arg(args, "--n", 200)?,
            interval: Duration::from_millis(arg(args, "--interval-ms", 100u64)?),
            warmup_s: arg(args, "--warmup-s", 5.0)?,
            peers: arg(args, "--peers", 5)?,
            machines: arg(args, "--machines", 4)?,
            storages: arg(args, "--storages", 2)?,
            domain: arg(args, "--domain", 100 + (std::process::id() % 100) as u16)?,
            keystore: arg(args, "--keystore", String::new())?,
        })
    }

    /// Every run is bounded: warm-up + n slots + slack.
    fn max_s(&self) -> f64 {
        self.warmup_s + self.n as f64 * self.interval.as_secs_f64() * 1.5 + 30.0
    }
}

/// The bridge's side of the contract for `/robot_0`: every entity's writers and where the
/// entities are.
struct StateWriters {
    own_pose: StampedWriter<PoseStamped>,
    own_part: StampedWriter<Bool>,
    flags: Vec<(StampedWriter<Bool>, bool)>,
    poses: Vec<(StampedWriter<PoseStamped>, f64, f64)>,
}

impl StateWriters {
    fn new(ctx: &Context, node: &Node, me: &str, a: &LatencyArgs) -> Result<Self> {
        let w = |name: String, p: Profile| StampedWriter::new(ctx, node, &name, p);
        let wb = |name: String, p: Profile| StampedWriter::<Bool>::new(ctx, node, &name, p);
        let own_pose = w(
            topics::robot(me, Leaf::Pose).ros_name(),
            Profile::RobotStream,
        )?;
        let own_part = wb(
            topics::robot(me, Leaf::HasPart).ros_name(),
            Profile::RobotStream,
        )?;
        let mut flags = Vec::new();
        let mut poses = Vec::new();
        for j in 0..a.machines {
            let x = -0.8 + 1.6 * j as f64 / (a.machines.max(2) - 1) as f64;
            let pose = topics::machine(j, Leaf::Pose).ros_name();
            poses.push((w(pose, Profile::LatchedPose)?, x, 0.9));
            let ready = topics::machine(j, Leaf::PartReady).ros_name();
            flags.push((wb(ready, Profile::PartReady)?, j % 2 == 0));
        }
        for k in 0..a.storages {
            let x = -0.6 + 1.2 * k as f64 / (a.storages.max(2) - 1) as f64;
            let pose = topics::storage(k, Leaf::Pose).ros_name();
            poses.push((w(pose, Profile::LatchedPose)?, x, -0.95));
        }
        for p in 1..=a.peers {
            let name = format!("robot_{p}");
            let x = -0.9 + 1.8 * p as f64 / (a.peers + 1) as f64;
            let pose = topics::robot(&name, Leaf::Pose).ros_name();
            poses.push((w(pose, Profile::RobotStream)?, x, 0.2));
            let part = topics::robot(&name, Leaf::HasPart).ros_name();
            flags.push((wb(part, Profile::RobotStream)?, p % 3 == 0));
        }
        Ok(Self {
            own_pose,
            own_part,
            flags,
            poses,
        })
    }

    /// Publish state k (the robot's own topics last); returns the time after the last write.
    fn publish(&self, k: i64) -> Instant {
        let st = Time::from_secs_f64(k as f64 * 0.1);
        let ns = Some(k * 100_000_000);
        for (w, x, y) in &self.poses {
            w.write(PoseStamped::planar(st, "map", *x, *y), ns).ok();
        }
        for (w, b) in &self.flags {
            w.write(Bool { data: *b }, ns).ok();
        }
        self.own_part.write(Bool { data: false }, ns).ok();
        self.own_pose
            .write(PoseStamped::planar(st, "map", -0.5, -0.5), ns)
            .ok();
        Instant::now()
    }
}

/// The two replies timed: the robot's cmd_vel (token 0) and the echo's pong (token 1).
struct Replies {
    cmd: Subscription<Twist>,
    pong: Subscription<Twist>,
    poll: Poll,
    events: Events,
}

const CMD: usize = 0;
const PONG_TOKEN: usize = 1;

impl Replies {
    fn new(node: &mut Node, me: &str) -> Result<Self> {
        let cmd_name = topics::robot(me, Leaf::CmdVel).ros_name();
        let mut cmd = subscription::<Twist>(node, &cmd_name, Profile::RobotStream)?;
        let mut pong = subscription::<Twist>(node, PONG, Profile::RobotStream)?;
        let poll = Poll::new()?;
        poll.registry()
            .register(&mut cmd, Token(CMD), Interest::READABLE)?;
        poll.registry()
            .register(&mut pong, Token(PONG_TOKEN), Interest::READABLE)?;
        Ok(Self {
            cmd,
            pong,
            poll,
            events: Events::with_capacity(16),
        })
    }

    /// Wait (at most 1 s) for the reply carrying `want` (a stamp key in us) on `which`;
    /// returns its arrival time.
    fn wait(&mut self, which: usize, want: i64) -> Option<Instant> {
        let deadline = Instant::now() + Duration::from_secs(1);
        loop {
            let sub = if which == CMD { &self.cmd } else { &self.pong };
            while let Ok(Some((_, info))) = sub.take() {
                if stamp_key_info(&info) == Some(want) {
                    return Some(Instant::now());
                }
            }
            let now = Instant::now();
            if now >= deadline {
                return None;
            }
            self.poll.poll(&mut self.events, Some(deadline - now)).ok();
        }
    }
}

/// The echo helper and the robot_node under test (lockstep, stats as JSON on stdout).
fn spawn_peers(a: &LatencyArgs) -> Result<(Kill, Kill)> {
    let exe = std::env::current_exe()?;
    let mut echo = Command::new(&exe);
    let mut rn = Command::new(&a.robot_node);
    if !a.keystore.is_empty() {
        for c in [&mut echo, &mut rn] {
            c.env("ROS_SECURITY_KEYSTORE", &a.keystore)
                .env("ROS_SECURITY_ENABLE", "true")
                .env("ROS_SECURITY_STRATEGY", "Enforce");
        }
        echo.env("ROS_SECURITY_ENCLAVE_OVERRIDE", BENCH_ENCLAVE);
        rn.env_remove("ROS_SECURITY_ENCLAVE_OVERRIDE");
    }
    let echo = Kill(
        echo.args([
            "echo",
            "--domain",
            &a.domain.to_string(),
            "--max-s",
            &format!("{}", a.max_s() + 10.0),
        ])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .spawn()
        .context("starting the echo process")?,
    );
    rn.env("ROS_DOMAIN_ID", a.domain.to_string())
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
    if !a.policy.is_empty() {
        rn.args(["-p", &format!("policy:={}", a.policy)]);
    }
    if !a.keystore.is_empty() {
        rn.args(["--enclave", ROBOT_ENCLAVE]);
    }
    let robot = Kill(
        rn.spawn()
            .with_context(|| format!("starting {}", a.robot_node))?,
    );
    Ok((echo, robot))
}

/// Latencies of one run, in microseconds.
#[derive(Default)]
struct Samples {
    bare: Vec<f64>,
    first: Vec<f64>,
    last: Vec<f64>,
    lost_state: usize,
    lost_bare: usize,
}

/// user + system CPU ticks of a process.
fn cpu_ticks(pid: u32) -> Option<u64> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let rest = &s[s.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    Some(f[11].parse::<u64>().ok()? + f[12].parse::<u64>().ok()?)
}

fn rss_kb(pid: u32) -> Option<u64> {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
        })
}

/// robot_node's final stats line (it prints it on SIGINT).
fn final_counters(out: std::process::ChildStdout) -> serde_json::Value {
    use std::io::BufRead;
    let mut last = serde_json::Value::Null;
    for line in std::io::BufReader::new(out).lines().map_while(Result::ok) {
        if let Ok(v) = serde_json::from_str::<serde_json::Value>(&line) {
            if v["final"] == true {
                last = v;
            }
        }
    }
    last
}

/// The bench: the bridge's writers, the robot and the echo, a warm-up, then per slot one
/// bare round trip and one state; one JSON summary line on stdout.
struct Latency {
    a: LatencyArgs,
    state: StateWriters,
    ping: StampedWriter<Twist>,
    replies: Replies,
    t_start: Instant,
    /// The last state (and ping) stamp sent.
    k: i64,
}

impl Latency {
    /// Warm-up: discovery on both sides, the robot acting on complete states.
    fn warm_up(&mut self) -> Result<()> {
        let mut warm_ok = 0;
        while self.t_start.elapsed().as_secs_f64() < self.a.warmup_s || warm_ok < 10 {
            if self.t_start.elapsed().as_secs_f64() > self.a.warmup_s + 30.0 {
                bail!("robot_node never answered during warm-up ({warm_ok} replies)");
            }
            self.k += 1;
            let k = self.k;
            self.state.publish(k);
            if self.replies.wait(CMD, k * 100_000).is_some() {
                warm_ok += 1;
            }
            self.ping
                .write(Twist::planar(0.0, 0.0), Some(k * 1000))
                .ok();
            self.replies.wait(PONG_TOKEN, k);
            std::thread::sleep(self.a.interval);
        }
        Ok(())
    }

    /// Measurement: per slot one bare round trip, half a slot later one state.
    fn measure(&mut self) -> Result<Samples> {
        let mut s = Samples::default();
        let interval = self.a.interval;
        let mut next = Instant::now();
        for i in 0..self.a.n {
            if self.t_start.elapsed().as_secs_f64() > self.a.max_s() {
                bail!("time bound reached after {i} states");
            }
            self.k += 1;
            let k = self.k;
            let t = Instant::now();
            self.ping
                .write(Twist::planar(0.0, 0.0), Some(k * 1000))
                .ok();
            match self.replies.wait(PONG_TOKEN, k) {
                Some(r) => s.bare.push((r - t).as_secs_f64() * 1e6),
                None => s.lost_bare += 1,
            }
            std::thread::sleep(interval / 2);
            let t_first = Instant::now();
            let t_last = self.state.publish(k);
            match self.replies.wait(CMD, k * 100_000) {
                Some(r) => {
                    s.first.push((r - t_first).as_secs_f64() * 1e6);
                    s.last.push((r - t_last).as_secs_f64() * 1e6);
                }
                None => s.lost_state += 1,
            }
            next += interval;
            let now = Instant::now();
            if next > now {
                std::thread::sleep(next - now);
            } else {
                next = now;
            }
        }
        Ok(s)
    }
}

fn latency(args: &[String]) -> Result<()> {
    let a = LatencyArgs::parse(args)?;
    let me = "robot_0";
    let sec = if a.keystore.is_empty() {
        None
    } else {
        let ks = bench_keystore(&a.keystore)?;
        Some(ros::Security::Enclave {
            enclave: BENCH_ENCLAVE.into(),
            dir: ks.enclave_dir(BENCH_ENCLAVE),
        })
    };
    let (ctx, mut node) = node_with(a.domain, "bench_bridge", sec.as_ref())?;
    let state = StateWriters::new(&ctx, &node, me, &a)?;
    let replies = Replies::new(&mut node, me)?;
    let ping = StampedWriter::<Twist>::new(&ctx, &node, PING, Profile::RobotStream)?;
    let (_echo, mut robot) = spawn_peers(&a)?;
    let robot_pid = robot.0.id();
    let robot_out = robot.0.stdout.take().expect("piped");
    let mut bench = Latency {
        a,
        state,
        ping,
        replies,
        t_start: Instant::now(),
        k: 0,
    };
    bench.warm_up()?;
    let cpu0 = cpu_ticks(robot_pid);
    let tm0 = Instant::now();
    let mut s = bench.measure()?;
    let window = tm0.elapsed().as_secs_f64();
    let cpu_pct = match (cpu0, cpu_ticks(robot_pid)) {
        (Some(a), Some(b)) => (b - a) as f64 / 100.0 / window * 100.0, // USER_HZ 100
        _ => f64::NAN,
    };
    let rss = rss_kb(robot_pid);
    drop(robot); // SIGINT: robot_node prints its final stats line
    let robot_final = final_counters(robot_out);
    let a = &bench.a;
    let (first, last, bare) = (&mut s.first, &mut s.last, &mut s.bare);
    let summary = serde_json::json!({
        "controller": if a.policy.is_empty() { "greedy".to_string() } else { format!("policy:{}", a.policy) },
        "n": a.n,
        "interval_ms": a.interval.as_millis() as u64,
        "entities": {"machines": a.machines, "storages": a.storages, "peers": a.peers},
        "samples_per_state": 2 + 2 * a.machines + a.storages + 2 * a.peers,
        "state_first_write_to_cmd_us": {"p50": pct(first, 0.5), "p99": pct(first, 0.99), "max": pct(first, 1.0), "count": first.len()},
        "state_last_write_to_cmd_us": {"p50": pct(last, 0.5), "p99": pct(last, 0.99), "max": pct(last, 1.0)},
        "bare_round_trip_us": {"p50": pct(bare, 0.5), "p99": pct(bare, 0.99), "max": pct(bare, 1.0), "count": bare.len()},
        "lost_states": s.lost_state,
        "lost_bare": s.lost_bare,
        "robot_node_cpu_pct_one_core": cpu_pct,
        "robot_node_window_s": window,
        "robot_node_rss_kb": rss,
        "robot_final_counters": robot_final,
    });
    println!("{summary}");
    Ok(())
}
