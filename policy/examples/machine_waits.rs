//! Where machine time goes: for each ready part, how many steps it waits for a pick, split
//! by what the nearest part-less robot was doing meanwhile. Machine utilization (and so the
//! parts) is lost only in those steps, so this says which behaviour a better controller
//! would have to change (docs/RESULTS.md 7.8).
//!
//! Classes of a ready-part step at machine j:
//! - `first`: before j's first pick of the episode (robots still arriving);
//! - `at-box`: a part-less robot is within pick reach of j's box plus one step's travel
//!   (arriving, or held off by the safety margin);
//! - `en-route`: part-less robots exist, all of them farther than that (travel);
//! - `none-free`: every robot carries a part.
//!
//! Also: parts picked but still carried at the end (`stranded`), and for `en-route` steps
//! whether the matching (`obs::targets::matched_machine`, timed by the simulator's own
//! timers, which the planner's clock equals offline) sends a part-less robot to j, and
//! how many steps away that robot is (docs/RESULTS.md 7.13).
//!
//! cargo run --release -p policy --features train --example machine_waits -- CHECKPOINT|greedy-orca SETUP [EPISODES] [SEED]

use policy::train::eval::{run_episode_hooked, Controller};
use sim::{ScenarioConfig, Setup};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(ck), Some(setup)) = (args.first(), args.get(1)) else {
        return Err("usage: machine_waits CHECKPOINT|greedy-orca SETUP [EPISODES] [SEED]".into());
    };
    let setup: Setup = setup.parse().map_err(|e| format!("SETUP {setup}: {e}"))?;
    let episodes: u64 = args.get(2).map_or(Ok(10), |s| s.parse())?;
    let seed: u64 = args.get(3).map_or(Ok(0), |s| s.parse())?;
    let ctrl = Controller::script_or_filtered_checkpoint(ck)?;
    let cfg = ScenarioConfig::default();
    // [first, at-box, en-route, none-free]
    let mut waits = [0u64; 4];
    let (mut parts, mut stranded, mut machine_steps) = (0u64, 0u64, 0u64);
    let mut idle_steps = 0u64;
    let mut robot_steps = 0u64;
    // en-route steps with a robot matched to the machine, and that robot's distance in steps
    let (mut heading, mut heading_steps) = (0u64, 0.0f64);
    let mut batch = obs::ObsBatch::default();
    for ep in 0..episodes {
        let mut picked_once: Vec<bool> = Vec::new();
        let mut last_ready: Vec<bool> = Vec::new();
        let mut final_carried = 0u64;
        let m = run_episode_hooked(
            &ctrl,
            &cfg,
            setup,
            seed,
            ep,
            |env| {
                let sizes = env.sizes();
                let near = sizes.robot_radius + sizes.reach + cfg.task.k_speed * cfg.world.dt;
                let machines: Vec<_> = env.machines().collect();
                let robots: Vec<_> = env.robots().collect();
                let step = cfg.task.k_speed * cfg.world.dt;
                let params = sim::baselines::greedy_params(sizes, &cfg);
                env.observe(&mut batch);
                let ready_in: Vec<Option<u32>> = machines
                    .iter()
                    .map(|m| Some(if m.part_ready { 0 } else { m.timer }))
                    .collect();
                let matched: Vec<Option<usize>> = (0..robots.len())
                    .map(|i| {
                        obs::targets::matched_machine(
                            batch.own_row(i),
                            batch.machines_row(i),
                            batch.peers_row(i),
                            &params,
                            &ready_in,
                        )
                    })
                    .collect();
                if picked_once.is_empty() {
                    picked_once = vec![false; machines.len()];
                    last_ready = vec![true; machines.len()];
                }
                for (j, m) in machines.iter().enumerate() {
                    if last_ready[j] && !m.part_ready {
                        picked_once[j] = true;
                    }
                    last_ready[j] = m.part_ready;
                    machine_steps += 1;
                    if !m.part_ready {
                        continue;
                    }
                    let mut free = robots.iter().filter(|r| !r.has_part).peekable();
                    let class = if !picked_once[j] {
                        0
                    } else if free.peek().is_none() {
                        3
                    } else if free.any(|r| obs::geom::box_distance(m.centre, m.half, r.pos) <= near)
                    {
                        1
                    } else {
                        2
                    };
                    waits[class] += 1;
                    let to_j = (0..robots.len()).find(|&i| matched[i] == Some(j));
                    if let Some(i) = to_j.filter(|_| class == 2) {
                        heading += 1;
                        heading_steps += (obs::geom::box_distance(m.centre, m.half, robots[i].pos)
                            / step) as f64;
                    }
                }
                final_carried = robots.iter().filter(|r| r.has_part).count() as u64;
                idle_steps += robots.iter().filter(|r| !r.has_part).count() as u64;
                robot_steps += robots.len() as u64;
            },
            |_, _| {},
        )?;
        parts += m.parts_delivered as u64;
        stranded += final_carried;
    }
    let e = episodes as f64;
    let m = (setup.machines as f64) * e;
    println!(
        "{setup} {ck} ({episodes} episodes, seed {seed}): parts {:.1}, stranded {:.2} per episode, robots part-less {:.1} % of steps",
        parts as f64 / e,
        stranded as f64 / e,
        100.0 * idle_steps as f64 / robot_steps.max(1) as f64
    );
    println!(
        "  ready-part steps per machine per episode: first {:.1}, at-box {:.1}, en-route {:.1}, none-free {:.1} (of {:.0} steps)",
        waits[0] as f64 / m,
        waits[1] as f64 / m,
        waits[2] as f64 / m,
        waits[3] as f64 / m,
        machine_steps as f64 / m
    );
    println!(
        "  en-route steps with a part-less robot matched to the machine: {:.1} % of them, that robot {:.1} steps from the box on average",
        100.0 * heading as f64 / waits[2].max(1) as f64,
        heading_steps / heading.max(1) as f64
    );
    Ok(())
}
