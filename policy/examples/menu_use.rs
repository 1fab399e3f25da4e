//! Which target-menu entries (`obs::targets`) a target-action policy picks, by setup and by
//! whether the robot carries a part: argmax, through the ORCA planner and filter exactly as
//! `tending eval` runs it. Used to see where a policy spends its robots (docs/RESULTS.md 7.4).
//!
//! cargo run --release -p policy --features train --example menu_use -- CHECKPOINT SETUP [EPISODES]

use obs::targets::{TargetAction, N_TARGET_ACTIONS};
use policy::nn::categorical;
use policy::train::eval::eval_env_seed;
use policy::Policy;
use sim::baselines::GreedyOrcaFleet;
use sim::{Env, ScenarioConfig, Setup};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(ck), Some(setup)) = (args.first(), args.get(1)) else {
        return Err("usage: menu_use CHECKPOINT SETUP [EPISODES]".into());
    };
    let setup: Setup = setup.parse().map_err(|e| format!("SETUP {setup}: {e}"))?;
    let episodes: u64 = args.get(2).map_or(Ok(10), |s| s.parse())?;
    // "greedy-orca" instead of a checkpoint: the script, for its share of robots carrying
    let pol = if ck == "greedy-orca" {
        None
    } else {
        Some(Policy::load(ck)?)
    };
    if pol
        .as_ref()
        .is_some_and(|p| p.actor().arch.n_actions != N_TARGET_ACTIONS)
    {
        return Err(format!("{ck}: not a target-action policy").into());
    }
    let cfg = ScenarioConfig::default();
    // counts[has_part][action]
    let mut counts = [[0u64; N_TARGET_ACTIONS]; 2];
    let (mut parts, mut contacts) = (0u64, 0u64);
    for ep in 0..episodes {
        let mut env = Env::new(cfg.clone(), setup, eval_env_seed(0, ep))?;
        if ep == 0 {
            println!("{setup} sizes: {:?}", env.sizes());
        }
        let mut actor = pol.as_ref().map(|p| p.actor().clone());
        let mut fleet = match actor {
            Some(_) => GreedyOrcaFleet::new_filter(&env, obs::orca::FILTER_CLEARANCE)?,
            None => GreedyOrcaFleet::new(&env)?,
        };
        let n = env.n_robots();
        let mut h = vec![0.0f32; n * actor.as_ref().map_or(0, |a| a.hidden())];
        let masks = vec![1.0f32; n];
        let mut o = obs::ObsBatch::default();
        let (mut actions, mut prefs, mut vels) = (vec![0u8; n], Vec::new(), Vec::new());
        while !env.is_done() {
            env.observe(&mut o);
            let Some(actor) = actor.as_mut() else {
                for r in 0..n {
                    counts[usize::from(o.own_row(r)[2] > 0.5)][1] += 1;
                }
                fleet.act(&o, &mut vels)?;
                env.step_velocities(&vels)?;
                continue;
            };
            let logits = actor.forward_step(&o, &mut h, &masks)?;
            for (r, a) in actions.iter_mut().enumerate() {
                *a = categorical::argmax(&logits[r * N_TARGET_ACTIONS..(r + 1) * N_TARGET_ACTIONS])
                    as u8;
                counts[usize::from(o.own_row(r)[2] > 0.5)][*a as usize] += 1;
            }
            fleet.target_velocities(&o, &actions, &mut prefs)?;
            fleet.filter(&o, &prefs, &mut vels)?;
            env.step_velocities(&vels)?;
        }
        let m = env.metrics();
        parts += m.parts_delivered as u64;
        contacts += m.collisions as u64;
    }
    println!(
        "{setup} ({episodes} episodes, seed 0): parts {:.1}, contact steps {:.1} per episode",
        parts as f64 / episodes as f64,
        contacts as f64 / episodes as f64
    );
    for (carrying, row) in counts.iter().enumerate() {
        let total: u64 = row.iter().sum::<u64>().max(1);
        let label = if carrying == 1 {
            "with a part"
        } else {
            "without a part"
        };
        print!(
            "{label:>15} ({:5.1} %):",
            100.0 * total as f64 / counts.iter().flatten().sum::<u64>().max(1) as f64
        );
        for (a, c) in row.iter().enumerate() {
            let name = TargetAction::from_index(a as u8).map_or("?", |t| t.name());
            print!(" {name} {:.1} %", 100.0 * *c as f64 / total as f64);
        }
        println!();
    }
    Ok(())
}
