//! `tending bag play`: every message republished with its topic's original QoS and timing.

use super::*;

pub(super) type SendFn = Box<dyn Fn(&[u8]) -> Result<()>>;

pub(super) fn player<M: RosMessage + std::fmt::Debug>(
    node: &mut Node,
    name: &str,
    qos: QosProfile,
) -> Result<SendFn> {
    let p: Publisher<M> = ros::publisher_qos(node, name, qos)?;
    let name = name.to_string();
    Ok(Box::new(move |data: &[u8]| {
        let m: M = msgs::cdr::decode(data).map_err(|e| anyhow!("{name}: {e}"))?;
        p.publish(m).map_err(|e| anyhow!("publish {name}: {e:?}"))
    }))
}

pub(super) fn player_for(
    node: &mut Node,
    name: &str,
    type_name: &str,
    qos: QosProfile,
) -> Result<SendFn> {
    match type_name {
        "geometry_msgs/msg/PoseStamped" => player::<PoseStamped>(node, name, qos),
        "std_msgs/msg/Bool" => player::<Bool>(node, name, qos),
        "geometry_msgs/msg/Twist" => player::<Twist>(node, name, qos),
        "rosgraph_msgs/msg/Clock" => player::<Clock>(node, name, qos),
        "visualization_msgs/msg/MarkerArray" => player::<MarkerArray>(node, name, qos),
        "diagnostic_msgs/msg/DiagnosticArray" => player::<DiagnosticArray>(node, name, qos),
        "std_msgs/msg/String" => player::<StdString>(node, name, qos),
        other => bail!("no player for type {other}"),
    }
}

pub(super) fn play(
    path: &std::path::Path,
    rate: f64,
    domain_id: Option<u16>,
    wait: f64,
    enclave: &str,
) -> Result<()> {
    anyhow::ensure!(rate > 0.0, "--rate must be positive");
    let r = BagReader::open(path)?;
    let stop = ros::stop_flag()?;
    let mut ros = ros_node(domain(domain_id), "tending_play", enclave)?;
    let mut pubs: Vec<Option<SendFn>> = Vec::new();
    for t in &r.topics {
        let qos = if t.qos_yaml.is_empty() {
            msgs::qos::robot_stream()
        } else {
            qos_from_yaml(&t.qos_yaml)
        };
        match player_for(ros.node(), &t.name, &t.type_name, qos) {
            Ok(p) => pubs.push(Some(p)),
            Err(e) => {
                eprintln!("skipping {}: {e:#}", t.name);
                pubs.push(None);
            }
        }
    }
    std::thread::sleep(Duration::from_secs_f64(wait.max(0.0)));
    let mut order: Vec<&bag::BagMessage> = r.messages.iter().collect();
    order.sort_by_key(|m| m.log_time);
    let Some(t0) = order.first().map(|m| m.log_time) else {
        println!("no messages");
        return Ok(());
    };
    let start = Instant::now();
    let (mut sent, mut failed) = (0u64, 0u64);
    for m in order {
        if stop.load(Ordering::SeqCst) {
            break;
        }
        let due = start + Duration::from_secs_f64(secs(m.log_time - t0) / rate);
        let now = Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
        if let Some(p) = &pubs[m.topic_index] {
            match p(&m.data) {
                Ok(()) => sent += 1,
                Err(e) => {
                    failed += 1;
                    if failed <= 5 {
                        eprintln!("{e:#}");
                    }
                }
            }
        }
    }
    // Let reliable writers deliver the tail before the participant goes away.
    std::thread::sleep(Duration::from_millis(500));
    drop(ros);
    println!(
        "played {sent} messages ({failed} failed) in {:.1} s",
        start.elapsed().as_secs_f64()
    );
    Ok(())
}
