//! How often a robot carrying a part stands still away from every storage: a carrier
//! should be driving or placing, so a long stop there is a robot stuck against a box (or
//! behind other robots). Counts episodes with a spell of at least `MIN_STEPS` steps within
//! `RADIUS_M` of one spot, and the carrier-steps past `MIN_STEPS` of those spells farther
//! than `AWAY_RADII` robot radii from every storage box (queues at a storage excluded).
//! Used for the planner's detour (plan::detour, docs/RESULTS.md 7.10).
//!
//! cargo run --release -p learn --example stuck_carriers -- CHECKPOINT|greedy-orca SETUPS [EPISODES] [SEED]
//! (`STUCK_VERBOSE=1`: print each stop's episode, robot, first step and position)

use learn::eval::{run_episode_hooked, Method};
use sim::{ScenarioConfig, Setup};

const MIN_STEPS: u32 = 40;
const RADIUS_M: f32 = 0.02;
const AWAY_RADII: f32 = 6.0;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(ck), Some(setups)) = (args.first(), args.get(1)) else {
        return Err("usage: stuck_carriers CHECKPOINT|greedy-orca SETUPS [EPISODES] [SEED]".into());
    };
    let episodes: u64 = args.get(2).map_or(Ok(50), |s| s.parse())?;
    let seed: u64 = args.get(3).map_or(Ok(0), |s| s.parse())?;
    // STUCK_VERBOSE=1: where and when each stop began
    let verbose = std::env::var_os("STUCK_VERBOSE").is_some();
    let ctrl = Method::script_or_filtered_checkpoint(ck)?;
    let cfg = ScenarioConfig::default();
    for s in setups.split(',') {
        let setup: Setup = s.parse().map_err(|e| format!("SETUPS {s}: {e}"))?;
        let (mut stuck_episodes, mut stuck_steps, mut parts) = (0, 0u64, 0u64);
        for ep in 0..episodes {
            // per robot: where the current spell began and how long it has lasted
            let mut spell: Vec<([f32; 2], u32)> = Vec::new();
            let mut longest = 0u32;
            let m = run_episode_hooked(
                &ctrl,
                &cfg,
                setup,
                seed,
                ep,
                |env| {
                    let radius = env.sizes().robot_radius;
                    let storages: Vec<_> = env.storages().map(|s| (s.centre, s.half)).collect();
                    let robots: Vec<_> = env.robots().collect();
                    if spell.len() != robots.len() {
                        spell = robots.iter().map(|r| (r.pos, 0)).collect();
                    }
                    for (i, r) in robots.iter().enumerate() {
                        let (at, n) = spell[i];
                        let moved =
                            ((r.pos[0] - at[0]).powi(2) + (r.pos[1] - at[1]).powi(2)).sqrt();
                        if !r.has_part || moved >= RADIUS_M {
                            spell[i] = (r.pos, 0);
                            continue;
                        }
                        spell[i].1 = n + 1;
                        longest = longest.max(n + 1);
                        let to_storage = storages
                            .iter()
                            .map(|&(c, h)| plan::geom::box_distance(c, h, r.pos))
                            .fold(f32::INFINITY, f32::min);
                        if n + 1 >= MIN_STEPS && to_storage > AWAY_RADII * radius {
                            stuck_steps += 1;
                            if n + 1 == MIN_STEPS && verbose {
                                println!(
                                    "  episode {ep}: robot {i} still since step {} at ({:.3}, {:.3})",
                                    env.steps() - MIN_STEPS,
                                    r.pos[0],
                                    r.pos[1]
                                );
                                if std::env::var_os("STUCK_SCENE").is_some() {
                                    for q in &robots {
                                        println!(
                                            "    robot at ({:.3}, {:.3}) part {}",
                                            q.pos[0], q.pos[1], q.has_part
                                        );
                                    }
                                    for m in env.machines() {
                                        println!("    machine at ({:.3}, {:.3}) half ({:.3}, {:.3}) ready {}", m.centre[0], m.centre[1], m.half[0], m.half[1], m.part_ready);
                                    }
                                    for (c, h) in &storages {
                                        println!(
                                            "    storage at ({:.3}, {:.3}) half ({:.3}, {:.3})",
                                            c[0], c[1], h[0], h[1]
                                        );
                                    }
                                }
                            }
                        }
                    }
                },
                |_, _| {},
            )?;
            parts += m.parts_delivered as u64;
            if longest >= MIN_STEPS {
                stuck_episodes += 1;
            }
        }
        println!(
            "{s} ({episodes} episodes, seed {seed}): parts {:.1}; episodes with a carrier still \
             for {MIN_STEPS}+ steps: {stuck_episodes}; carrier-steps past {MIN_STEPS} away from storages: {stuck_steps}",
            parts as f64 / episodes as f64
        );
    }
    Ok(())
}
