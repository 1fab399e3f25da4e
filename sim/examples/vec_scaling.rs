//! Where the batched path wins or loses: agent-steps/s (observations included) of
//! - one env, stepped in a loop on this thread;
//! - N envs in a plain loop on this thread (the sequential reference);
//! - N envs by `VecEnv` (sim::fork: the caller steps one run of envs, micropool's
//!   spinning thread the other);
//! - N envs by rayon's `par_iter` entered from outside its pool (VecEnv's previous path).
//!
//!   cargo run --release -p sim --example vec_scaling -- [SETUP] [N_ENVS] [SECONDS] [ROUNDS]
//!
//! With `VEC_SCALING_ONLY=loop` (or `=vec`) only the N-env loop on this thread (or
//! `VecEnv`) is measured, SECONDS once, and its agent-steps/s printed: two `loop`
//! processes at once show what two independent single-threaded workers get on this
//! machine, the ceiling for any split of one batch over its two cores
//! (`bench/sim/ceiling.sh`).
//!
//! With ROUNDS > 1 (a shared, noisy machine) one env, the loop and VecEnv are measured in
//! turn, SECONDS each, ROUNDS times, and each ratio is reported as the median over the
//! rounds of that round's ratio (neighbours' load drifts over seconds, so a ratio of two
//! measurements taken seconds apart is noisier than the median of adjacent pairs).
use obs::ObsBatch;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use sim::{Env, ScenarioConfig, Setup, VecEnv};
use std::time::{Duration, Instant};

fn actions(n: usize, rng: &mut rand_chacha::ChaCha8Rng) -> Vec<Vec<u8>> {
    (0..64)
        .map(|_| (0..n).map(|_| rng.gen_range(0..5u8)).collect())
        .collect()
}

/// Calls of `f` per second over `secs`, after a warm-up.
fn rate(secs: f64, mut f: impl FnMut(usize)) -> f64 {
    (0..20).for_each(&mut f);
    let t0 = Instant::now();
    let mut calls = 0;
    while t0.elapsed() < Duration::from_secs_f64(secs) {
        for _ in 0..10 {
            f(calls);
            calls += 1;
        }
    }
    calls as f64 / t0.elapsed().as_secs_f64()
}

fn step_one(env: &mut Env, a: &[u8], out: &mut ObsBatch, i: usize) {
    if env.is_done() {
        env.reset(i as u64).expect("reset");
    }
    env.step_actions(a).expect("step");
    env.observe(out);
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let setup: Setup = args.get(1).map_or("6.4_2", |s| s).parse().expect("SETUP");
    let n_envs: usize = args.get(2).map_or(32, |s| s.parse().expect("N_ENVS"));
    let secs: f64 = args.get(3).map_or(2.0, |s| s.parse().expect("SECONDS"));
    let rounds: usize = args.get(4).map_or(1, |s| s.parse().expect("ROUNDS"));
    let cfg = ScenarioConfig::default();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let r = setup.robots;
    let (p1, pn) = (actions(r, &mut rng), actions(r * n_envs, &mut rng));
    let new_envs = || -> Vec<Env> {
        (0..n_envs)
            .map(|e| Env::new(cfg.clone(), setup, e as u64).expect("env"))
            .collect()
    };

    let mut one = Env::new(cfg.clone(), setup, 1).expect("env");
    let mut out = ObsBatch::default();
    let (mut envs, mut outs) = (new_envs(), vec![ObsBatch::default(); n_envs]);
    let mut v = VecEnv::new(cfg.clone(), setup, n_envs, 1).expect("VecEnv");
    let step_loop = |envs: &mut Vec<Env>, outs: &mut Vec<ObsBatch>, i: usize| {
        for (e, (env, o)) in envs.iter_mut().zip(outs.iter_mut()).enumerate() {
            step_one(env, &pn[i % 64][e * r..(e + 1) * r], o, i);
        }
    };
    match std::env::var("VEC_SCALING_ONLY").as_deref() {
        Ok("loop") => {
            let rate = rate(secs, |i| step_loop(&mut envs, &mut outs, i)) * (r * n_envs) as f64;
            println!("{setup} x {n_envs} envs, loop on one thread: {rate:.0} agent-steps/s");
            return;
        }
        Ok("vec") => {
            let rate = rate(secs, |i| {
                v.step_actions_observe(&pn[i % 64], &mut out).expect("step");
            }) * (r * n_envs) as f64;
            println!("{setup} x {n_envs} envs, VecEnv: {rate:.0} agent-steps/s");
            return;
        }
        _ => {}
    }
    let (mut singles, mut loops, mut forks) = (vec![], vec![], vec![]);
    for _ in 0..rounds.max(1) {
        singles.push(rate(secs, |i| step_one(&mut one, &p1[i % 64], &mut out, i)) * r as f64);
        loops.push(rate(secs, |i| step_loop(&mut envs, &mut outs, i)) * (r * n_envs) as f64);
        forks.push(
            rate(secs, |i| {
                v.step_actions_observe(&pn[i % 64], &mut out).expect("step");
            }) * (r * n_envs) as f64,
        );
    }
    let median = |mut x: Vec<f64>| {
        x.sort_by(f64::total_cmp);
        x[x.len() / 2]
    };
    let ratio = |a: &[f64], b: &[f64]| median(a.iter().zip(b).map(|(a, b)| a / b).collect());
    if rounds > 1 {
        println!(
            "{setup} x {n_envs} envs, {rounds} rounds of {secs} s, medians of per-round ratios: \
             loop/1 env {:.2}x | VecEnv/1 env {:.2}x | VecEnv/loop {:.2}x (VecEnv/1 env per round: {})",
            ratio(&loops, &singles),
            ratio(&forks, &singles),
            ratio(&forks, &loops),
            forks
                .iter()
                .zip(&singles)
                .map(|(f, s)| format!("{:.2}", f / s))
                .collect::<Vec<_>>()
                .join(" ")
        );
        return;
    }
    let (single, looped, forked) = (singles[0], loops[0], forks[0]);

    let rayon_ext = rate(secs, |i| {
        envs.par_iter_mut()
            .zip(outs.par_iter_mut())
            .enumerate()
            .for_each(|(e, (env, o))| step_one(env, &pn[i % 64][e * r..(e + 1) * r], o, i));
    }) * (r * n_envs) as f64;

    let empty_mp = 1e6
        / rate(secs, |_| {
            micropool::join(|| std::hint::black_box(1), || std::hint::black_box(2));
        });
    let empty_ry = 1e6
        / rate(secs, |_| {
            rayon::join(|| std::hint::black_box(1), || std::hint::black_box(2));
        });
    println!("empty join from outside: micropool {empty_mp:.2} us, rayon {empty_ry:.2} us");
    println!(
        "{setup} x {n_envs} envs, {} threads: 1 env {single:.0} | loop {looped:.0} ({:.2}x) | VecEnv {forked:.0} ({:.2}x) | rayon from outside {rayon_ext:.0} ({:.2}x)",
        sim::fork::threads(),
        looped / single,
        forked / single,
        rayon_ext / single
    );
}
