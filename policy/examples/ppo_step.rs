//! The actor PPO minibatch step of `bench_nn` alone (14.10_4, T=10 x B=480 = 4,800 rows),
//! repeated, for profilers and for side-by-side timing:
//! `cargo run --release -p policy --example ppo_step -- [steps] [actor|critic]`.
//! Prints one line per step: milliseconds.

use obs::{Counts, ObsBatch};
use policy::{Actor, ArchConfig, Critic, PpoActorConfig, ValueLossConfig};
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

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let steps: usize = a.first().and_then(|x| x.parse().ok()).unwrap_or(20);
    let critic_only = a.get(1).map(String::as_str) == Some("critic");
    let mut rng = rand::rngs::StdRng::seed_from_u64(0);
    let c = Counts {
        machines: 10,
        storages: 4,
        peers: 13,
    };
    let t = 10;
    if critic_only {
        let (n, b) = (14, 490);
        let obs = rand_obs(t * b, c, &mut rng);
        let h0 = vec![0.0f32; b * 64];
        let masks = vec![1.0f32; t * b];
        let old_v = vec![0.0f32; t * b];
        let ret: Vec<f32> = (0..t * b).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let mut critic = Critic::new(ArchConfig::smappo(), 2);
        for _ in 0..steps {
            let t0 = Instant::now();
            critic
                .value_grads(
                    &obs,
                    t,
                    b,
                    n,
                    &h0,
                    &masks,
                    &old_v,
                    &ret,
                    ValueLossConfig::default(),
                )
                .unwrap();
            critic.step(10.0);
            println!("{:.2}", t0.elapsed().as_secs_f64() * 1e3);
        }
        return;
    }
    let b = 480;
    let obs = rand_obs(t * b, c, &mut rng);
    let h0: Vec<f32> = (0..b * 64).map(|_| rng.gen_range(-0.5..0.5)).collect();
    let masks: Vec<f32> = (0..t * b)
        .map(|i| if i % 97 == 0 { 0.0 } else { 1.0 })
        .collect();
    let actions: Vec<u8> = (0..t * b).map(|_| rng.gen_range(0..5)).collect();
    let old_logp = vec![-1.6f32; t * b];
    let adv: Vec<f32> = (0..t * b).map(|_| rng.gen_range(-1.0..1.0)).collect();
    let mut actor = Actor::new(ArchConfig::smappo(), 1);
    for _ in 0..steps {
        let t0 = Instant::now();
        actor
            .ppo_grads(
                &obs,
                t,
                b,
                &h0,
                &masks,
                &actions,
                &old_logp,
                &adv,
                PpoActorConfig::default(),
            )
            .unwrap();
        actor.step(10.0);
        println!("{:.2}", t0.elapsed().as_secs_f64() * 1e3);
    }
}
