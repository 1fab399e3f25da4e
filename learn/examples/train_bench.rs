//! Time PPO updates: `cargo run --release -p learn --example train_bench
//! -- [setup] [n_envs] [ppo_epoch] [updates] [smappo|mappo] [num_mini_batch]`.

use learn::{parse_curriculum, TrainConfig, Trainer};
use policy::ModelKind;

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let setup = a.first().cloned().unwrap_or_else(|| "6.4_2".into());
    let n_envs: usize = a.get(1).and_then(|x| x.parse().ok()).unwrap_or(8);
    let epochs: usize = a.get(2).and_then(|x| x.parse().ok()).unwrap_or(10);
    let updates: usize = a.get(3).and_then(|x| x.parse().ok()).unwrap_or(3);
    let kind = match a.get(4).map(String::as_str) {
        Some("mappo") => ModelKind::Mappo,
        _ => ModelKind::Smappo,
    };
    let num_mini_batch: usize = a.get(5).and_then(|x| x.parse().ok()).unwrap_or(1);
    let cfg = TrainConfig {
        n_envs,
        ppo_epoch: epochs,
        num_mini_batch,
        ..TrainConfig::default()
    };
    let sched = parse_curriculum(&format!("{setup}:1000000")).unwrap();
    // MAPPO pads to fixed maxima (42 robots by default): widen them to the setup benched
    let mut cfg = cfg;
    if kind == ModelKind::Mappo {
        let s = sched[0].setup;
        cfg.mappo_max_robots = cfg.mappo_max_robots.max(s.robots);
        cfg.mappo_max_machines = cfg.mappo_max_machines.max(s.machines);
        cfg.mappo_max_storages = cfg.mappo_max_storages.max(s.storages);
    }
    let mut t = Trainer::new(kind, cfg, sim::ScenarioConfig::default(), sched, 0).unwrap();
    for _ in 0..updates {
        let t0 = std::time::Instant::now();
        let s = t.step().unwrap();
        let dt = t0.elapsed().as_secs_f64();
        let steps = n_envs as f64 * 200.0 * t.current_setup().robots as f64;
        println!(
            "{kind} {setup} envs {n_envs} epochs {epochs}: update {:.2} s (rollout {:.2} s, \
             train {:.2} s = {:.3} s/epoch), {:.0} agent-steps/s, R {:.1} MU {:.3}",
            dt,
            s.rollout_secs,
            s.train_secs,
            s.train_secs / epochs as f64,
            steps / dt,
            s.team_reward,
            s.mu
        );
    }
}
