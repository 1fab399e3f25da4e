//! `tending record`: every contract topic found by discovery into a bag, until Ctrl-C /
//! SIGTERM or `--duration`; the typed readers it records with.

use super::*;

pub(super) fn domain(d: Option<u16>) -> u16 {
    d.or_else(|| std::env::var("ROS_DOMAIN_ID").ok()?.parse().ok())
        .unwrap_or(0)
}

/// The CLI's own node (no rosout), spinning so that topic discovery works.
pub(super) fn ros_node(domain_id: u16, name: &str, enclave: &str) -> Result<ros::RosNode> {
    let spec = ros::NodeSpec {
        namespace: "/",
        name,
        enable_rosout: false,
    };
    ros::RosNode::start(
        &ros::context(domain_id, Some(enclave))?,
        &spec,
        "ros2-spinner",
    )
}

pub(super) type Drain = Box<dyn FnMut(&mut BagWriter) -> Result<usize>>;

pub(super) fn wall_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

pub(super) fn recorder<M: RosMessage>(
    node: &mut Node,
    name: &str,
    qos: QosProfile,
) -> Result<Drain> {
    let sub: Subscription<M> = ros::subscription_qos(node, name, qos)?;
    let name = name.to_string();
    Ok(Box::new(move |w: &mut BagWriter| {
        let mut n = 0;
        loop {
            match sub.take() {
                Ok(Some((m, info))) => {
                    let now = wall_ns();
                    let publish = info
                        .source_timestamp()
                        .map(|t| t.to_nanos().max(0) as u64)
                        .unwrap_or(now);
                    let bytes = msgs::cdr::encode(&m).map_err(|e| anyhow!("{name}: {e}"))?;
                    w.write_full(&name, now, publish, &bytes)?;
                    n += 1;
                }
                Ok(None) => break,
                Err(e) => {
                    eprintln!("{name}: dropped an undecodable sample: {e:?}");
                    break;
                }
            }
        }
        Ok(n)
    }))
}

pub(super) fn recorder_for(
    node: &mut Node,
    name: &str,
    def: &MsgDef,
    qos: QosProfile,
) -> Result<Drain> {
    match def.full_name().as_str() {
        "geometry_msgs/msg/PoseStamped" => recorder::<PoseStamped>(node, name, qos),
        "std_msgs/msg/Bool" => recorder::<Bool>(node, name, qos),
        "geometry_msgs/msg/Twist" => recorder::<Twist>(node, name, qos),
        "rosgraph_msgs/msg/Clock" => recorder::<Clock>(node, name, qos),
        "visualization_msgs/msg/MarkerArray" => recorder::<MarkerArray>(node, name, qos),
        "diagnostic_msgs/msg/DiagnosticArray" => recorder::<DiagnosticArray>(node, name, qos),
        "std_msgs/msg/String" => recorder::<StdString>(node, name, qos),
        other => bail!("{name}: no recorder for type {other}"),
    }
}

pub fn record(a: RecordArgs) -> Result<()> {
    let stop = ros::stop_flag()?;
    let mut ros = ros_node(domain(a.domain_id), "tending_record", &a.enclave)?;
    let mut w = BagWriter::create(&a.dir)?;
    let start = Instant::now();
    let deadline = a
        .duration
        .map(|d| start + Duration::from_secs_f64(d.max(0.0)));
    let period = Duration::from_secs_f64(a.discovery_period.max(0.05));
    let mut next_discovery = start;
    let mut drains: Vec<(String, Drain)> = Vec::new();
    let mut refused = std::collections::HashSet::new();
    eprintln!(
        "recording contract topics into {} (Ctrl-C / SIGTERM to stop)",
        a.dir.display()
    );
    let result = (|| -> Result<()> {
        while !stop.load(Ordering::SeqCst) && deadline.is_none_or(|d| Instant::now() < d) {
            if Instant::now() >= next_discovery {
                next_discovery = Instant::now() + period;
                for d in ros.context().discovered_topics() {
                    let Some((name, def, profile)) = bag::contract_topic(&d.name) else {
                        continue;
                    };
                    if w.has_topic(&name) || refused.contains(&name) {
                        continue;
                    }
                    // ros2-client's spinner reads /clock as builtin_interfaces/Time, so
                    // that type shows up for /clock in every ros2-client graph: record
                    // /clock as the contract's rosgraph_msgs/Clock regardless.
                    let clock_artifact = name == topics::CLOCK
                        && d.type_name == "builtin_interfaces::msg::dds_::Time_";
                    if d.type_name != def.dds_name() && !clock_artifact {
                        eprintln!(
                            "not recording {name}: type {} is not the contract's {}",
                            d.type_name,
                            def.dds_name()
                        );
                        refused.insert(name);
                        continue;
                    }
                    let drain = recorder_for(ros.node(), &name, def, profile.qos())?;
                    w.add_topic(&name, def, &profile.offered_qos_yaml())?;
                    eprintln!("recording {name} ({})", def.full_name());
                    drains.push((name, drain));
                }
            }
            let mut got = 0;
            for (_, d) in drains.iter_mut() {
                got += d(&mut w)?;
            }
            w.flush_due()?;
            if got == 0 {
                std::thread::sleep(Duration::from_millis(2));
            }
        }
        for (_, d) in drains.iter_mut() {
            d(&mut w)?;
        }
        Ok(())
    })();
    let n = w.message_count();
    let meta = w.finish()?;
    drop(ros);
    eprintln!(
        "bag {}: {} messages on {} topics, {:.1} s",
        a.dir.display(),
        n,
        meta.topics.len(),
        meta.time_range.map(|(a, b)| secs(b - a)).unwrap_or(0.0)
    );
    result
}
