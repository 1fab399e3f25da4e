//! The actor PPO minibatch step of `bench_nn` alone (14.10_4, T=10 x B=480 = 4,800 rows),
//! repeated, for profilers and for side-by-side timing:
//! `cargo run --release -p policy --example ppo_step -- [steps] [actor|critic]`.
//! Prints one line per step: milliseconds; then `cpu_ms_per_step X`, the process CPU time
//! (all threads) per step, which other processes' load inflates far less than wall time.
//!
//! `ppo_step export CHECKPOINT OUT.safetensors`: the actor of CHECKPOINT, one batch of the
//! same shape, its logits and the PPO loss gradient of every parameter (before clipping
//! and Adam), for `bench/learner/torch_side_by_side.py` to check that PyTorch computes the
//! same function.

use obs::{Counts, ObsBatch};
use policy::{Actor, ArchConfig, Critic, Policy, PpoActorConfig, Sequences, ValueLossConfig};
use rand::{Rng, SeedableRng};
use safetensors::tensor::{Dtype, TensorView};
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

struct Batch {
    obs: ObsBatch,
    h0: Vec<f32>,
    masks: Vec<f32>,
    actions: Vec<u8>,
    old_logp: Vec<f32>,
    adv: Vec<f32>,
}

/// The actor batch: T = 10 x B = 480 rows at 14.10_4, episode starts every 97 rows.
fn actor_batch(rng: &mut impl Rng) -> Batch {
    let c = Counts {
        machines: 10,
        storages: 4,
        peers: 13,
    };
    let (t, b) = (10, 480);
    let obs = rand_obs(t * b, c, rng);
    let h0: Vec<f32> = (0..b * 64).map(|_| rng.gen_range(-0.5..0.5)).collect();
    let masks: Vec<f32> = (0..t * b)
        .map(|i| if i % 97 == 0 { 0.0 } else { 1.0 })
        .collect();
    let actions: Vec<u8> = (0..t * b).map(|_| rng.gen_range(0..5)).collect();
    let old_logp = vec![-1.6f32; t * b];
    let adv: Vec<f32> = (0..t * b).map(|_| rng.gen_range(-1.0..1.0)).collect();
    Batch {
        obs,
        h0,
        masks,
        actions,
        old_logp,
        adv,
    }
}

impl Batch {
    fn seq(&self, t: usize, b: usize) -> Sequences<'_> {
        Sequences::new(&self.obs, t, b, &self.h0, &self.masks)
    }
}

fn export(ckpt: &str, out: &str) {
    let mut rng = rand::rngs::StdRng::seed_from_u64(0);
    let bt = actor_batch(&mut rng);
    let mut actor = Policy::load(ckpt).expect("checkpoint").actor().clone();
    let (t, b) = (10, 480);
    let logits = actor
        .forward_seq(&bt.obs, t, b, &bt.h0, &bt.masks)
        .unwrap()
        .to_vec();
    actor.params.zero_grad();
    let st = actor
        .ppo_grads(
            bt.seq(t, b),
            &bt.actions,
            &bt.old_logp,
            &bt.adv,
            PpoActorConfig::default(),
        )
        .unwrap();
    let n = t * b;
    let c = bt.obs.counts;
    let f = |v: &[f32]| -> Vec<u8> { v.iter().flat_map(|x| x.to_le_bytes()).collect() };
    let acts: Vec<f32> = bt.actions.iter().map(|&a| a as f32).collect();
    let mut tensors: Vec<(String, Vec<usize>, Vec<u8>)> = vec![
        ("in.own".into(), vec![n, 3], f(&bt.obs.own)),
        (
            "in.machines".into(),
            vec![n, c.machines, 3],
            f(&bt.obs.machines),
        ),
        (
            "in.storages".into(),
            vec![n, c.storages, 2],
            f(&bt.obs.storages),
        ),
        ("in.peers".into(), vec![n, c.peers, 3], f(&bt.obs.peers)),
        ("in.h0".into(), vec![b, 64], f(&bt.h0)),
        ("in.masks".into(), vec![t, b], f(&bt.masks)),
        ("in.actions".into(), vec![n], f(&acts)),
        ("in.old_logp".into(), vec![n], f(&bt.old_logp)),
        ("in.adv".into(), vec![n], f(&bt.adv)),
        ("out.logits".into(), vec![n, 5], f(&logits)),
        ("out.loss".into(), vec![1], f(&[st.loss])),
    ];
    for e in &actor.params.entries {
        tensors.push((
            format!("param.{}", e.name),
            e.shape.clone(),
            f(&actor.params.data[e.slot.r()]),
        ));
        tensors.push((
            format!("grad.{}", e.name),
            e.shape.clone(),
            f(&actor.params.grad[e.slot.r()]),
        ));
    }
    let views: Vec<(String, TensorView)> = tensors
        .iter()
        .map(|(k, s, d)| {
            (
                k.clone(),
                TensorView::new(Dtype::F32, s.clone(), d).unwrap(),
            )
        })
        .collect();
    std::fs::write(out, safetensors::serialize(views, &None).unwrap()).unwrap();
    println!("wrote {out}: loss {}", st.loss);
}

/// User + system CPU time of this process (all threads), seconds.
fn cpu_secs() -> f64 {
    let s = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let f: Vec<&str> = s
        .rsplit(')')
        .next()
        .unwrap_or("")
        .split_whitespace()
        .collect();
    let ticks = |i: usize| f.get(i).and_then(|x| x.parse::<f64>().ok()).unwrap_or(0.0);
    (ticks(11) + ticks(12)) / 100.0
}

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    if a.first().map(String::as_str) == Some("export") {
        export(&a[1], &a[2]);
        return;
    }
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
        let seq = Sequences::new(&obs, t, b, &h0, &masks);
        let c0 = cpu_secs();
        for _ in 0..steps {
            let t0 = Instant::now();
            critic
                .value_grads(seq, n, &old_v, &ret, ValueLossConfig::default())
                .unwrap();
            critic.step(10.0);
            println!("{:.2}", t0.elapsed().as_secs_f64() * 1e3);
        }
        println!(
            "cpu_ms_per_step {:.2}",
            (cpu_secs() - c0) * 1e3 / steps.max(1) as f64
        );
        return;
    }
    let b = 480;
    let bt = actor_batch(&mut rng);
    let mut actor = Actor::new(ArchConfig::smappo(), 1);
    let c0 = cpu_secs();
    for _ in 0..steps {
        let t0 = Instant::now();
        actor
            .ppo_grads(
                bt.seq(t, b),
                &bt.actions,
                &bt.old_logp,
                &bt.adv,
                PpoActorConfig::default(),
            )
            .unwrap();
        actor.step(10.0);
        println!("{:.2}", t0.elapsed().as_secs_f64() * 1e3);
    }
    println!(
        "cpu_ms_per_step {:.2}",
        (cpu_secs() - c0) * 1e3 / steps.max(1) as f64
    );
}
