//! Bit-for-bit determinism of the batched path: `VecEnv`, whose envs are split across
//! threads (`sim::fork`), gives exactly what the same envs stepped one by one on this
//! thread give, episode resets included.
use sim::{episode_seed, Env, ScenarioConfig, Setup, VecEnv};

const N_ENVS: usize = 8;
const SEED: u64 = 42;
const STEPS: usize = 450; // past two episode ends (200 steps each)

fn actions(n: usize) -> Vec<Vec<u8>> {
    let mut state = 1u64;
    (0..STEPS)
        .map(|_| {
            (0..n)
                .map(|_| {
                    state = state
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    ((state >> 33) % 5) as u8
                })
                .collect()
        })
        .collect()
}

#[test]
fn the_batched_path_equals_envs_stepped_one_by_one() {
    let setup: Setup = "6.4_2".parse().unwrap();
    let n = setup.robots * N_ENVS;
    let acts = actions(n);

    let mut v = VecEnv::new(ScenarioConfig::default(), setup, N_ENVS, SEED).unwrap();
    let (mut rewards_v, mut obs_v) = (Vec::new(), obs::ObsBatch::default());
    for a in &acts {
        v.step_actions(a).unwrap();
        rewards_v.extend_from_slice(v.rewards());
    }
    v.observe(&mut obs_v);

    let mut envs: Vec<Env> = (0..N_ENVS)
        .map(|e| Env::new(ScenarioConfig::default(), setup, episode_seed(SEED, e, 0)).unwrap())
        .collect();
    let mut episode = [0u64; N_ENVS];
    let mut rewards_s = Vec::new();
    for a in &acts {
        for (e, env) in envs.iter_mut().enumerate() {
            env.step_actions(&a[e * setup.robots..(e + 1) * setup.robots])
                .unwrap();
            rewards_s.extend_from_slice(env.rewards());
            if env.is_done() {
                episode[e] += 1;
                env.reset(episode_seed(SEED, e, episode[e])).unwrap();
            }
        }
    }
    let mut peers_s = Vec::new();
    for env in &envs {
        let mut o = obs::ObsBatch::default();
        env.observe(&mut o);
        peers_s.extend_from_slice(&o.peers);
    }

    let bits = |x: &[f32]| x.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&rewards_v), bits(&rewards_s));
    assert_eq!(bits(&obs_v.peers), bits(&peers_s));
    let parts = |es: &[Env]| {
        es.iter()
            .map(|e| e.metrics().parts_collected)
            .collect::<Vec<_>>()
    };
    assert_eq!(parts(v.envs()), parts(&envs));
    assert!(
        rewards_v.iter().any(|&r| r != rewards_v[0]),
        "rewards should vary"
    );
    assert!(
        episode.iter().all(|&k| k == 2),
        "two episode ends per env: {episode:?}"
    );
}

#[test]
fn the_fused_step_and_observation_equal_the_two_calls() {
    let setup: Setup = "4.2_2".parse().unwrap();
    let acts = actions(setup.robots * N_ENVS);
    let mut a = VecEnv::new(ScenarioConfig::default(), setup, N_ENVS, SEED).unwrap();
    let mut b = VecEnv::new(ScenarioConfig::default(), setup, N_ENVS, SEED).unwrap();
    let (mut oa, mut ob) = (obs::ObsBatch::default(), obs::ObsBatch::default());
    let bits = |x: &[f32]| x.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
    for (t, act) in acts.iter().enumerate() {
        a.step_actions_observe(act, &mut oa).unwrap();
        b.step_actions(act).unwrap();
        b.observe(&mut ob);
        assert_eq!(bits(a.rewards()), bits(b.rewards()), "step {t}");
        assert_eq!(a.done(), b.done(), "step {t}");
        for (x, y) in [
            (&oa.own, &ob.own),
            (&oa.machines, &ob.machines),
            (&oa.storages, &ob.storages),
            (&oa.peers, &ob.peers),
        ] {
            assert_eq!(bits(x), bits(y), "step {t}");
        }
    }
}
