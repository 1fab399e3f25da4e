//! `tending bag render`: GIF/SVG/PNG frames of the poses and part_ready flags.

use super::*;

pub(super) fn render(
    path: &std::path::Path,
    out: &std::path::Path,
    frame_period: f64,
) -> Result<()> {
    anyhow::ensure!(frame_period > 0.0, "--frame-period must be positive");
    let r = BagReader::open(path)?;
    let Some((t0, t1)) = r.time_range() else {
        bail!("{} holds no messages", r.path.display());
    };
    // Sizes from the first MarkerArray if recorded, else the default scenario's base sizes.
    let mut robot_radius = 0.05f32;
    let mut machine_half = [0.1f32, 0.1];
    let mut storage_half = [0.1f32, 0.1];
    if let Some((_, ma)) = r
        .decode_topic::<MarkerArray>(topics::MARKERS)
        .unwrap_or_default()
        .into_iter()
        .next()
    {
        for m in &ma.markers {
            let half = [m.scale.x as f32 / 2.0, m.scale.y as f32 / 2.0];
            match m.ns.as_str() {
                "robots" => robot_radius = half[0],
                "machines" => machine_half = half,
                "storages" => storage_half = half,
                _ => {}
            }
        }
    }
    #[derive(Default)]
    struct State {
        pos: Option<([f32; 2], u64)>,
        flag: bool,
    }
    let mut robots: BTreeMap<String, State> = BTreeMap::new();
    let mut machines: BTreeMap<u32, State> = BTreeMap::new();
    let mut storages: BTreeMap<u32, State> = BTreeMap::new();
    let mut frames = Vec::new();
    let period_ns = (frame_period * 1e9) as u64;
    let stale_ns = 1_000_000_000u64.max(2 * period_ns);
    let mut next = t0;
    let mut delivered = 0u32;
    let mut idx = 0;
    let mut msgs_sorted: Vec<&bag::BagMessage> = r.messages.iter().collect();
    msgs_sorted.sort_by_key(|m| m.log_time);
    let parsed: Vec<Option<topics::EntityTopic>> = r
        .topics
        .iter()
        .map(|t| topics::parse_topic(&t.name))
        .collect();
    while next <= t1 {
        while idx < msgs_sorted.len() && msgs_sorted[idx].log_time <= next {
            let m = msgs_sorted[idx];
            idx += 1;
            let Some(et) = &parsed[m.topic_index] else {
                continue;
            };
            let st = match &et.entity {
                Entity::Robot(n) => robots.entry(n.clone()).or_default(),
                Entity::Machine(j) => machines.entry(*j).or_default(),
                Entity::Storage(k) => storages.entry(*k).or_default(),
            };
            match et.leaf {
                Leaf::Pose => {
                    if let Ok(p) = msgs::cdr::decode::<PoseStamped>(&m.data) {
                        let q = p.pose.position;
                        st.pos = Some(([q.x as f32, q.y as f32], m.log_time));
                    }
                }
                Leaf::HasPart | Leaf::PartReady => {
                    if let Ok(b) = msgs::cdr::decode::<Bool>(&m.data) {
                        if et.leaf == Leaf::HasPart && st.flag && !b.data {
                            delivered += 1;
                        }
                        st.flag = b.data;
                    }
                }
                Leaf::CmdVel => {}
            }
        }
        let live = |s: &State| s.pos.filter(|(_, t)| next.saturating_sub(*t) <= stale_ns);
        frames.push(plots::episode::Frame {
            robots: robots
                .values()
                .filter_map(|s| live(s).map(|(p, _)| (p, s.flag)))
                .collect(),
            // machines and storages are latched: no staleness
            machines: machines
                .values()
                .filter_map(|s| s.pos.map(|(p, _)| (p, machine_half, s.flag)))
                .collect(),
            storages: storages
                .values()
                .filter_map(|s| s.pos.map(|(p, _)| (p, storage_half)))
                .collect(),
            robot_radius,
            step: frames.len() as u32,
            delivered,
        });
        next += period_ns;
    }
    let mut cfg = sim::ScenarioConfig::default();
    cfg.world.dt = frame_period as f32;
    plots::episode::write(out, &cfg, &frames)?;
    println!(
        "{} frames ({:.1} s of bag time, {} robots, {} machines, {} storages) -> {}",
        frames.len(),
        secs(t1 - t0),
        robots.len(),
        machines.len(),
        storages.len(),
        out.display()
    );
    Ok(())
}
