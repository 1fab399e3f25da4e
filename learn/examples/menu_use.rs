//! Which target-menu entries (`plan::targets`) a target-action policy picks, by setup and by
//! whether the robot carries a part: argmax, through the ORCA planner and filter, by
//! `tending eval`'s own episode runner. Used to see where a policy spends its robots
//! (docs/RESULTS.md 7.4-7.5).
//!
//! cargo run --release -p learn --example menu_use -- CHECKPOINT SETUP [EPISODES]

use learn::eval::{run_episode_hooked, Method};
use plan::targets::{TargetAction, N_TARGET_ACTIONS};
use sim::{ScenarioConfig, Setup};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(ck), Some(setup)) = (args.first(), args.get(1)) else {
        return Err("usage: menu_use CHECKPOINT|greedy-orca|matching-orca SETUP [EPISODES]".into());
    };
    let setup: Setup = setup.parse().map_err(|e| format!("SETUP {setup}: {e}"))?;
    let episodes: u64 = args.get(2).map_or(Ok(10), |s| s.parse())?;
    // "greedy-orca" instead of a checkpoint: the script, for its share of robots carrying
    // (every robot-step counts as the "greedy" entry).
    let ctrl = Method::script_or_filtered_checkpoint(ck)?;
    if let Method::Learned { actor, .. } = &ctrl {
        if !plan::targets::menu_size_ok(actor.arch.n_actions) {
            return Err(format!("{ck}: not a target-action policy").into());
        }
    }
    let cfg = ScenarioConfig::default();
    // counts[has_part][action]
    let mut counts = [[0u64; N_TARGET_ACTIONS]; 2];
    let (mut parts, mut contacts) = (0u64, 0u64);
    let mut o = obs::ObsBatch::default();
    // The script's robot-steps by has_part (it picks no discrete action).
    let mut script = [0u64; 2];
    for ep in 0..episodes {
        let m = run_episode_hooked(
            &ctrl,
            &cfg,
            setup,
            0,
            ep,
            |env| {
                if matches!(ctrl, Method::GreedyOrca { .. }) {
                    env.observe(&mut o);
                    for r in 0..o.rows {
                        script[usize::from(o.own_row(r)[2] > 0.5)] += 1;
                    }
                }
            },
            |o, actions| {
                for (r, &a) in actions.iter().enumerate() {
                    counts[usize::from(o.own_row(r)[2] > 0.5)][a as usize] += 1;
                }
            },
        )?;
        parts += m.parts_delivered as u64;
        contacts += m.collisions as u64;
    }
    for (row, n) in counts.iter_mut().zip(script) {
        row[TargetAction::Greedy as usize] += n;
    }
    println!(
        "{setup} ({episodes} episodes, seed 0): parts {:.1}, contact steps {:.1} per episode",
        parts as f64 / episodes as f64,
        contacts as f64 / episodes as f64
    );
    let all = counts.iter().flatten().sum::<u64>().max(1);
    for (carrying, row) in counts.iter().enumerate() {
        let total: u64 = row.iter().sum::<u64>().max(1);
        let label = if carrying == 1 {
            "with a part"
        } else {
            "without a part"
        };
        print!("{label:>15} ({:5.1} %):", 100.0 * total as f64 / all as f64);
        for (a, c) in row.iter().enumerate() {
            let name = TargetAction::from_index(a as u8).map_or("?", |t| t.name());
            print!(" {name} {:.1} %", 100.0 * *c as f64 / total as f64);
        }
        println!();
    }
    Ok(())
}
