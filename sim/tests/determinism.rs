//! Bit-for-bit determinism whatever the thread count.
use sim::{ScenarioConfig, VecEnv};

fn run(threads: usize) -> (Vec<u32>, Vec<f32>, Vec<f32>) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let mut v =
            VecEnv::new(ScenarioConfig::default(), "6.4_2".parse().unwrap(), 8, 42).unwrap();
        let n = v.robots_per_env() * v.n_envs();
        let mut obs = obs::ObsBatch::default();
        let mut rewards = Vec::new();
        let mut a = vec![0u8; n];
        let mut state = 1u64;
        for _ in 0..450 {
            for x in a.iter_mut() {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                *x = ((state >> 33) % 5) as u8;
            }
            v.step_actions(&a).unwrap();
            rewards.extend_from_slice(v.rewards());
        }
        v.observe(&mut obs);
        let parts = v
            .envs()
            .iter()
            .map(|e| e.metrics().parts_collected)
            .collect();
        (parts, rewards, obs.peers)
    })
}

#[test]
fn same_results_with_one_and_two_threads() {
    let a = run(1);
    let b = run(2);
    assert_eq!(a.0, b.0);
    assert!(a
        .1
        .iter()
        .zip(&b.1)
        .all(|(x, y)| x.to_bits() == y.to_bits()));
    assert!(a
        .2
        .iter()
        .zip(&b.2)
        .all(|(x, y)| x.to_bits() == y.to_bits()));
    assert!(a.1.iter().any(|&r| r != a.1[0]), "rewards should vary");
}
