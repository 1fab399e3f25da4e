//! Fault (d): a robot's node dies in a realtime fleet (`kill robot_1` typed into `tending
//! fleet`, the README's main job, 6.4_2). A real base stops on a short command timeout; the
//! bridge does the same (`cmd_vel_timeout_s`, which `tending fleet` sets to 3 control
//! periods, 0.3 s; docs/adr/0031-command-timeout.md): the dead robot's body must stop
//! within the timeout and a few ticks, touch nothing (no contact step
//! involving it: walls, machines, storages or peers) until the bridge removes it, and be
//! removed at the staleness timeout as before.
//!
//! Contacts are recomputed from the bridge's bag (`--record`) with the simulator's rule
//! (`sim::Env`'s collision count: surface distance at most `task.collision_distance`),
//! per step of the killed robot's pose, against the peers' poses of the same step and the
//! machines, storages and walls; the fleet's own total from `/tending/metrics` after the kill
//! is reported beside it.
//!
//! `TENDING_KILL_AT_S` (default 12) sets when the kill is typed (seconds after the fleet
//! started), `TENDING_KILL_SEED` (default 0) the fleet's seed, `TENDING_KILL_CMD_TIMEOUT_S`
//! a `--cmd-vel-timeout` other than the fleet's default (measurements only); the figures go
//! to `$TENDING_FAULTS_REPORT` like the other fault tests'. The report also gives the gaps
//! between the surviving robots' cmd_vel arrivals at the bridge (what a command timeout
//! must stay above for a live robot never to be stopped).

mod common;
use common::*;

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use msgs::{DiagnosticArray, PoseStamped};

const SETUP: &str = "6.4_2";
const KILLED: &str = "robot_1";
/// `tending fleet`'s default command timeout (3 periods at 10 Hz) and stale timeout.
const CMD_TIMEOUT_S: f64 = 0.3;
const STALE_S: f64 = 2.0;
/// Ticks (at 10 Hz) the body may take to stop after the timeout, plus scheduling slack.
const STOP_SLACK_S: f64 = 0.4;
/// The farthest a robot at k_speed (0.5 m/s) rolls before it stands still:
/// k_speed x (`CMD_TIMEOUT_S` + `STOP_SLACK_S`).
const STOP_DISTANCE_M: f64 = 0.5 * (CMD_TIMEOUT_S + STOP_SLACK_S);

fn env_f64(key: &str, default: f64) -> f64 {
    std::env::var(key)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// `tending fleet` of 6.4_2 recording into `dir`; `kill robot_1` typed `kill_at` seconds
/// after the start; the fleet stops by itself 6 s later. Returns the kill's wall time (ns)
/// and the fleet's stdout; asserts a clean exit.
fn run_fleet(domain: u16, seed: u64, kill_at: f64, dir: &Path) -> (u64, String) {
    let mut cmd = Command::new(bin("tending"));
    cmd.args(["fleet", "--setup", SETUP, "--seed", &seed.to_string()]);
    if let Ok(t) = std::env::var("TENDING_KILL_CMD_TIMEOUT_S") {
        cmd.args(["--cmd-vel-timeout", &t]);
    }
    if secure() {
        cmd.arg("--secure")
            .arg("--keystore")
            .arg(fault_keystore().root());
    }
    let mut child = cmd
        .args(["--duration", &format!("{}", kill_at + 6.0)])
        .args(["--domain", &domain.to_string()])
        .arg("--record")
        .arg(dir)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let out = child.stdout.take().unwrap();
    let reader = std::thread::spawn(move || {
        BufReader::new(out)
            .lines()
            .map_while(Result::ok)
            .collect::<Vec<_>>()
    });
    std::thread::sleep(Duration::from_secs_f64(kill_at));
    let t_kill = wall_ns();
    writeln!(stdin, "kill {KILLED}").unwrap();
    stdin.flush().unwrap();
    let deadline = Instant::now() + Duration::from_secs(60);
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("fleet did not stop");
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    let text = reader.join().unwrap().join("\n");
    let mut err = String::new();
    let _ = std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err);
    assert!(status.success(), "fleet failed: {status}\n{text}\n{err}");
    assert!(text.contains(&format!("SIGKILL {KILLED}")), "{text}");
    (t_kill, text)
}

