//! End-to-end over real DDS: the `robot_node` binary against a Rust test publisher on a
//! private ROS_DOMAIN_ID (derived from the process id).

use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use msgs::topics::{self, Leaf};
use msgs::{Bool, Clock, PoseStamped, Profile, RosMessage, Time, Twist};
use ros2_client::dds::{Context, ContextOptions, Node, Publisher, Subscription};
use ros2_client::{Name, NodeName, NodeOptions};

fn publisher<M: RosMessage>(node: &mut Node, name: &str, profile: Profile) -> Publisher<M> {
    typed_publisher(node, name, M::type_name(), profile)
}

/// A publisher of `M` under the message type name `ty` (which may not be `M`'s).
fn typed_publisher<M: serde::Serialize>(
    node: &mut Node,
    name: &str,
    ty: ros2_client::MessageTypeName,
    profile: Profile,
) -> Publisher<M> {
    let qos = profile.qos();
    let topic = node
        .create_topic(&Name::parse(name).unwrap(), ty, &qos)
        .unwrap();
    node.create_publisher(&topic, Some(qos)).unwrap()
}

fn cmd_subscription(node: &mut Node, name: &str) -> Subscription<Twist> {
    let qos = Profile::RobotStream.qos();
    let topic = node
        .create_topic(&Name::parse(name).unwrap(), Twist::type_name(), &qos)
        .unwrap();
    node.create_subscription(&topic, Some(qos)).unwrap()
}

/// The test's own DDS participant on domain `d`, with one node `/<name>_<pid>`.
fn test_node(d: u16, name: &str) -> (Context, Node) {
    let ctx = Context::with_options(ContextOptions::new().domain_id(d)).unwrap();
    let node = ctx
        .new_node(
            NodeName::new("/", &format!("{name}_{}", std::process::id())).unwrap(),
            NodeOptions::new().enable_rosout(false),
        )
        .unwrap();
    (ctx, node)
}

/// `robot_node --ros-args <args>` on domain `d`.
fn robot_node(d: u16, args: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_robot_node"));
    c.arg("--ros-args")
        .args(args)
        .env("ROS_DOMAIN_ID", d.to_string());
    c
}

/// Send `signal` (`-TERM`, `-INT`) to the child, then wait up to 5 s for its exit,
/// calling `poll` every `period` meanwhile.
fn signal_and_wait(
    child: &mut Kill,
    signal: &str,
    period: Duration,
    mut poll: impl FnMut(),
) -> std::process::ExitStatus {
    let st = Command::new("kill")
        .args([signal, &child.0.id().to_string()])
        .status()
        .unwrap();
    assert!(st.success());
    let t_kill = Instant::now();
    loop {
        poll();
        if let Some(s) = child.0.try_wait().unwrap() {
            return s;
        }
        assert!(
            t_kill.elapsed() < Duration::from_secs(5),
            "robot_node did not exit on {signal}"
        );
        std::thread::sleep(period);
    }
}

/// A message with the PoseStamped type name but a 1-byte body: must be dropped as undecodable.
#[derive(serde::Serialize, serde::Deserialize)]
struct Short {
    data: bool,
}

