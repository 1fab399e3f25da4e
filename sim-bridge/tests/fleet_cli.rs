//! `tending fleet` end to end: a short realtime fleet delivers parts and exits 0; a
//! lockstep fleet stops by itself at the requested sim time.
//!
//! Needs `tending`, `sim_bridge` and `robot_node` in the same target directory:
//! `cargo build --release --bin tending -p robot-node -p sim-bridge` first.

use std::path::PathBuf;
use std::process::Command;

fn tending() -> PathBuf {
    let p = PathBuf::from(env!("CARGO_BIN_EXE_sim_bridge"))
        .parent()
        .unwrap()
        .join("tending");
    assert!(
        p.exists(),
        "{} not built: cargo build --release --bin tending",
        p.display()
    );
    p
}

/// `tending fleet ARGS... --no-stdin --domain DOMAIN`; asserts it exited 0 and returns
/// its stdout.
fn run_fleet(args: &[&std::ffi::OsStr], domain: u16) -> String {
    let out = Command::new(tending())
        .arg("fleet")
        .args(args)
        .args(["--no-stdin", "--domain", &domain.to_string()])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "fleet {args:?} failed: {}\n{stdout}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

fn final_metrics(stdout: &str) -> serde_json::Value {
    let line = stdout
        .lines()
        .rev()
        .find_map(|l| l.strip_prefix("final: "))
        .unwrap_or_else(|| panic!("no final line in:\n{stdout}"));
    serde_json::from_str(line).unwrap()
}

#[test]
fn realtime_fleet_delivers_parts_and_stops_cleanly() {
    let domain = test_domains::domain(0);
    let out = Command::new(tending())
        .args([
            "fleet",
            "--setup",
            "6.4_2",
            "--duration",
            "12",
            "--seed",
            "0",
        ])
        .args(["--domain", &domain.to_string()])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "fleet failed: {}\n{stdout}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    let m = final_metrics(&stdout);
    assert_eq!(m["robots"], 6, "{m}");
    assert!(m["parts_delivered"].as_u64().unwrap() > 0, "{m}");
    assert!(m["step"].as_u64().unwrap() >= 80, "{m}");
    assert_eq!(m["cmds_dropped_non_finite"], 0, "{m}");
}

/// Robots grouped several per robot_node process (what large fleets get by default) work
/// like one process per robot: every robot acts on the bridge's state and parts arrive.
#[test]
fn grouped_robot_processes_keep_every_robot_on_state() {
    let domain = test_domains::domain(1);
    let out = Command::new(tending())
        .args(["fleet", "--setup", "6.4_2", "--duration", "12"])
        .args(["--robots-per-process", "3", "--no-stdin"])
        .args(["--domain", &domain.to_string()])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "fleet failed: {}\n{stdout}\n{stderr}",
        out.status
    );
    assert!(
        stderr.contains("6 robots in 2 robot_node processes"),
        "{stderr}"
    );
    let m = final_metrics(&stdout);
    assert_eq!(m["robots"], 6, "{m}");
    assert!(m["parts_delivered"].as_u64().unwrap() > 0, "{m}");
    // health lines: every robot acting on state once started
    assert!(stdout.contains("on_state=6 "), "{stdout}");
}

#[test]
fn lockstep_fleet_ends_at_the_requested_sim_time() {
    let domain = test_domains::domain(2);
    let out = Command::new(tending())
        .args([
            "fleet",
            "--setup",
            "3.2_1",
            "--duration",
            "5",
            "--mode",
            "lockstep",
        ])
        .args(["--domain", &domain.to_string()])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "fleet failed: {}\n{stdout}",
        out.status
    );
    let m = final_metrics(&stdout);
    assert_eq!(m["step"], 50, "{m}");
    assert_eq!(m["lockstep_timeouts"], 0, "{m}");
}