/// The scene's static geometry and the simulator's contact rule.
struct Scene {
    r: f64,
    cd: f64,
    half_room: f64,
    /// Centres and half extents of machines and storages.
    boxes: Vec<([f64; 2], [f64; 2], &'static str)>,
}

impl Scene {
    fn new(bag: &bag::BagReader, seed: u64) -> Self {
        let cfg = sim::ScenarioConfig::default();
        let env = sim::Env::new(cfg.clone(), SETUP.parse().unwrap(), seed).unwrap();
        let s = *env.sizes();
        let mut boxes = Vec::new();
        for tp in &bag.topics {
            let (half, kind) = if tp.name.starts_with("/machine_") {
                (s.machine_half, "machine")
            } else if tp.name.starts_with("/storage_") {
                (s.storage_half, "storage")
            } else {
                continue;
            };
            if !tp.name.ends_with("/pose") {
                continue;
            }
            let poses: Vec<(u64, PoseStamped)> = bag.decode_topic(&tp.name).unwrap();
            if let Some((_, p)) = poses.last() {
                let c = [p.pose.position.x, p.pose.position.y];
                boxes.push((c, [half[0] as f64, half[1] as f64], kind));
            }
        }
        Scene {
            r: s.robot_radius as f64,
            cd: cfg.task.collision_distance as f64,
            half_room: cfg.world.room_size as f64 / 2.0,
            boxes,
        }
    }

    /// Gap between a robot at `p` and the nearest body (peer, box or wall), m.
    fn clearance(&self, p: [f64; 2], peers: &[[f64; 2]]) -> f64 {
        let peers = peers
            .iter()
            .map(|q| (p[0] - q[0]).hypot(p[1] - q[1]) - 2.0 * self.r);
        let boxes = self.boxes.iter().map(|(c, h, _)| {
            let dx = (p[0] - c[0]).abs() - h[0];
            let dy = (p[1] - c[1]).abs() - h[1];
            dx.max(0.0).hypot(dy.max(0.0)) - self.r
        });
        let walls = p.iter().map(|v| self.half_room - v.abs() - self.r);
        peers
            .chain(boxes)
            .chain(walls)
            .fold(f64::INFINITY, f64::min)
    }

    /// Bodies a robot at `p` touches, by kind, with `peers` at the same step.
    fn contacts(&self, p: [f64; 2], peers: &[[f64; 2]]) -> Vec<&'static str> {
        let mut hit = Vec::new();
        for q in peers {
            if (p[0] - q[0]).hypot(p[1] - q[1]) <= 2.0 * self.r + self.cd {
                hit.push("robot");
            }
        }
        for (c, h, kind) in &self.boxes {
            let dx = (p[0] - c[0]).abs() - h[0];
            let dy = (p[1] - c[1]).abs() - h[1];
            // outside: Euclidean distance to the box; inside: negative
            let d = if dx > 0.0 || dy > 0.0 {
                dx.max(0.0).hypot(dy.max(0.0))
            } else {
                dx.max(dy)
            };
            if d - self.r <= self.cd {
                hit.push(kind);
            }
        }
        for v in p {
            if self.half_room - v.abs() - self.r <= self.cd {
                hit.push("wall");
            }
        }
        hit
    }
}

/// Stamp key (us) of a pose.
fn key(p: &PoseStamped) -> i64 {
    msgs::stamp::stamp_key_time(&p.header.stamp)
}

fn xy(p: &PoseStamped) -> [f64; 2] {
    [p.pose.position.x, p.pose.position.y]
}

/// The value of `key` in the last `/tending/metrics` sample logged at or before `t`.
fn metric_at(m: &[(u64, DiagnosticArray)], t: u64, key: &str) -> f64 {
    m.iter()
        .take_while(|(lt, _)| *lt <= t)
        .last()
        .and_then(|(_, d)| d.number(key))
        .unwrap_or(0.0)
}

/// Gaps (s) between consecutive cmd_vel arrivals at the bridge of the robots that were
/// not killed, once the simulator runs (their first 20 commands skipped): the largest,
/// and how many exceed 0.2, 0.3 and 0.5 s, of how many.
fn cmd_gaps(bag: &bag::BagReader) -> serde_json::Value {
    let mut gaps = Vec::new();
    for tp in bag.topics.iter().filter(|t| {
        t.name.starts_with("/robot_")
            && t.name.ends_with("/cmd_vel")
            && t.name != "/robot_1/cmd_vel"
    }) {
        let i = bag.topic_index(&tp.name).unwrap();
        let ts: Vec<u64> = bag
            .messages
            .iter()
            .filter(|m| m.topic_index == i)
            .map(|m| m.log_time)
            .skip(20)
            .collect();
        gaps.extend(ts.windows(2).map(|w| (w[1] - w[0]) as f64 / 1e9));
    }
    let over = |x: f64| gaps.iter().filter(|&&g| g > x).count();
    serde_json::json!({
        "n": gaps.len(), "max_s": gaps.iter().copied().fold(0.0, f64::max),
        "over_0.2": over(0.2), "over_0.3": over(0.3), "over_0.5": over(0.5),
    })
}

