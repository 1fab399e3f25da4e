//! Per-robot decision time against fleet size, on one core (issue 46, docs/bench/scale.md).
//!
//! cargo run --release -p learn --example decision_time -- [SETUPS] [STEPS] [BOUNDS]
//!
//! For every setup on the grown floor (docs/adr/0037), every method and every observation
//! bound ("all" or K nearest), one episode of STEPS steps, single-threaded: the time to
//! decide (observation + network + planner + filter, everything a robot computes) per
//! robot per step, and the physics apart. Prints a Markdown table; progress on stderr.
//! Run with RAYON_NUM_THREADS=1 so that "one core" holds. Each episode runs REPEAT times
//! (default 3) and the fastest run is reported: on a shared machine the minimum is the
//! figure least disturbed by other load.

use learn::{run_episode_timed, Method};
use policy::Policy;
use sim::{Floor, ScenarioConfig, Setup};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let setups = args
        .first()
        .map_or("100.66_33,300.200_100,1000.666_333", String::as_str);
    let steps: u32 = args.get(1).map_or(Ok(10), |s| s.parse())?;
    let bounds = args.get(2).map_or("all,8", String::as_str);
    let repeat: usize = std::env::var("REPEAT").map_or(Ok(3), |s| s.parse())?;
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../policy/pretrained");
    let moves = Policy::load(format!("{root}/smappo_moves_6.4_2.safetensors"))?;
    let shipped = Policy::load(format!("{root}/smappo_6.4_2.safetensors"))?;
    let methods: Vec<(&str, Method)> = vec![
        ("greedy-orca", Method::greedy_orca()),
        ("matching-orca", Method::matching_orca()),
        (
            "smappo 5 moves (paper)",
            Method::learned(Box::new(moves.actor().clone()), false),
        ),
        (
            "smappo targets (shipped)",
            Method::filtered(Box::new(shipped.actor().clone()), false),
        ),
    ];
    println!("| setup | room (m) | observation | method | us per robot-decision | physics ms per step | parts | contacts |");
    println!("|---|---|---|---|---|---|---|---|");
    for s in setups.split(',') {
        let setup: Setup = s.parse()?;
        for b in bounds.split(',') {
            let mut cfg = ScenarioConfig::default();
            cfg.world.floor = Floor::Grown;
            cfg.world.episode_steps = steps;
            if b != "all" {
                cfg.observation = obs::Bound::nearest(b.parse()?);
            }
            let room = sim::layout::room_for(setup, &cfg);
            for (name, m) in &methods {
                let t0 = std::time::Instant::now();
                let (metrics, mut t) = run_episode_timed(m, &cfg, setup, 0, 0)?;
                for _ in 1..repeat {
                    let (again, u) = run_episode_timed(m, &cfg, setup, 0, 0)?;
                    assert_eq!(again, metrics, "episodes are deterministic");
                    if u.decide_secs < t.decide_secs {
                        t = u;
                    }
                }
                eprintln!(
                    "{s} {b} {name}: {:.1} us/decision ({:.1} s)",
                    t.us_per_decision(),
                    t0.elapsed().as_secs_f64()
                );
                println!(
                    "| {s} | {room:.2} | {} | {name} | {:.1} | {:.2} | {} | {} |",
                    cfg.observation.label(),
                    t.us_per_decision(),
                    1e3 * t.physics_secs / steps as f64,
                    metrics.parts_delivered,
                    metrics.collisions
                );
            }
        }
    }
    Ok(())
}