/// `tending fleet --record DIR`: the bridge's bag holds the run; `tending bag metrics`
/// recomputes from it the parts the bridge reported in its final metrics line.
#[test]
fn recorded_fleet_bag_matches_the_final_metrics() {
    let domain = test_domains::domain(3);
    let dir = std::env::temp_dir().join(format!("tending-rec-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let stdout = run_fleet(
        &[
            "--setup".as_ref(),
            "4.4_2".as_ref(),
            "--duration".as_ref(),
            "10".as_ref(),
            "--record".as_ref(),
            dir.as_os_str(),
        ],
        domain,
    );
    let m = final_metrics(&stdout);
    let parts = m["parts_delivered"].as_u64().unwrap();
    assert!(parts > 0, "{m}");
    let bm = Command::new(tending())
        .args(["bag", "metrics"])
        .arg(&dir)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&bm.stdout);
    assert!(bm.status.success(), "bag metrics failed:\n{text}");
    assert!(!text.contains("not complete"), "{text}");
    let grab = |prefix: &str| -> u64 {
        let l = text
            .lines()
            .find_map(|l| l.strip_prefix(prefix))
            .unwrap_or_else(|| panic!("no `{prefix}` in:\n{text}"));
        l.split_whitespace().next().unwrap().parse().unwrap()
    };
    assert_eq!(grab("total from /tending/metrics: "), parts, "{text}\n{m}");
    // contacts by kind, as the bridge reported them last
    let kinds = text
        .lines()
        .find_map(|l| l.strip_prefix("collisions by kind from /tending/metrics: "))
        .unwrap_or_else(|| panic!("no collisions by kind in:\n{text}"));
    let rr = format!("robot-robot {}", m["collisions_robot_robot"]);
    assert!(kinds.starts_with(&rr), "{kinds} vs {m}");
    assert_eq!(grab("total from has_part: "), parts, "{text}\n{m}");
    // every robot's cmd_vel was recorded as received
    let r = bag::BagReader::open(&dir).unwrap();
    assert!(r.complete, "bag not finalized");
    for i in 0..4 {
        let n = r
            .decode_topic::<msgs::Twist>(&format!("/robot_{i}/cmd_vel"))
            .unwrap()
            .len();
        assert!(n >= 50, "robot_{i}: {n} cmd_vel recorded");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Real time: no robot acts before its inputs settled (ADR 0024). Its first command is
/// computed with every machine, storage and peer of the setup known; before the settle
/// rule, robots of a 20-robot fleet acted with no machine known yet and drove into them.
#[test]
fn realtime_robots_first_act_with_every_entity_known() {
    let domain = test_domains::domain(4);
    let logs = std::env::temp_dir().join(format!("tending-settle-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&logs);
    run_fleet(
        &[
            "--setup".as_ref(),
            "6.4_2".as_ref(),
            "--duration".as_ref(),
            "6".as_ref(),
            "--log-dir".as_ref(),
            logs.as_os_str(),
        ],
        domain,
    );
    for i in 0..6 {
        let log = std::fs::read_to_string(logs.join(format!("robot_{i}.log"))).unwrap();
        let first = log
            .lines()
            .find(|l| l.contains("controlling: observation counts"))
            .unwrap_or_else(|| panic!("robot_{i} never acted:\n{log}"));
        assert!(
            first.contains("machines: 4, storages: 2, peers: 5"),
            "robot_{i} first acted on an incomplete world: {first}"
        );
        assert!(log.contains("inputs settled"), "robot_{i}:\n{log}");
    }
    let _ = std::fs::remove_dir_all(&logs);
}

/// Robot positions by (stamp in ms, robot index) from a recorded bag.
fn recorded_poses(
    dir: &std::path::Path,
    robots: usize,
) -> std::collections::BTreeMap<(i64, usize), (f64, f64)> {
    let r = bag::BagReader::open(dir).unwrap();
    let mut m = std::collections::BTreeMap::new();
    for i in 0..robots {
        let poses = r
            .decode_topic::<msgs::PoseStamped>(&format!("/robot_{i}/pose"))
            .unwrap();
        for (_, p) in poses {
            let ms = p.header.stamp.sec as i64 * 1000 + p.header.stamp.nanosec as i64 / 1_000_000;
            m.insert((ms, i), (p.pose.position.x, p.pose.position.y));
        }
    }
    m
}

/// Real time acts on each whole state and its commands reach the bridge before the next
/// step (ADR 0024), so a realtime run is the lockstep run, which is the offline episode:
/// the same position for every robot at every step both recorded. Only a late command
/// (the bridge's `cmd_age_1`+) or a state acted on before it was whole may break that,
/// and then most commands must still answer the stepped state.
#[test]
fn realtime_fleet_moves_robots_as_lockstep_does() {
    let domain = test_domains::domain(5);
    let base = std::env::temp_dir().join(format!("tending-rt-vs-ls-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&base);
    let run = |mode: &str, secs: &str| {
        let dir = base.join(mode);
        let logs = base.join(format!("{mode}-logs"));
        let stdout = run_fleet(
            &[
                "--setup".as_ref(),
                "6.4_2".as_ref(),
                "--duration".as_ref(),
                secs.as_ref(),
                "--mode".as_ref(),
                mode.as_ref(),
                "--record".as_ref(),
                dir.as_os_str(),
                "--log-dir".as_ref(),
                logs.as_os_str(),
            ],
            domain,
        );
        (recorded_poses(&dir, 6), final_metrics(&stdout))
    };
    let (ls, _) = run("lockstep", "6");
    let (rt, m) = run("realtime", "6");
    let late: u64 = ["cmd_age_1", "cmd_age_2", "cmd_age_3plus"]
        .iter()
        .map(|k| m[k].as_u64().unwrap())
        .sum();
    let on_time = m["cmd_age_0"].as_u64().unwrap();
    let waits: u64 = (0..6)
        .map(|i| {
            let log =
                std::fs::read_to_string(base.join(format!("realtime-logs/robot_{i}.log"))).unwrap();
            let last = log
                .lines()
                .rev()
                .find(|l| l.contains("final counters"))
                .unwrap();
            let v = last.split("state_wait_timeouts=").nth(1).unwrap();
            v.split_whitespace().next().unwrap().parse::<u64>().unwrap()
        })
        .sum();
    let common: Vec<_> = rt.keys().filter(|k| ls.contains_key(k)).collect();
    assert!(
        common.len() >= 6 * 40,
        "only {} common samples",
        common.len()
    );
    let differ = common.iter().filter(|k| rt[k] != ls[k]).count();
    if late == 0 && waits == 0 {
        assert_eq!(
            differ,
            0,
            "{differ} of {} positions differ: {m}",
            common.len()
        );
    } else {
        eprintln!("realtime run had {late} late commands and {waits} wait timeouts: not compared");
        assert!(on_time >= 9 * late, "{on_time} on time, {late} late: {m}");
    }
    let _ = std::fs::remove_dir_all(&base);
}

/// `tending fleet --cell-size` (docs/adr/0038-cell-topics.md) with robots grouped several
/// per process: the bridge publishes and records the cell topics, every robot reads the
/// cells around it and none of its peers', machines' or storages' own topics, and the
/// lockstep run ends without a robot acting on an incomplete state.
#[test]
fn a_fleet_on_cell_topics_reads_cells_not_entities() {
    let domain = test_domains::domain(6);
    let dir = std::env::temp_dir().join(format!("tending-cells-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let (bag_dir, logs) = (dir.join("bag"), dir.join("logs"));
    let stdout = run_fleet(
        &[
            "--setup".as_ref(),
            "12.8_4".as_ref(),
            "--floor".as_ref(),
            "grown".as_ref(),
            "--nearest".as_ref(),
            "3".as_ref(),
            "--cell-size".as_ref(),
            "1".as_ref(),
            "--policy".as_ref(),
            "matching-orca".as_ref(),
            "--mode".as_ref(),
            "lockstep".as_ref(),
            "--duration".as_ref(),
            "3".as_ref(),
            "--robots-per-process".as_ref(),
            "4".as_ref(),
            "--record".as_ref(),
            bag_dir.as_os_str(),
            "--log-dir".as_ref(),
            logs.as_os_str(),
        ],
        domain,
    );
    let m = final_metrics(&stdout);
    assert_eq!(m["step"], 30, "{m}");
    assert_eq!(m["lockstep_timeouts"], 0, "{m}");
    let r = bag::BagReader::open(&bag_dir).unwrap();
    let cells = r.decode_topic::<msgs::Path>("/tending/cells/c0_0").unwrap();
    assert!(cells.len() >= 30, "{} cell samples recorded", cells.len());
    let mut robot_logs = 0;
    for e in std::fs::read_dir(&logs).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        if !name.starts_with("robot_") {
            continue;
        }
        robot_logs += 1;
        let text = std::fs::read_to_string(&p).unwrap();
        assert!(
            text.contains("subscribed to cell /tending/cells/c"),
            "{name}:\n{text}"
        );
        assert!(
            !text.contains("discovered /"),
            "{name} read an entity topic:\n{text}"
        );
        assert!(text.contains("lockstep_wait_timeouts=0"), "{name}:\n{text}");
    }
    assert_eq!(robot_logs, 3, "12 robots, 4 per process");
    let _ = std::fs::remove_dir_all(&dir);
}
