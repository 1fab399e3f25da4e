//! Reward-design sanity run: 60 PPO updates of 8 episodes with a chosen reward mix.
//! `cargo run --release -p learn --example reward_sanity -- progress 6.4_2`
//! (only the progress term) or `-- tuned 6.4_2` (defaults with COLL / UTIL env overrides).
//! This is how the simulator's collision and utilization defaults were chosen.
use learn::*;
fn main() {
    let mut sc = sim::ScenarioConfig::default();
    let which = std::env::args().nth(1).unwrap_or("progress".into());
    let r = &mut sc.rewards;
    if which == "tuned" {
        r.collision = std::env::var("COLL")
            .map(|v| v.parse().unwrap())
            .unwrap_or(-0.1);
        r.utilization = std::env::var("UTIL")
            .map(|v| v.parse().unwrap())
            .unwrap_or(-0.02);
    }
    if which == "progress" {
        r.pick = 0.0;
        r.place = 0.0;
        r.collision = 0.0;
        r.utilization = 0.0;
        r.time = 0.0;
        r.progress = 2.0;
    }
    let cfg = TrainConfig {
        n_envs: 8,
        num_mini_batch: 4,
        ..TrainConfig::default()
    };
    let setup: sim::Setup = std::env::args()
        .nth(2)
        .unwrap_or("1.1_1".into())
        .parse()
        .unwrap();
    let mut t = Trainer::new(
        policy::ModelKind::Smappo,
        cfg,
        sc,
        vec![Stage {
            setup,
            episodes: 100000,
        }],
        0,
    )
    .unwrap();
    for u in 0..60 {
        let s = t.step().unwrap();
        if u % 5 == 0 {
            println!(
                "upd {u} R {:.2} parts {:.2} coll {:.1} ent {:.3} kl {:.4} vl {:.3}",
                s.team_reward,
                s.parts_delivered,
                s.collisions,
                s.entropy,
                s.approx_kl,
                s.value_loss
            );
        }
    }
}