/// What one kill showed (see [`analyse`]).
struct Kill {
    /// Contact steps of the killed robot after its kill.
    contacts: usize,
    kinds: BTreeMap<&'static str, usize>,
    /// Gap to the nearest body at the kill, m.
    clearance_at_kill: f64,
    /// Distance it moved later than the command timeout plus a few ticks.
    moved_after_stop: f64,
    /// Its last pose, seconds after the kill.
    last_pose_s: f64,
    timeout: f64,
}

/// Every robot's position by step (stamp key), but the killed one's.
fn peers_by_step(bag: &bag::BagReader) -> BTreeMap<i64, Vec<[f64; 2]>> {
    let mut peers: BTreeMap<i64, Vec<[f64; 2]>> = BTreeMap::new();
    let mine = format!("/{KILLED}/pose");
    for tp in bag
        .topics
        .iter()
        .filter(|t| t.name.starts_with("/robot_") && t.name.ends_with("/pose") && t.name != mine)
    {
        for (_, p) in bag.decode_topic::<PoseStamped>(&tp.name).unwrap() {
            peers.entry(key(&p)).or_default().push(xy(&p));
        }
    }
    peers
}

/// The killed robot after its kill at `t_kill`, from the bag in `dir`: its contacts, how
/// far and how long it moved, when it was removed; printed and reported.
fn analyse(dir: &Path, seed: u64, kill_at: f64, t_kill: u64) -> Kill {
    let bag = bag::BagReader::open(dir).unwrap();
    assert!(bag.complete, "bag not finalized");
    let scene = Scene::new(&bag, seed);
    assert_eq!(scene.boxes.len(), 6, "machines and storages in the bag");
    let peers = peers_by_step(&bag);
    let mine: Vec<(u64, PoseStamped)> = bag.decode_topic(&format!("/{KILLED}/pose")).unwrap();
    let before: Vec<&(u64, PoseStamped)> = mine.iter().filter(|(t, _)| *t <= t_kill).collect();
    let after: Vec<&(u64, PoseStamped)> = mine.iter().filter(|(t, _)| *t > t_kill).collect();
    assert!(before.len() > 20, "{KILLED} had few poses before the kill");
    assert!(!after.is_empty(), "no pose of {KILLED} after the kill");
    let last_before = before.last().unwrap();
    let empty = Vec::new();
    let clearance_at_kill = scene.clearance(
        xy(&last_before.1),
        peers.get(&key(&last_before.1)).unwrap_or(&empty),
    );
    // its speed at the kill, over the last 5 steps
    let b5 = before[before.len().saturating_sub(6)];
    let speed_at_kill = {
        let (a, b) = (xy(&b5.1), xy(&last_before.1));
        let dt = (key(&last_before.1) - key(&b5.1)) as f64 / 1e6;
        (a[0] - b[0]).hypot(a[1] - b[1]) / dt.max(0.1)
    };
    let mut contacts = 0usize;
    let mut kinds: BTreeMap<&'static str, usize> = BTreeMap::new();
    let mut travelled = 0.0;
    let mut prev = xy(&last_before.1);
    for (_, p) in &after {
        let c = xy(p);
        travelled += (c[0] - prev[0]).hypot(c[1] - prev[1]);
        prev = c;
        for k in scene.contacts(c, peers.get(&key(p)).unwrap_or(&empty)) {
            contacts += 1;
            *kinds.entry(k).or_default() += 1;
        }
    }
    // still moving once the timeout and a few ticks have passed?
    let timeout = env_f64("TENDING_KILL_CMD_TIMEOUT_S", CMD_TIMEOUT_S);
    let settle = t_kill + ((timeout + STOP_SLACK_S) * 1e9) as u64;
    let settled: Vec<[f64; 2]> = after
        .iter()
        .filter(|(t, _)| *t >= settle)
        .map(|(_, p)| xy(p))
        .collect();
    let moved_after_stop = settled
        .windows(2)
        .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
        .sum::<f64>();
    let last_pose_s = (after.last().unwrap().0 as f64 - t_kill as f64) / 1e9;
    let gaps = cmd_gaps(&bag);
    let metrics: Vec<(u64, DiagnosticArray)> = bag.decode_topic("/tending/metrics").unwrap();
    let t_end = metrics.last().map(|m| m.0).unwrap_or(t_kill);
    let fleet_contacts_after =
        metric_at(&metrics, t_end, "collisions") - metric_at(&metrics, t_kill, "collisions");
    eprintln!(
        "{KILLED} killed {kill_at} s after the start (seed {seed}): speed at the kill {speed_at_kill:.2} m/s, \
         {clearance_at_kill:.3} m from the nearest body; \
         after the kill: {} steps, travelled {travelled:.3} m, {moved_after_stop:.3} m of it later than \
         {:.1} s, {contacts} contact steps {kinds:?}, last pose {last_pose_s:.2} s after the kill; \
         fleet contacts after the kill (metrics) {fleet_contacts_after}",
        after.len(),
        timeout + STOP_SLACK_S
    );
    report(serde_json::json!({
        "fault": "robot SIGKILLed in a realtime fleet",
        "setup": SETUP, "seed": seed, "kill_at_s": kill_at, "cmd_vel_timeout_s": timeout,
        "speed_at_kill": speed_at_kill, "clearance_at_kill_m": clearance_at_kill,
        "steps_after_kill": after.len(),
        "travelled_after_kill_m": travelled, "moved_after_stop_m": moved_after_stop,
        "killed_robot_contact_steps": contacts, "by_kind": kinds,
        "last_pose_after_kill_s": last_pose_s,
        "fleet_contacts_after_kill": fleet_contacts_after,
        "cmd_gaps_of_live_robots": gaps,
    }));
    Kill {
        contacts,
        kinds,
        clearance_at_kill,
        moved_after_stop,
        last_pose_s,
        timeout,
    }
}

