//! Write a small synthetic bag of contract messages: `synthetic_bag <dir> [steps]`.
//! Used by tests/bags (Python readers) and handy to look at in Foxglove.

use bag::BagWriter;
use msgs::{schema, Bool, Clock, PoseStamped, Profile, Time, Twist};

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let dir = args
        .next()
        .ok_or_else(|| anyhow::anyhow!("usage: synthetic_bag <dir> [steps]"))?;
    let steps: u64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(20);
    let mut w = BagWriter::create(&dir)?;
    let t0: u64 = 1_700_000_000_000_000_000;
    w.add_topic("/clock", &schema::CLOCK, &Profile::Clock.offered_qos_yaml())?;
    w.add_topic(
        "/robot_0/pose",
        &schema::POSE_STAMPED,
        &Profile::RobotStream.offered_qos_yaml(),
    )?;
    w.add_topic(
        "/robot_0/has_part",
        &schema::BOOL,
        &Profile::RobotStream.offered_qos_yaml(),
    )?;
    w.add_topic(
        "/robot_0/cmd_vel",
        &schema::TWIST,
        &Profile::RobotStream.offered_qos_yaml(),
    )?;
    for k in 0..steps {
        let t = t0 + k * 100_000_000;
        let stamp = Time::from_secs_f64(k as f64 * 0.1);
        w.write_msg("/clock", t, &Clock { clock: stamp })?;
        w.write_msg(
            "/robot_0/pose",
            t,
            &PoseStamped::planar(stamp, "map", k as f64 * 0.25, -0.5),
        )?;
        w.write_msg("/robot_0/has_part", t, &Bool { data: k % 2 == 1 })?;
        w.write_msg("/robot_0/cmd_vel", t, &Twist::planar(0.5, -(k as f64)))?;
    }
    let m = w.finish()?;
    println!("{} messages", m.message_count);
    Ok(())
}
