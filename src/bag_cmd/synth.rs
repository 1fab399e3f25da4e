//! `tending bag synth`: a scripted episode on the contract topics, written as a bag.

use super::*;

/// A scripted episode on the contract topics: robot i shuttles between machine i % M and
/// storage i % K, picking (has_part false -> true) at the machine and delivering (true ->
/// false) at the storage; /tending/metrics reports the same counts once per second.
pub(super) fn synth(
    dir: &std::path::Path,
    duration: f64,
    robots: usize,
    realtime: bool,
) -> Result<()> {
    let stop = if realtime {
        Some(ros::stop_flag()?)
    } else {
        None
    };
    let mut w = BagWriter::create(dir)?;
    let machines = [[-0.8f64, 0.8], [0.8, 0.8]];
    let storages = [[0.0f64, -0.9]];
    add_topics(&mut w, &machines, &storages, robots)?;
    let t0 = wall_ns();
    let start = Instant::now();
    let steps = (duration / 0.1).round() as u64;
    let leg = 15u64; // steps per leg
    let (mut picks, mut deliveries) = (0u64, 0u64);
    let mut step = 0;
    while step < steps {
        if let Some(s) = &stop {
            if s.load(Ordering::SeqCst) {
                break;
            }
            let due = start + Duration::from_millis(100 * step);
            let now = Instant::now();
            if due > now {
                std::thread::sleep(due - now);
            }
        }
        let t = if realtime {
            wall_ns()
        } else {
            t0 + step * 100_000_000
        };
        let stamp = Time::from_secs_f64(step as f64 * 0.1);
        w.write_msg(topics::CLOCK, t, &Clock { clock: stamp })?;
        if step == 0 {
            for (j, m) in machines.iter().enumerate() {
                let p = PoseStamped::planar(stamp, topics::FRAME_ID, m[0], m[1]);
                w.write_msg(&format!("/machine_{j}/pose"), t, &p)?;
            }
            for (k, s) in storages.iter().enumerate() {
                let p = PoseStamped::planar(stamp, topics::FRAME_ID, s[0], s[1]);
                w.write_msg(&format!("/storage_{k}/pose"), t, &p)?;
            }
        }
        let phase = step % (2 * leg);
        if step % 5 == 0 {
            for j in 0..machines.len() {
                w.write_msg(
                    &format!("/machine_{j}/part_ready"),
                    t,
                    &Bool { data: phase < leg },
                )?;
            }
        }
        for i in 0..robots {
            let m = machines[i % machines.len()];
            let s = storages[i % storages.len()];
            let carrying = phase >= leg; // picked at the machine, heading to storage
            let f = (phase % leg) as f64 / leg as f64;
            let (a, b) = if carrying { (m, s) } else { (s, m) };
            let x = a[0] + (b[0] - a[0]) * f;
            let y = a[1] + (b[1] - a[1]) * f + 0.05 * i as f64;
            w.write_msg(
                &format!("/robot_{i}/pose"),
                t,
                &PoseStamped::planar(stamp, topics::FRAME_ID, x, y),
            )?;
            w.write_msg(&format!("/robot_{i}/has_part"), t, &Bool { data: carrying })?;
            w.write_msg(
                &format!("/robot_{i}/cmd_vel"),
                t,
                &Twist::planar((b[0] - a[0]) / 1.5, (b[1] - a[1]) / 1.5),
            )?;
            if step > 0 && phase == leg {
                picks += 1;
            }
            if step > 0 && phase == 0 {
                deliveries += 1;
            }
        }
        if step % 10 == 0 {
            let d = metrics_msg(
                stamp,
                step,
                steps,
                machines.len(),
                robots,
                picks,
                deliveries,
            );
            w.write_msg(topics::METRICS, t, &d)?;
        }
        step += 1;
    }
    let n = w.message_count();
    w.finish()?;
    println!(
        "{} messages, {step} steps, {picks} picks, {deliveries} deliveries -> {}",
        n,
        dir.display()
    );
    Ok(())
}

/// The bag's topics: clock, metrics, each machine's pose and part_ready, each storage's
/// pose, and each robot's pose, has_part and cmd_vel, with the contract's QoS.
fn add_topics(
    w: &mut BagWriter,
    machines: &[[f64; 2]],
    storages: &[[f64; 2]],
    robots: usize,
) -> Result<()> {
    let rs = Profile::RobotStream.offered_qos_yaml();
    w.add_topic(
        topics::CLOCK,
        &schema::CLOCK,
        &Profile::Clock.offered_qos_yaml(),
    )?;
    w.add_topic(
        topics::METRICS,
        &schema::DIAGNOSTIC_ARRAY,
        &Profile::Visualization.offered_qos_yaml(),
    )?;
    for (j, _) in machines.iter().enumerate() {
        w.add_topic(
            &format!("/machine_{j}/pose"),
            &schema::POSE_STAMPED,
            &Profile::LatchedPose.offered_qos_yaml(),
        )?;
        w.add_topic(
            &format!("/machine_{j}/part_ready"),
            &schema::BOOL,
            &Profile::PartReady.offered_qos_yaml(),
        )?;
    }
    for (k, _) in storages.iter().enumerate() {
        w.add_topic(
            &format!("/storage_{k}/pose"),
            &schema::POSE_STAMPED,
            &Profile::LatchedPose.offered_qos_yaml(),
        )?;
    }
    for i in 0..robots {
        w.add_topic(&format!("/robot_{i}/pose"), &schema::POSE_STAMPED, &rs)?;
        w.add_topic(&format!("/robot_{i}/has_part"), &schema::BOOL, &rs)?;
        w.add_topic(&format!("/robot_{i}/cmd_vel"), &schema::TWIST, &rs)?;
    }
    Ok(())
}

/// The /tending/metrics message of step `step` (of `steps`): the pick and delivery counts
/// so far, utilization against `machines` parts per 2 s.
fn metrics_msg(
    stamp: Time,
    step: u64,
    steps: u64,
    machines: usize,
    robots: usize,
    picks: u64,
    deliveries: u64,
) -> DiagnosticArray {
    let kv = |k: &str, v: String| msgs::KeyValue {
        key: k.into(),
        value: v,
    };
    let p_max = (machines as u64 * steps / 20).max(1);
    DiagnosticArray {
        header: msgs::Header {
            stamp,
            frame_id: String::new(),
        },
        status: vec![msgs::DiagnosticStatus {
            level: msgs::DiagnosticStatus::OK,
            name: "tending/metrics".into(),
            message: String::new(),
            hardware_id: "synth".into(),
            values: vec![
                kv("parts_delivered", deliveries.to_string()),
                kv("parts_collected", picks.to_string()),
                kv("collisions", "0".into()),
                kv(
                    "machine_utilization",
                    format!("{:.4}", picks as f64 / p_max as f64),
                ),
                kv("p_max", p_max.to_string()),
                kv("robots", robots.to_string()),
                kv("step", step.to_string()),
            ],
        }],
    }
}