/// One fleet run with `kill robot_1` at `kill_at` s; what the killed robot did after it,
/// and the fleet's stdout.
fn kill_once(domain: u16, seed: u64, kill_at: f64) -> (Kill, String) {
    let dir = std::env::temp_dir().join(format!("tending-kill-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let (t_kill, text) = run_fleet(domain, seed, kill_at, &dir);
    let k = analyse(&dir, seed, kill_at, t_kill);
    let _ = std::fs::remove_dir_all(&dir);
    (k, text)
}

/// A dead robot stops within the command timeout and a few ticks, is removed at the
/// stale timeout, and touches nothing meanwhile. No timeout guarantees the last for a
/// robot killed just before it reaches a body: it may roll up to k_speed x (timeout +
/// slack), `STOP_DISTANCE_M`, before it stands still. So a kill farther than that from
/// every body must touch nothing (a touch fails at once), while a kill within it that
/// touched is inconclusive and the kill is tried again later in a new run (at +3 and +6 s);
/// three inconclusive kills fail too. Every run must stop in time and be removed on time.
#[test]
fn a_killed_robot_stops_within_the_command_timeout_and_touches_nothing() {
    let kill_at = env_f64("TENDING_KILL_AT_S", 12.0);
    let seed = env_f64("TENDING_KILL_SEED", 0.0) as u64;
    let domain = test_domains::domain(0);
    let mut touched = Vec::new();
    for at in [kill_at, kill_at + 3.0, kill_at + 6.0] {
        let (k, text) = kill_once(domain, seed, at);
        let mut failures = Vec::new();
        if k.moved_after_stop > 0.005 {
            failures.push(format!(
                "{KILLED} moved {:.3} m later than {} s after its kill",
                k.moved_after_stop,
                k.timeout + STOP_SLACK_S
            ));
        }
        // removed at the staleness timeout, not earlier (plus a tick and scheduling slack)
        if !(STALE_S - 0.3..=STALE_S + 1.0).contains(&k.last_pose_s) {
            failures.push(format!(
                "{KILLED}: last pose {:.2} s after the kill (want ~{STALE_S} s)",
                k.last_pose_s
            ));
        }
        assert!(failures.is_empty(), "{}\n{text}", failures.join("\n"));
        if k.contacts == 0 {
            return;
        }
        let what = format!(
            "killed at {at} s, {:.3} m from the nearest body: {KILLED} touched {} bodies after \
             its kill: {:?}",
            k.clearance_at_kill, k.contacts, k.kinds
        );
        assert!(
            k.clearance_at_kill <= STOP_DISTANCE_M,
            "{what}, beyond its stopping distance {STOP_DISTANCE_M} m\n{text}"
        );
        eprintln!("{what}; within its stopping distance: inconclusive, again 3 s later");
        touched.push(what);
    }
    panic!(
        "every kill was within the stopping distance of a body and touched it:\n{}",
        touched.join("\n")
    );
}
