//! Where robot-robot contacts happen: for every touching pair at the end of a step, what
//! the two robots were doing (carrying or not, speed, how far from the nearest storage and
//! machine, in robot radii). Argmax, through the ORCA planner and filter, by `tending
//! eval`'s own episode runner.
//!
//! cargo run --release -p learn --example contact_sites -- CHECKPOINT|greedy-orca SETUP [EPISODES] [SEED]

use learn::eval::{run_episode_watched, Method};
use sim::{ScenarioConfig, Setup};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(ck), Some(setup)) = (args.first(), args.get(1)) else {
        return Err("usage: contact_sites CHECKPOINT|greedy-orca SETUP [EPISODES] [SEED]".into());
    };
    let setup: Setup = setup.parse().map_err(|e| format!("SETUP {setup}: {e}"))?;
    let episodes: u64 = args.get(2).map_or(Ok(20), |s| s.parse())?;
    let seed: u64 = args.get(3).map_or(Ok(7), |s| s.parse())?;
    let ctrl = Method::script_or_filtered_checkpoint(ck)?;
    let cfg = ScenarioConfig::default();
    let touch = cfg.task.collision_distance;
    let mut prev_vel: Vec<[f32; 2]> = vec![];
    for ep in 0..episodes {
        run_episode_watched(&ctrl, &cfg, setup, seed, ep, |env| {
            let r = env.sizes().robot_radius;
            let robots: Vec<_> = env.robots().collect();
            let st: Vec<_> = env.storages().collect();
            let ma: Vec<_> = env.machines().collect();
            let gap = |p: [f32; 2], c: [f32; 2], h: [f32; 2]| {
                let dx = ((p[0] - c[0]).abs() - h[0]).max(0.0);
                let dy = ((p[1] - c[1]).abs() - h[1]).max(0.0);
                (dx * dx + dy * dy).sqrt()
            };
            for i in 0..robots.len() {
                for j in i + 1..robots.len() {
                    let (a, b) = (robots[i], robots[j]);
                    let d = ((a.pos[0] - b.pos[0]).powi(2) + (a.pos[1] - b.pos[1]).powi(2)).sqrt();
                    if d - 2.0 * r > touch {
                        continue;
                    }
                    let mid = [(a.pos[0] + b.pos[0]) / 2.0, (a.pos[1] + b.pos[1]) / 2.0];
                    let ds = st
                        .iter()
                        .map(|s| gap(mid, s.centre, s.half))
                        .fold(f32::INFINITY, f32::min);
                    let dm = ma
                        .iter()
                        .map(|m| gap(mid, m.centre, m.half))
                        .fold(f32::INFINITY, f32::min);
                    let sp = |v: [f32; 2]| (v[0] * v[0] + v[1] * v[1]).sqrt();
                    let pv = |k: usize| prev_vel.get(k).map_or(f32::NAN, |&v| sp(v));
                    println!(
                        "ep {ep} step {} pair {i}-{j} gap_mm {:.1} parts {}{} speed {:.2}/{:.2} prev {:.2}/{:.2} storage_r {:.1} machine_r {:.1}",
                        env.steps(),
                        (d - 2.0 * r) * 1000.0,
                        u8::from(a.has_part),
                        u8::from(b.has_part),
                        sp(a.vel),
                        sp(b.vel),
                        pv(i),
                        pv(j),
                        ds / r,
                        dm / r
                    );
                }
            }
            prev_vel = robots.iter().map(|x| x.vel).collect();
        })?;
    }
    Ok(())
}
