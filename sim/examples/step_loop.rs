//! A bare step loop for profilers: `cargo run --release -p sim --example step_loop -- 14.10_4 2000`.
fn main() {
    let mut args = std::env::args().skip(1);
    let setup: sim::Setup = args.next().unwrap_or("14.10_4".into()).parse().unwrap();
    let steps: usize = args.next().map(|s| s.parse().unwrap()).unwrap_or(2000);
    let mut env = sim::Env::new(sim::ScenarioConfig::default(), setup, 1).unwrap();
    let n = env.n_robots();
    let mut obs = obs::ObsBatch::default();
    let mut a = vec![0u8; n];
    let mut s = 1u64;
    for k in 0..steps {
        for x in a.iter_mut() {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1);
            *x = ((s >> 33) % 5) as u8;
        }
        if env.is_done() {
            env.reset(k as u64).unwrap();
        }
        env.step_actions(&a).unwrap();
        env.observe(&mut obs);
    }
    println!(
        "{} agent-steps, parts {}",
        steps * n,
        env.metrics().parts_collected
    );
}
