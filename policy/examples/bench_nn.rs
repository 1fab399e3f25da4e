//! Benchmark: single-robot decisions and one PPO minibatch step (fwd + bwd + Adam).
//! Run: cargo run -p policy --release --example bench_nn

use obs::{Counts, ObsBatch};
use policy::{
    ActMode, Actor, ArchConfig, Critic, Policy, PpoActorConfig, Sequences, ValueLossConfig,
};
use rand::{Rng, SeedableRng};
use std::time::Instant;

fn rand_obs(rows: usize, c: Counts, rng: &mut impl Rng) -> ObsBatch {
    let mut b = ObsBatch::zeros(rows, c);
    for (v, dim, flag) in [
        (&mut b.own, 3, Some(2)),
        (&mut b.machines, 3, Some(2)),
        (&mut b.storages, 2, None),
        (&mut b.peers, 3, Some(2)),
    ] {
        for (i, x) in v.iter_mut().enumerate() {
            *x = if Some(i % dim) == flag {
                rng.gen_range(0..2) as f32
            } else {
                rng.gen_range(-1.15..1.15)
            };
        }
    }
    b
}

fn counts(m: usize, s: usize, p: usize) -> Counts {
    Counts {
        machines: m,
        storages: s,
        peers: p,
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v[v.len() / 2]
}

fn main() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(0);
    let actor = Actor::new(ArchConfig::smappo(), 0);
    println!("SMAPPO actor parameters: {}", actor.params.len());
    let critic_n = Critic::new(ArchConfig::smappo(), 0).params.len();
    println!("SMAPPO critic parameters: {critic_n}");
    let mut pol = Policy::from_actor(actor, serde_json::Value::Null);

    for (name, c) in [
        ("14.10_4", counts(10, 4, 13)),
        ("100.16_2", counts(16, 2, 99)),
    ] {
        let obs: Vec<ObsBatch> = (0..64).map(|_| rand_obs(1, c, &mut rng)).collect();
        let mut st = pol.new_state();
        for o in obs.iter().cycle().take(500) {
            pol.act(o, &mut st, ActMode::Greedy).unwrap();
        }
        let mut per_call = vec![];
        for _ in 0..20 {
            let t0 = Instant::now();
            for o in obs.iter().cycle().take(500) {
                std::hint::black_box(pol.act(o, &mut st, ActMode::Greedy).unwrap());
            }
            per_call.push(t0.elapsed().as_secs_f64() / 500.0 * 1e6);
        }
        println!(
            "decision {name} (machines {}, storages {}, peers {}): median {:.1} us (min {:.1})",
            c.machines,
            c.storages,
            c.peers,
            median(per_call.clone()),
            per_call.iter().cloned().fold(f64::MAX, f64::min)
        );
    }

    // PPO minibatch: T = 10, B = 480 (4,800 rows) at 14.10_4
    let (t, b) = (10, 480);
    let c = counts(10, 4, 13);
    let obs = rand_obs(t * b, c, &mut rng);
    let h0: Vec<f32> = (0..b * 64).map(|_| rng.gen_range(-0.5..0.5)).collect();
    let masks: Vec<f32> = (0..t * b)
        .map(|i| if i % 97 == 0 { 0.0 } else { 1.0 })
        .collect();
    let actions: Vec<u8> = (0..t * b).map(|_| rng.gen_range(0..5)).collect();
    let old_logp = vec![-1.6f32; t * b];
    let adv: Vec<f32> = (0..t * b).map(|_| rng.gen_range(-1.0..1.0)).collect();
    let mut actor = Actor::new(ArchConfig::smappo(), 1);
    let seq = Sequences::new(&obs, t, b, &h0, &masks);
    let mut times = vec![];
    for i in 0..12 {
        let t0 = Instant::now();
        actor
            .ppo_grads(seq, &actions, &old_logp, &adv, PpoActorConfig::default())
            .unwrap();
        actor.step(10.0);
        if i >= 2 {
            times.push(t0.elapsed().as_secs_f64() * 1e3);
        }
    }
    let mut fwd = vec![];
    for _ in 0..5 {
        let t0 = Instant::now();
        std::hint::black_box(actor.forward_seq(&obs, t, b, &h0, &masks).unwrap());
        fwd.push(t0.elapsed().as_secs_f64() * 1e3);
    }
    println!(
        "actor PPO minibatch step 14.10_4, T={t} x B={b} = {} rows, fwd+bwd+Adam: median {:.1} ms (min {:.1}); forward only {:.1} ms",
        t * b,
        median(times.clone()),
        times.iter().cloned().fold(f64::MAX, f64::min),
        median(fwd)
    );

    // critic minibatch: 480 rows = 34 envs of 14 robots would not divide; use 35 envs x 14 = 490
    let n = 14;
    let b = 490;
    let obs = rand_obs(t * b, c, &mut rng);
    let h0 = vec![0.0f32; b * 64];
    let masks = vec![1.0f32; t * b];
    let old_v = vec![0.0f32; t * b];
    let ret: Vec<f32> = (0..t * b).map(|_| rng.gen_range(-1.0..1.0)).collect();
    let mut critic = Critic::new(ArchConfig::smappo(), 2);
    let seq = Sequences::new(&obs, t, b, &h0, &masks);
    let mut times = vec![];
    for i in 0..7 {
        let t0 = Instant::now();
        critic
            .value_grads(seq, n, &old_v, &ret, ValueLossConfig::default())
            .unwrap();
        critic.step(10.0);
        if i >= 2 {
            times.push(t0.elapsed().as_secs_f64() * 1e3);
        }
    }
    println!(
        "critic minibatch step 14.10_4, T={t} x B={b} ({} envs x {n}) = {} rows, fwd+bwd+Adam: median {:.1} ms",
        b / n,
        t * b,
        median(times)
    );
}
