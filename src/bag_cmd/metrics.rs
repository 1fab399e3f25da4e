//! `tending bag metrics`: prints what `bag::metrics` finds in a bag, bin by bin and in total.

use super::*;

pub(super) fn metrics(path: &std::path::Path, period: f64) -> Result<()> {
    let r = BagReader::open(path)?;
    if !r.complete {
        eprintln!(
            "warning: {} is not complete ({}); using what is readable",
            r.path.display(),
            r.stopped_early.as_deref().unwrap_or("?")
        );
    }
    let m = bag::metrics(&r, period)?;
    print_metrics_table(&r.path, &m);
    print_metrics_totals(&m);
    Ok(())
}

/// The bins: from has_part (and poses), next to /tending/metrics when recorded.
pub(super) fn print_metrics_table(path: &std::path::Path, m: &bag::BagMetrics) {
    let has_metrics = m.has_metrics;
    println!(
        "bag {}: {:.1} s, {} robots seen (pose/has_part topics){}",
        path.display(),
        m.duration_s,
        m.robots_seen,
        if has_metrics {
            ", /tending/metrics recorded"
        } else {
            ", no /tending/metrics"
        }
    );
    println!(
        "from has_part: delivered = true->false transitions, picks = false->true; robots = pose topics with data in the row's period"
    );
    print!(
        "{:>8} {:>6} {:>6} {:>10}",
        "t [s]", "robots", "picks", "delivered"
    );
    if has_metrics {
        print!(
            " | {:>14} {:>10} {:>7} {:>7}",
            "rep. delivered", "collisions", "MU", "robots"
        );
    }
    println!();
    for row in &m.rows {
        print!(
            "{:>8.1} {:>6} {:>6} {:>10}",
            row.t, row.robots_alive, row.picks, row.deliveries
        );
        if has_metrics {
            print!(
                " | {:>14} {:>10} {:>7} {:>7}",
                get(&row.reported, "parts_delivered"),
                get(&row.reported, "collisions"),
                get(&row.reported, "machine_utilization"),
                get(&row.reported, "robots"),
            );
        }
        println!();
    }
    println!();
}

pub(super) fn get(m: &BTreeMap<String, String>, k: &str) -> String {
    m.get(k).cloned().unwrap_or("-".into())
}

/// The episode's totals, and where has_part and /tending/metrics disagree.
pub(super) fn print_metrics_totals(m: &bag::BagMetrics) {
    let last = m.last();
    let last_reported = &last.reported;
    let p_max: Option<f64> = last_reported.get("p_max").and_then(|v| v.parse().ok());
    println!(
        "total from has_part: {} delivered, {} picked{}",
        last.deliveries,
        last.picks,
        match p_max {
            Some(p) if p > 0.0 => format!(
                ", MU = picks / p_max = {} / {} = {:.3}",
                last.picks,
                p,
                last.picks as f64 / p
            ),
            _ => ", MU n/a (no p_max recorded)".into(),
        }
    );
    if m.has_metrics {
        println!(
            "total from /tending/metrics: {} delivered, {} collected, {} collisions, MU {}",
            get(last_reported, "parts_delivered"),
            get(last_reported, "parts_collected"),
            get(last_reported, "collisions"),
            get(last_reported, "machine_utilization")
        );
        // bridges before the per-kind counts recorded only the total
        if last_reported.contains_key("collisions_robot_robot") {
            println!(
                "collisions by kind from /tending/metrics: robot-robot {}, robot-machine {}, robot-storage {}, robot-wall {}",
                get(last_reported, "collisions_robot_robot"),
                get(last_reported, "collisions_robot_machine"),
                get(last_reported, "collisions_robot_storage"),
                get(last_reported, "collisions_robot_wall")
            );
        } else {
            println!("collisions by kind: n/a (recorded by a bridge that reported only totals)");
        }
        // bridges before issue 47 did not count collision events
        if last_reported.contains_key("collision_events") {
            println!(
                "collision events from /tending/metrics: {}",
                get(last_reported, "collision_events")
            );
        }
        if let Some(rep) = last_reported
            .get("parts_delivered")
            .and_then(|v| v.parse::<u64>().ok())
        {
            if rep != last.deliveries {
                println!(
                    "note: has_part transitions give {} deliveries, /tending/metrics {} (a robot despawned while carrying, or a recording that started mid-episode)",
                    last.deliveries, rep
                );
            }
        }
    } else {
        println!("collisions: n/a (only /tending/metrics carries them)");
    }
}
