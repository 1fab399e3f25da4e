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
    let domain = (std::process::id() % 50) as u16 + 150;
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

#[test]
fn lockstep_fleet_ends_at_the_requested_sim_time() {
    let domain = (std::process::id() % 50) as u16 + 100;
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