fn wait_for(
    cmd: &Subscription<Twist>,
    within: Duration,
    pred: impl Fn(&Twist) -> bool,
) -> Option<Duration> {
    let t0 = Instant::now();
    while t0.elapsed() < within {
        while let Ok(Some((t, _))) = cmd.take() {
            assert!(
                msgs::validate::twist(&t).is_ok(),
                "non-finite cmd_vel {t:?}"
            );
            if pred(&t) {
                return Some(t0.elapsed());
            }
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    None
}

struct Kill(Child);
impl Drop for Kill {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn bad_argument_exits_2_naming_it() {
    let out = Command::new(env!("CARGO_BIN_EXE_robot_node"))
        .args(["--ros-args", "-p", "k_speed:=fast"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("k_speed"), "{err}");
}

/// Publishers of robot_0's world: its own pose and part, a ready machine to its right, a
/// storage, a peer carrying a part, and garbage on its own pose topic.
struct World0 {
    own_pose: Publisher<PoseStamped>,
    own_part: Publisher<Bool>,
    m_pose: Publisher<PoseStamped>,
    m_ready: Publisher<Bool>,
    s_pose: Publisher<PoseStamped>,
    peer_pose: Publisher<PoseStamped>,
    peer_part: Publisher<Bool>,
    short_pose: Publisher<Short>,
}

impl World0 {
    fn new(node: &mut Node) -> Self {
        Self {
            own_pose: publisher(node, "/robot_0/pose", Profile::RobotStream),
            own_part: publisher(node, "/robot_0/has_part", Profile::RobotStream),
            m_pose: publisher(node, "/machine_0/pose", Profile::LatchedPose),
            m_ready: publisher(node, "/machine_0/part_ready", Profile::PartReady),
            s_pose: publisher(node, "/storage_0/pose", Profile::LatchedPose),
            peer_pose: publisher(node, "/robot_5/pose", Profile::RobotStream),
            peer_part: publisher(node, "/robot_5/has_part", Profile::RobotStream),
            short_pose: typed_publisher(
                node,
                "/robot_0/pose",
                PoseStamped::type_name(),
                Profile::RobotStream,
            ),
        }
    }

    /// Publish at 20 Hz until `running` clears; robot_0's own pose (and the garbage on
    /// its topic) only while `own_alive` is set.
    fn spawn(
        self,
        own_alive: Arc<AtomicBool>,
        running: Arc<AtomicBool>,
    ) -> std::thread::JoinHandle<()> {
        std::thread::spawn(move || {
            let mut i = 0u64;
            while running.load(Ordering::SeqCst) {
                let st = Time::now();
                if own_alive.load(Ordering::SeqCst) {
                    self.own_pose
                        .publish(PoseStamped::planar(st, "map", -0.5, -0.5))
                        .ok();
                    if i.is_multiple_of(2) {
                        // garbage that must be dropped, never reach the controller
                        let mut bad = PoseStamped::planar(st, "map", f64::NAN, 0.0);
                        self.own_pose.publish(bad.clone()).ok();
                        bad.pose.position.x = 7.0;
                        self.own_pose.publish(bad).ok();
                        self.short_pose.publish(Short { data: true }).ok();
                    }
                }
                self.own_part.publish(Bool { data: false }).ok();
                self.m_pose
                    .publish(PoseStamped::planar(st, "map", 0.5, -0.5))
                    .ok();
                self.m_ready.publish(Bool { data: true }).ok();
                self.peer_pose
                    .publish(PoseStamped::planar(st, "map", 0.9, 0.9))
                    .ok();
                self.peer_part.publish(Bool { data: true }).ok();
                self.s_pose
                    .publish(PoseStamped::planar(st, "map", -0.5, 0.8))
                    .ok();
                i += 1;
                std::thread::sleep(Duration::from_millis(50));
            }
        })
    }
}

/// Phase 1: the first non-zero command toward the machine (+x) within 12 s, and when.
fn first_command_toward_machine(cmd: &Subscription<Twist>) -> (Option<Twist>, Duration) {
    let t0 = Instant::now();
    let mut got: Option<Twist> = None;
    while t0.elapsed() < Duration::from_secs(12) {
        while let Ok(Some((t, _))) = cmd.take() {
            assert!(
                msgs::validate::twist(&t).is_ok(),
                "non-finite cmd_vel {t:?}"
            );
            if t.linear.x > 0.0 {
                got = Some(t);
            }
        }
        if got.is_some() {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    (got, t0.elapsed())
}

/// Phase 2 (own pose just stopped): how long until a zero command, ignoring the first
/// 200 ms; None within 5 s.
fn zero_after_own_pose_stops(cmd: &Subscription<Twist>) -> Option<Duration> {
    let stop_at = Instant::now();
    let mut zero_after: Option<Duration> = None;
    while stop_at.elapsed() < Duration::from_secs(5) {
        while let Ok(Some((t, _))) = cmd.take() {
            if t.linear.x == 0.0
                && t.linear.y == 0.0
                && stop_at.elapsed() > Duration::from_millis(200)
            {
                zero_after.get_or_insert(stop_at.elapsed());
            }
        }
        if zero_after.is_some() {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    zero_after
}

/// The node's log reports every kind of dropped input, discovered every topic, and
/// ended with the final counters.
fn assert_log_reports_drops_and_discovery(log: &str) {
    assert!(
        log.contains("Decode"),
        "undecodable poses were not reported:\n{log}"
    );
    assert!(log.contains("final counters"), "{log}");
    for t in [
        "/machine_0/pose",
        "/machine_0/part_ready",
        "/storage_0/pose",
        "/robot_5/pose",
        "/robot_5/has_part",
    ] {
        assert!(
            log.contains(&format!("discovered {t}")),
            "{t} not discovered:\n{log}"
        );
    }
    assert!(
        log.contains("NonFinite"),
        "NaN poses were not reported as dropped:\n{log}"
    );
    assert!(
        log.contains("OutOfRoom"),
        "out-of-room poses were not reported:\n{log}"
    );
}

#[test]
fn commands_toward_machine_then_zero_when_own_pose_stale() {
    let d = test_domains::domain(0);
    let (_ctx, mut node) = test_node(d, "test_pub");
    let world = World0::new(&mut node);
    let cmd = cmd_subscription(
        &mut node,
        &topics::robot("robot_0", Leaf::CmdVel).ros_name(),
    );

    let log_path = std::env::temp_dir().join(format!("robot_node_it_{}.log", std::process::id()));
    let log = std::fs::File::create(&log_path).unwrap();
    let child = robot_node(
        d,
        &[
            "-r",
            "__ns:=/robot_0",
            "-p",
            "control_rate_hz:=20",
            "-p",
            "stale_timeout_s:=1.0",
            "-p",
            "k_speed:=0.5",
            "-p",
            "discovery_period_s:=0.2",
        ],
    )
    .env("RUST_LOG", "info,rustdds=warn,ros2_client=warn")
    .stdout(Stdio::null())
    .stderr(log)
    .spawn()
    .unwrap();
    let mut child = Kill(child);
    let show_log = || std::fs::read_to_string(&log_path).unwrap_or_default();

    let own_alive = Arc::new(AtomicBool::new(true));
    let running = Arc::new(AtomicBool::new(true));
    let pub_thread = world.spawn(own_alive.clone(), running.clone());

    // Phase 1: a non-zero command toward the machine (+x) arrives.
    let (got, first) = first_command_toward_machine(&cmd);
    let t =
        got.unwrap_or_else(|| panic!("no cmd_vel toward the machine; node log:\n{}", show_log()));
    assert!((t.linear.x - 0.5).abs() < 1e-9, "{t:?}");
    assert_eq!(t.linear.y, 0.0);
    eprintln!("first command toward machine after {first:?}");

    // Phase 2: own pose stops; zero velocity follows within the stale timeout (+ slack).
    own_alive.store(false, Ordering::SeqCst);
    let z = zero_after_own_pose_stops(&cmd).unwrap_or_else(|| {
        panic!(
            "no zero cmd_vel after own pose stopped; log:\n{}",
            show_log()
        )
    });
    eprintln!("zero command {z:?} after own pose stopped");
    assert!(z >= Duration::from_millis(800), "zero too early: {z:?}");
    assert!(z <= Duration::from_millis(2500), "zero too late: {z:?}");

    // Phase 3: own pose comes back -> moving again; then SIGTERM -> a zero command and a
    // clean exit (status 0).
    own_alive.store(true, Ordering::SeqCst);
    let back = wait_for(&cmd, Duration::from_secs(5), |t| t.linear.x > 0.4)
        .unwrap_or_else(|| panic!("no command after own pose returned; log:\n{}", show_log()));
    eprintln!("moving again {back:?} after own pose returned");
    running.store(false, Ordering::SeqCst);
    pub_thread.join().unwrap();
    // read cmd_vel while the node shuts down (samples of a writer that is gone may be
    // discarded by the reader)
    let mut last = None;
    let status = signal_and_wait(&mut child, "-TERM", Duration::from_millis(5), || {
        while let Ok(Some((t, _))) = cmd.take() {
            last = Some(t);
        }
    });
    let log = show_log();
    assert!(status.success(), "exit status {status:?}; log:\n{log}");
    // the last command received is the zero published on shutdown
    assert_eq!(
        last,
        Some(Twist::zero()),
        "no zero cmd_vel on shutdown; log:\n{log}"
    );
    assert_log_reports_drops_and_discovery(&log);
    eprintln!(
        "{}",
        log.lines()
            .filter(|l| l.contains("counters"))
            .collect::<Vec<_>>()
            .join("\n")
    );
    std::fs::remove_file(&log_path).ok();
}

#[test]
fn sim_time_ticks_follow_clock() {
    let d = test_domains::domain(1);
    let (_ctx, mut node) = test_node(d, "test_clock");
    let clock: Publisher<Clock> = publisher(&mut node, "/clock", Profile::Clock);
    let own_pose: Publisher<PoseStamped> =
        publisher(&mut node, "/robot_1/pose", Profile::RobotStream);
    let own_part: Publisher<Bool> = publisher(&mut node, "/robot_1/has_part", Profile::RobotStream);
    let s_pose: Publisher<PoseStamped> =
        publisher(&mut node, "/storage_3/pose", Profile::LatchedPose);
    let cmd = cmd_subscription(&mut node, "/robot_1/cmd_vel");

    let child = robot_node(
        d,
        &[
            "-r",
            "__ns:=/robot_1",
            "-p",
            "use_sim_time:=true",
            "-p",
            "control_rate_hz:=10",
            "-p",
            "discovery_period_s:=0.2",
        ],
    )
    .stdout(Stdio::null())
    .stderr(Stdio::null())
    .spawn()
    .unwrap();
    let _child = Kill(child);

    // Robot has a part, storage is up (+y): expect linear.y = +0.5 while the clock runs.
    let publish_data = |st: Time| {
        own_pose
            .publish(PoseStamped::planar(st, "map", 0.0, -0.5))
            .ok();
        own_part.publish(Bool { data: true }).ok();
        s_pose
            .publish(PoseStamped::planar(st, "map", 0.0, 1.0))
            .ok();
    };
    let mut sim_t = 0.0f64;
    let mut up = 0usize;
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(10) && up < 5 {
        sim_t += 0.05;
        let st = Time::from_secs_f64(sim_t);
        clock.publish(Clock { clock: st }).ok();
        publish_data(st);
        while let Ok(Some((t, _))) = cmd.take() {
            if t.linear.y > 0.4 && t.linear.x == 0.0 {
                up += 1;
            }
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(up >= 5, "only {up} commands toward the storage in sim time");
    // Clock stops (data keeps flowing): no more ticks, so no more commands.
    std::thread::sleep(Duration::from_millis(200));
    while let Ok(Some(_)) = cmd.take() {}
    let quiet = Instant::now();
    let mut n = 0;
    while quiet.elapsed() < Duration::from_millis(800) {
        publish_data(Time::from_secs_f64(sim_t));
        while let Ok(Some(_)) = cmd.take() {
            n += 1;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(n, 0, "commands while /clock was stopped");
}

/// Publishers of robot_0 (no part, left of the ready machine: heads +x) and robot_1
/// (carrying a part, below the storage: heads +y), the machine and the storage.
struct TwoRobotWorld {
    pose_pubs: Vec<Publisher<PoseStamped>>,
    part_pubs: Vec<Publisher<Bool>>,
    m_pose: Publisher<PoseStamped>,
    m_ready: Publisher<Bool>,
    s_pose: Publisher<PoseStamped>,
}

impl TwoRobotWorld {
    fn new(node: &mut Node) -> Self {
        Self {
            pose_pubs: ["/robot_0/pose", "/robot_1/pose"]
                .iter()
                .map(|n| publisher(node, n, Profile::RobotStream))
                .collect(),
            part_pubs: ["/robot_0/has_part", "/robot_1/has_part"]
                .iter()
                .map(|n| publisher(node, n, Profile::RobotStream))
                .collect(),
            m_pose: publisher(node, "/machine_0/pose", Profile::LatchedPose),
            m_ready: publisher(node, "/machine_0/part_ready", Profile::PartReady),
            s_pose: publisher(node, "/storage_0/pose", Profile::LatchedPose),
        }
    }

    /// Publish at 20 Hz until `running` clears; returns the machine's and the robots'
    /// pose publishers.
    fn spawn(
        self,
        running: Arc<AtomicBool>,
    ) -> std::thread::JoinHandle<(Publisher<PoseStamped>, Vec<Publisher<PoseStamped>>)> {
        let Self {
            pose_pubs,
            part_pubs,
            m_pose,
            m_ready,
            s_pose,
        } = self;
        std::thread::spawn(move || {
            while running.load(Ordering::SeqCst) {
                let st = Time::now();
                pose_pubs[0]
                    .publish(PoseStamped::planar(st, "map", -0.5, -0.5))
                    .ok();
                part_pubs[0].publish(Bool { data: false }).ok();
                pose_pubs[1]
                    .publish(PoseStamped::planar(st, "map", -0.5, 0.2))
                    .ok();
                part_pubs[1].publish(Bool { data: true }).ok();
                m_pose
                    .publish(PoseStamped::planar(st, "map", 0.5, -0.5))
                    .ok();
                m_ready.publish(Bool { data: true }).ok();
                s_pose
                    .publish(PoseStamped::planar(st, "map", -0.5, 0.8))
                    .ok();
                std::thread::sleep(Duration::from_millis(50));
            }
            (m_pose, pose_pubs)
        })
    }
}

/// One final stats line per hosted robot, each with the process's 7 shared readers
/// (2 own topics per robot + machine pose/part_ready + storage pose; separate readers per
/// robot would be 2 x 7 = 14), commands, and no foreign-writer drops.
fn assert_final_stats(out_path: &std::path::Path) {
    let finals: Vec<serde_json::Value> = std::fs::read_to_string(out_path)
        .unwrap()
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|v| v["final"] == true)
        .collect();
    assert_eq!(finals.len(), 2, "one final stats line per robot");
    for (f, me) in finals.iter().zip(["robot_0", "robot_1"]) {
        assert_eq!(f["robot"], me);
        assert_eq!(f["subscriptions"], 7, "{f}");
        assert!(f["commands"].as_u64().unwrap() > 5, "{f}");
        assert_eq!(f["dropped"]["foreign_writer"], 0, "{f}");
    }
}

/// Two robots in one process (`-p robots:=robot_0,robot_1`): one reader per topic for
/// both (robot_1's own topics are robot_0's peer topics and vice versa), each robot acts
/// on its own data and sees the other as a peer, each has its own cmd_vel.
#[test]
fn two_robots_in_one_process_share_one_reader_per_topic() {
    let d = test_domains::domain(2);
    let (_ctx, mut node) = test_node(d, "test_multi");
    let world = TwoRobotWorld::new(&mut node);
    // spun, so that the node learns which readers its writers matched
    let spinner = node.spinner().unwrap();
    std::thread::spawn(move || smol::block_on(spinner.spin()));
    let cmd0 = cmd_subscription(&mut node, "/robot_0/cmd_vel");
    let cmd1 = cmd_subscription(&mut node, "/robot_1/cmd_vel");

    let tmp = std::env::temp_dir();
    let err_path = tmp.join(format!("robot_node_multi_{}.log", std::process::id()));
    let out_path = tmp.join(format!("robot_node_multi_{}.jsonl", std::process::id()));
    let child = robot_node(
        d,
        &[
            "-p",
            "robots:=robot_0..1",
            "-p",
            "control_rate_hz:=20",
            "-p",
            "discovery_period_s:=0.2",
            "-p",
            "stats_json:=true",
            "-p",
            "stats_period_s:=0.5",
        ],
    )
    .env("RUST_LOG", "info,rustdds=warn,ros2_client=warn")
    .stdout(std::fs::File::create(&out_path).unwrap())
    .stderr(std::fs::File::create(&err_path).unwrap())
    .spawn()
    .unwrap();
    let mut child = Kill(child);
    let show_log = || std::fs::read_to_string(&err_path).unwrap_or_default();

    let running = Arc::new(AtomicBool::new(true));
    let pub_thread = world.spawn(running.clone());
    let right = wait_for(&cmd0, Duration::from_secs(15), |t| {
        t.linear.x > 0.4 && t.linear.y == 0.0
    });
    let up = wait_for(&cmd1, Duration::from_secs(5), |t| {
        t.linear.y > 0.4 && t.linear.x == 0.0
    });
    // let a stats period pass with everything known
    std::thread::sleep(Duration::from_millis(1200));
    running.store(false, Ordering::SeqCst);
    let (m_pose, pose_pubs) = pub_thread.join().unwrap();
    // one DDS reader per topic in the robot_node process: the machine's pose writer and
    // robot_1's pose writer each matched exactly one reader (two robots with their own
    // readers would make two)
    let matched = (
        m_pose.get_subscription_count(&node),
        pose_pubs[1].get_subscription_count(&node),
    );
    let status = signal_and_wait(&mut child, "-INT", Duration::from_millis(10), || {});
    let log = show_log();
    assert!(status.success(), "exit status {status:?}; log:\n{log}");
    assert!(right.is_some(), "robot_0 never commanded +x; log:\n{log}");
    assert!(up.is_some(), "robot_1 never commanded +y; log:\n{log}");
    assert_eq!(
        matched,
        (1, 1),
        "readers matched by /machine_0/pose, /robot_1/pose"
    );
    assert_final_stats(&out_path);
    // each sees one peer (the other hosted robot), one machine, one storage
    for me in ["robot_0", "robot_1"] {
        assert!(
            log.contains(&format!("counters {me}: accepted=",))
                && log.lines().any(|l| l.contains(&format!("counters {me}:"))
                    && l.contains("known machines=1 storages=1 peers=1")),
            "{me} did not know 1 machine, 1 storage, 1 peer:\n{log}"
        );
    }
    assert!(log.contains("2 robots in one process"), "{log}");
    std::fs::remove_file(&err_path).ok();
    std::fs::remove_file(&out_path).ok();
}

/// Lockstep (docs/adr/0029-lockstep-resends.md): a robot that answered a state sends the
/// same answer, stamped with that state, again every `lockstep_resend_s` while no newer
/// state comes (the bridge may not have received it); with 0 it answers once. The test
/// stands in for the bridge: it publishes one state (own pose and has_part, stamped
/// 0.1 s) until the first answer, then only listens.
#[test]
fn lockstep_answer_is_resent_while_no_newer_state_comes() {
    const STAMP_NS: i64 = 100_000_000;
    for (i, (resend, extra_min, extra_max)) in
        [("0.3", 2, 5), ("0.0", 0, 0)].into_iter().enumerate()
    {
        let d = test_domains::domain(3 + i as u16);
        let (ctx, mut node) = test_node(d, "lockstep_resend");
        let pose_pub: Publisher<PoseStamped> =
            publisher(&mut node, "/robot_0/pose", Profile::RobotStream);
        let part =
            ros::StampedWriter::<Bool>::new(&ctx, &node, "/robot_0/has_part", Profile::RobotStream)
                .unwrap();
        let cmd = cmd_subscription(&mut node, "/robot_0/cmd_vel");
        // killed when dropped, at the end of the iteration
        let _child = Kill(
            robot_node(
                d,
                &[
                    "-r",
                    "__ns:=/robot_0",
                    "-p",
                    "lockstep:=true",
                    "-p",
                    &format!("lockstep_resend_s:={resend}"),
                    "--disable-rosout-logs",
                ],
            )
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
        );
        let pose = PoseStamped::planar(Time::from_secs_f64(0.1), "map", 0.0, 0.0);
        // the state until the first answer stamped with it
        let answers = |cmd: &Subscription<Twist>| {
            let mut n = 0;
            while let Ok(Some((_, info))) = cmd.take() {
                if ros::stamp_key_info(&info) == Some(STAMP_NS / 1000) {
                    n += 1;
                }
            }
            n
        };
        let deadline = Instant::now() + Duration::from_secs(20);
        let mut first = 0;
        while first == 0 {
            assert!(
                Instant::now() < deadline,
                "no answer to the state (resend {resend})"
            );
            pose_pub.publish(pose.clone()).unwrap();
            part.write(Bool { data: false }, Some(STAMP_NS)).unwrap();
            std::thread::sleep(Duration::from_millis(100));
            first = answers(&cmd);
        }
        // then no newer state: count the copies in the next second
        std::thread::sleep(Duration::from_millis(1000));
        let extra = answers(&cmd) + first - 1;
        assert!(
            (extra_min..=extra_max).contains(&extra),
            "lockstep_resend_s {resend}: {extra} resent answers in 1 s, expected \
             {extra_min}..={extra_max}"
        );
    }
}
