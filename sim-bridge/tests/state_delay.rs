//! `-p test_state_delay_ms` (fault injection, bench/faults): the bridge publishes every
//! state message late, without slowing the simulation.
//!
//! Two realtime bridges side by side (own DDS domains): one with a 1500 ms state delay,
//! one without. This test subscribes to `/robot_0/pose` of each and, for every sample,
//! compares its arrival with the moment the bridge's stdout metrics line (every 0.1 s,
//! never delayed) first showed a `sim_time` at or past the sample's stamp. That stdout
//! line is printed after the step, so arrival minus it *underestimates* how long the
//! sample was held. Generous bounds, not timing assertions: the delayed bridge's median
//! must be at least half the delay, the undelayed one's below half of it; the delayed
//! bridge must keep stepping (its sim time advances like the other's) and its samples
//! arrive in stamp order.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use msgs::{PoseStamped, Profile, RosMessage};
use ros2_client::{Context, ContextOptions, Name, NodeName, NodeOptions, Subscription};

const DELAY_MS: f64 = 1500.0;
const RUN_S: f64 = 9.0;

struct Bridge {
    child: Child,
    /// (arrival, sim_time) of every stdout metrics line.
    lines: Arc<Mutex<Vec<(Instant, f64)>>>,
}

impl Drop for Bridge {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn spawn_bridge(domain: u16, delay_ms: f64) -> Bridge {
    let exe = PathBuf::from(env!("CARGO_BIN_EXE_sim_bridge"));
    let mut child = Command::new(exe)
        .env("ROS_DOMAIN_ID", domain.to_string())
        .args(["--ros-args", "-p", "setup:=2.2_1", "-p", "seed:=0"])
        .args(["-p", "startup_grace_s:=600", "-p", "metrics_period_s:=0.1"])
        // no robot nodes here: step without waiting for them
        .args(["-p", "wait_for_robots:=false"])
        .args(["-p", &format!("test_state_delay_ms:={delay_ms}")])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("starting sim_bridge");
    let out = child.stdout.take().unwrap();
    let lines = Arc::new(Mutex::new(Vec::new()));
    let l2 = lines.clone();
    std::thread::spawn(move || {
        for l in BufReader::new(out).lines().map_while(Result::ok) {
            let t = Instant::now();
            if let Ok(v) = serde_json::from_str::<serde_json::Value>(&l) {
                if let Some(s) = v["sim_time"].as_f64() {
                    l2.lock().unwrap().push((t, s));
                }
            }
        }
    });
    Bridge { child, lines }
}

fn pose_sub(ctx: &Context) -> (ros2_client::Node, Subscription<PoseStamped>) {
    let mut node = ctx
        .new_node(
            NodeName::new("/", "state_delay_probe").unwrap(),
            NodeOptions::new().enable_rosout(false),
        )
        .unwrap();
    let qos = Profile::RobotStream.qos();
    let t = node
        .create_topic(
            &Name::parse("/robot_0/pose").unwrap(),
            PoseStamped::type_name(),
            &qos,
        )
        .unwrap();
    let s = node.create_subscription(&t, Some(qos)).unwrap();
    (node, s)
}

/// `a - b` in seconds, either sign.
fn signed_s(a: Instant, b: Instant) -> f64 {
    a.saturating_duration_since(b).as_secs_f64() - b.saturating_duration_since(a).as_secs_f64()
}

struct Measured {
    samples: usize,
    /// Median of arrival minus the first stdout line at or past the stamp [s].
    median_lag_s: f64,
    in_order: bool,
    last_sim_time: f64,
}

fn measure(b: &Bridge, got: &[(Instant, f64)]) -> Measured {
    let lines = b.lines.lock().unwrap().clone();
    let mut lags: Vec<f64> = got
        .iter()
        .filter_map(|(r, s)| {
            lines
                .iter()
                .find(|(_, st)| *st >= s - 1e-6)
                .map(|(t, _)| signed_s(*r, *t))
        })
        .collect();
    lags.sort_by(|a, b| a.partial_cmp(b).unwrap());
    Measured {
        samples: got.len(),
        median_lag_s: lags.get(lags.len() / 2).copied().unwrap_or(f64::NAN),
        in_order: got.windows(2).all(|w| w[0].1 <= w[1].1),
        last_sim_time: lines.last().map(|l| l.1).unwrap_or(0.0),
    }
}

#[test]
fn state_delay_holds_every_state_message_without_stopping_the_simulation() {
    let (d_delay, d_clean) = (test_domains::domain(0), test_domains::domain(1));
    let delayed = spawn_bridge(d_delay, DELAY_MS);
    let clean = spawn_bridge(d_clean, 0.0);
    let ctx_d = Context::with_options(ContextOptions::new().domain_id(d_delay)).unwrap();
    let ctx_c = Context::with_options(ContextOptions::new().domain_id(d_clean)).unwrap();
    let (_nd, sub_d) = pose_sub(&ctx_d);
    let (_nc, sub_c) = pose_sub(&ctx_c);
    let mut got_d: Vec<(Instant, f64)> = Vec::new();
    let mut got_c: Vec<(Instant, f64)> = Vec::new();
    let t0 = Instant::now();
    while t0.elapsed().as_secs_f64() < RUN_S {
        for (sub, got) in [(&sub_d, &mut got_d), (&sub_c, &mut got_c)] {
            while let Ok(Some((p, _))) = sub.take() {
                let s = p.header.stamp.sec as f64 + p.header.stamp.nanosec as f64 * 1e-9;
                got.push((Instant::now(), s));
            }
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let md = measure(&delayed, &got_d);
    let mc = measure(&clean, &got_c);
    eprintln!(
        "delayed {DELAY_MS} ms: {} samples, median lag >= {:.3} s, last sim time {:.1} s; \
         undelayed: {} samples, median lag >= {:.3} s, last sim time {:.1} s",
        md.samples,
        md.median_lag_s,
        md.last_sim_time,
        mc.samples,
        mc.median_lag_s,
        mc.last_sim_time
    );
    assert!(
        mc.samples >= 10 && md.samples >= 10,
        "too few poses received: delayed {}, undelayed {}",
        md.samples,
        mc.samples
    );
    assert!(
        md.median_lag_s >= DELAY_MS / 2000.0,
        "delayed bridge: median lag {:.3} s, want >= {:.3} s",
        md.median_lag_s,
        DELAY_MS / 2000.0
    );
    assert!(
        mc.median_lag_s < DELAY_MS / 2000.0,
        "undelayed bridge: median lag {:.3} s, want < {:.3} s",
        mc.median_lag_s,
        DELAY_MS / 2000.0
    );
    assert!(md.in_order, "delayed samples out of stamp order");
    // the hold does not block the step loop: both simulations advanced alike
    assert!(
        md.last_sim_time >= 0.5 * mc.last_sim_time && md.last_sim_time > 2.0,
        "delayed bridge sim time {:.1} s vs undelayed {:.1} s",
        md.last_sim_time,
        mc.last_sim_time
    );
}
