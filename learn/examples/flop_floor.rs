//! The arithmetic floor of SMAPPO training (issue 11): multiply-adds per observation row of
//! the actor and the critic, counted from the parameter tensors the real networks
//! instantiate (built by `Trainer::new` from the bundled training config), then per PPO
//! update and per issue-11 target, divided by this machine's theoretical FP32 peak.
//!
//! ```sh
//! cargo run --release -p learn --example flop_floor -- [GHz] [cores]
//! # one real update of the bundled config (rollout and train seconds), optionally smaller:
//! cargo run --release -p learn --example flop_floor -- \
//!     --measure 6.4_2 [n_envs] [ppo_epoch]
//! # the AVX-512 FMA rate this machine actually delivers (about 1 s):
//! cargo run --release -p learn --example flop_floor -- --fma
//! ```
//!
//! Counting rules (per observation row, from `nn::attention`, `nn::linear`, `nn::gru`,
//! `encoder`, `critic`): a Linear `[out, in]` costs out*in forward and 2*out*in backward
//! (dW and dx; the first layer on raw observations, `self_enc`, has no dx); GRU weights
//! out*in forward, 2*out*in backward (dW, and dx resp. the BPTT dh product). An attention
//! `in_proj_weight` `[3E, E]` with S keys costs 3*E^2 forward in GEMMs (Q, U = Wk^T q per
//! head, O = Wv ebar per head) plus 2*H*S*E in the per-row kernel (scores, weighted sum),
//! backward 6*E^2 plus 4*H*S*E (the score dots, dU, and dK with two products per element);
//! its `out_proj` E^2 / 2*E^2. Entity encoders (`*_enc`, d_in <= 4) run inside the row
//! kernel: S*out*in forward, twice that backward (recompute and weight gradient). The
//! critic's global attention runs once per env-step (its query is a parameter), so its
//! cost per row is divided by the robots per env. Biases, LayerNorm, softmax exp and the
//! GRU gates are elementwise: not counted (they are in the measured non-GEMM time).

use learn::{parse_curriculum, TrainConfig, Trainer};
use nn::ParamStore;
use policy::ModelKind;
use sim::{ScenarioConfig, Setup};

const BUNDLED: &str = include_str!("../../policy/pretrained/smappo_6.4_2.train.toml");

/// Multiply-adds per observation row.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Macs {
    gemm_fwd: f64,
    gemm_bwd: f64,
    /// Per-row attention kernels and entity encoders (own loops, not GEMM calls).
    row_fwd: f64,
    row_bwd: f64,
}

impl Macs {
    fn fwd(&self) -> f64 {
        self.gemm_fwd + self.row_fwd
    }
    fn bwd(&self) -> f64 {
        self.gemm_bwd + self.row_bwd
    }
    fn total(&self) -> f64 {
        self.fwd() + self.bwd()
    }
}

/// Entities a row sees: machines, storages, peers (`sim::Env::obs_counts`).
type Entities = [usize; 3];

const GROUPS: [&str; 3] = ["machines", "storages", "peers"];

/// Multiply-adds per row of one SMAPPO network from its parameter tensors. `robots`: rows
/// per env-step (the critic's global attention runs once per env-step).
fn count(store: &ParamStore, heads: usize, s: Entities, robots: usize) -> Macs {
    let mut m = Macs::default();
    for e in &store.entries {
        if e.shape.len() != 2 {
            continue; // biases, LayerNorm, the critic's global query: no products
        }
        let (out, inp) = (e.shape[0] as f64, e.shape[1] as f64);
        let name = e.name.as_str();
        let group = GROUPS.iter().position(|g| name.contains(g));
        // (keys per query, queries per row)
        let (keys, per_row) = if name.starts_with("global_att.") {
            (robots, 1.0 / robots as f64)
        } else {
            (group.map_or(0, |g| s[g]), 1.0)
        };
        let kf = keys as f64;
        if name.ends_with("self_enc.weight") {
            m.gemm_fwd += out * inp;
            m.gemm_bwd += out * inp; // dW only: its input is the observation
        } else if name.ends_with("_enc.weight") {
            assert!(group.is_some(), "entity encoder of no group: {name}");
            m.row_fwd += kf * out * inp;
            m.row_bwd += 2.0 * kf * out * inp; // recompute + weight gradient
        } else if name.ends_with(".in_proj_weight") {
            assert_eq!(e.shape[0], 3 * e.shape[1], "{name}");
            if keys > 0 {
                let (ee, h) = (inp, heads as f64);
                m.gemm_fwd += 3.0 * ee * ee * per_row;
                m.gemm_bwd += 6.0 * ee * ee * per_row;
                m.row_fwd += 2.0 * h * kf * ee * per_row;
                m.row_bwd += 4.0 * h * kf * ee * per_row;
            }
        } else if name.ends_with(".out_proj.weight") {
            // runs even with no keys (on a zero vector)
            m.gemm_fwd += out * inp * per_row;
            m.gemm_bwd += 2.0 * out * inp * per_row;
        } else if name.starts_with("gru.weight_")
            || name == "encoder.fc.weight"
            || name == "fc.weight"
            || name.ends_with("_out.weight")
        {
            m.gemm_fwd += out * inp;
            m.gemm_bwd += 2.0 * out * inp;
        } else {
            panic!(
                "no counting rule for {name} {:?} (only SMAPPO is modelled)",
                e.shape
            );
        }
    }
    m
}

/// What the networks of `setup` cost per row (actor, critic), built as training builds them.
fn networks(cfg: &TrainConfig, setup: &str) -> (Macs, Macs, Setup, Entities) {
    let sched = parse_curriculum(&format!("{setup}:1000")).unwrap();
    let scenario = ScenarioConfig::default();
    let t = Trainer::new(ModelKind::Smappo, cfg.clone(), scenario.clone(), sched, 0).unwrap();
    let st = t.current_setup();
    let c = sim::Env::new(scenario, st, 0).unwrap().obs_counts();
    let s = [c.machines, c.storages, c.peers];
    let a = count(&t.actor.params, t.actor.arch.heads, s, st.robots);
    let cr = count(&t.critic.params, t.critic.arch.heads, s, st.robots);
    (a, cr, st, s)
}

fn g(x: f64) -> String {
    format!("{:.1} G", x / 1e9)
}

fn k(x: f64) -> String {
    format!("{:.0} k", x / 1e3)
}

fn measure(cfg: &TrainConfig, a: &[String]) {
    let setup = a.first().cloned().unwrap_or_else(|| "6.4_2".into());
    let mut cfg = cfg.clone();
    if let Some(n) = a.get(1).and_then(|x| x.parse().ok()) {
        cfg.n_envs = n;
    }
    if let Some(n) = a.get(2).and_then(|x| x.parse().ok()) {
        cfg.ppo_epoch = n;
    }
    let sched = parse_curriculum(&format!("{setup}:1000000")).unwrap();
    let mut t = Trainer::new(
        ModelKind::Smappo,
        cfg.clone(),
        ScenarioConfig::default(),
        sched,
        0,
    )
    .unwrap();
    let t0 = std::time::Instant::now();
    let st = t.step().unwrap();
    println!(
        "{setup} envs {} epochs {} mini-batches {}: update {:.2} s (rollout {:.2} s, train {:.2} s)",
        cfg.n_envs,
        cfg.ppo_epoch,
        cfg.num_mini_batch,
        t0.elapsed().as_secs_f64(),
        st.rollout_secs,
        st.train_secs
    );
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let cfg = TrainConfig::from_toml(BUNDLED).unwrap();
    if args.first().map(String::as_str) == Some("--measure") {
        return measure(&cfg, &args[1..]);
    }
    if args.first().map(String::as_str) == Some("--fma") {
        return fma_rate();
    }
    let ghz: f64 = args.first().and_then(|x| x.parse().ok()).unwrap_or(2.1);
    let cores: f64 = args.get(1).and_then(|x| x.parse().ok()).unwrap_or(2.0);
    // 2 FMA units x 16 f32 lanes (AVX-512) per cycle and core, one multiply-add each
    let peak = cores * 2.0 * 16.0 * ghz * 1e9;
    println!(
        "peak: {cores} cores x 2 FMA x 16 lanes x {ghz} GHz = {:.1} G multiply-adds/s \
         ({:.1} GFLOP/s)\n",
        peak / 1e9,
        2.0 * peak / 1e9
    );
    let steps = ScenarioConfig::default().world.episode_steps as f64;
    println!(
        "bundled config: n_envs {}, ppo_epoch {}, num_mini_batch {}, episode {steps} steps\n",
        cfg.n_envs, cfg.ppo_epoch, cfg.num_mini_batch
    );
    println!(
        "| setup | entities (m, s, p) | actor fwd / bwd | critic fwd / bwd | per row and epoch \
         | rollout per agent-step | of which GEMM |"
    );
    println!("|---|---|---|---|---|---|---|");
    let mut per_setup = vec![];
    for setup in ["6.4_2", "100.16_2"] {
        let (a, c, st, s) = networks(&cfg, setup);
        let epoch_row = a.total() + c.total();
        let gemm = a.gemm_fwd + a.gemm_bwd + c.gemm_fwd + c.gemm_bwd;
        println!(
            "| {setup} | {s:?} | {} / {} | {} / {} | {} | {} | {:.0} % |",
            k(a.fwd()),
            k(a.bwd()),
            k(c.fwd()),
            k(c.bwd()),
            k(epoch_row),
            k(a.fwd() + c.fwd()),
            100.0 * gemm / epoch_row
        );
        let rows = cfg.n_envs as f64 * steps * st.robots as f64;
        // the epochs go over every row; the rollout is a forward step per row plus the
        // bootstrap critic step
        let train = cfg.ppo_epoch as f64 * rows * epoch_row;
        let rollout = rows * (a.fwd() + c.fwd()) + cfg.n_envs as f64 * st.robots as f64 * c.fwd();
        per_setup.push((setup, rows, train, rollout));
    }
    println!(
        "\n| setup | rows per update | multiply-adds per update: epochs / rollout | floor at peak: \
         epochs / rollout |"
    );
    println!("|---|---|---|---|");
    for (setup, rows, train, rollout) in &per_setup {
        println!(
            "| {setup} | {rows} | {} / {} | {:.3} s / {:.4} s |",
            g(*train),
            g(*rollout),
            train / peak,
            rollout / peak
        );
    }
    let (_, rows6, train6, roll6) = per_setup[0];
    let (_, _, train100, roll100) = per_setup[1];
    let envs = cfg.n_envs as f64;
    let (u_b, u_c) = ((2000.0 / envs).ceil(), (100.0 / envs).ceil());
    let targets = [
        (
            "(a) >= 15,600 agent-steps/s at 6.4_2 (one update)".to_string(),
            rows6 / 15_600.0,
            train6,
            roll6,
        ),
        (
            format!("(b) 2,000 episodes of 6.4_2 under 3 min ({u_b} updates)"),
            180.0,
            u_b * train6,
            u_b * roll6,
        ),
        (
            format!("(c) 100 episodes of 100.16_2 under 10 min ({u_c} updates)"),
            600.0,
            u_c * train100,
            u_c * roll100,
        ),
    ];
    println!(
        "\n| target | budget | multiply-adds: epochs / rollout | floor at peak: epochs / rollout \
         | epochs' floor / budget |"
    );
    println!("|---|---|---|---|---|");
    for (what, budget, train, rollout) in targets {
        println!(
            "| {what} | {budget:.3} s | {} / {} | {:.3} s / {:.3} s | {:.2} |",
            g(train),
            g(rollout),
            train / peak,
            rollout / peak,
            train / peak / budget
        );
    }
}

/// Measured AVX-512 FMA throughput: 12 independent chains of `vfmadd` per thread (enough
/// to cover 2 ports x 4 cycles latency), on 1 and on 2 threads.
fn fma_rate() {
    #[cfg(target_arch = "x86_64")]
    {
        if !std::arch::is_x86_feature_detected!("avx512f") {
            println!("no avx512f");
            return;
        }
        const ITERS: usize = 100_000_000;
        #[target_feature(enable = "avx512f")]
        unsafe fn run() -> f32 {
            use std::arch::x86_64::*;
            let mut acc = [_mm512_set1_ps(0.0); 12];
            let (a, b) = (_mm512_set1_ps(0.999_999), _mm512_set1_ps(1e-7));
            for _ in 0..ITERS {
                for x in acc.iter_mut() {
                    *x = _mm512_fmadd_ps(*x, a, b);
                }
            }
            let mut s = 0.0;
            for x in acc {
                s += _mm512_reduce_add_ps(x);
            }
            s
        }
        let once = || {
            // SAFETY: avx512f was detected above.
            std::hint::black_box(unsafe { run() });
        };
        let macs = (ITERS * 12 * 16) as f64;
        for threads in [1usize, 2] {
            let t0 = std::time::Instant::now();
            std::thread::scope(|s| {
                for _ in 0..threads {
                    s.spawn(once);
                }
            });
            let dt = t0.elapsed().as_secs_f64();
            let rate = threads as f64 * macs / dt;
            println!(
                "{threads} thread(s): {:.1} G multiply-adds/s = {:.2} GHz x 2 FMA x 16 lanes \
                 per thread ({dt:.2} s)",
                rate / 1e9,
                rate / threads as f64 / 32.0 / 1e9
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use policy::{ArchConfig, Critic};

    fn tiny() -> ArchConfig {
        ArchConfig {
            d_model: 8,
            heads: 2,
            hidden: 4,
            ..ArchConfig::smappo()
        }
    }

    /// d 8, 2 heads, hidden 4, 5 actions; 1 machine, 1 storage, 1 peer (2 robots per env).
    #[test]
    fn tiny_actor_by_hand() {
        let a = policy::Actor::new(tiny(), 0);
        let m = count(&a.params, 2, [1, 1, 1], 2);
        // self_enc 8x3 = 24; per group Q, U, O 3 x 8 x 8 = 192 + out_proj 64 = 256, x 3;
        // fc 4 x 8 -> 4 = 128; GRU 12 x 4 twice = 96; action_out 5 x 4 = 20
        assert_eq!(m.gemm_fwd, (24 + 3 * 256 + 128 + 96 + 20) as f64);
        // backward: self_enc dW only 24; everything else twice
        assert_eq!(m.gemm_bwd, (24 + 2 * (3 * 256 + 128 + 96 + 20)) as f64);
        // entity encoders 1 x 8 x (3 + 2 + 3) = 64; scores + sums 2 x 2 heads x 1 x 8 = 32
        // per group
        assert_eq!(m.row_fwd, (64 + 3 * 32) as f64);
        assert_eq!(m.row_bwd, (2 * 64 + 3 * 64) as f64);
    }

    #[test]
    fn tiny_critic_by_hand() {
        let c = Critic::new(tiny(), 0);
        let m = count(&c.params, 2, [1, 1, 1], 2);
        // encoder as the actor's but fc 32 -> 8 = 256; global attention 4 x 64 = 256 per
        // env-step = 128 per row (2 robots); fc 16 -> 4 = 64; GRU 96; value_out 4
        assert_eq!(m.gemm_fwd, (24 + 3 * 256 + 256 + 128 + 64 + 96 + 4) as f64);
        assert_eq!(
            m.gemm_bwd,
            (24 + 2 * (3 * 256 + 256 + 128 + 64 + 96 + 4)) as f64
        );
        // global attention row kernel: 2 x 2 heads x 2 keys x 8 = 64 per env-step = 32 per row
        assert_eq!(m.row_fwd, (64 + 3 * 32 + 32) as f64);
        assert_eq!(m.row_bwd, (2 * 64 + 3 * 64 + 64) as f64);
    }

    #[test]
    fn empty_groups_cost_only_their_out_proj() {
        let a = policy::Actor::new(tiny(), 0);
        let full = count(&a.params, 2, [1, 1, 1], 2);
        let none = count(&a.params, 2, [0, 0, 0], 1);
        assert_eq!(full.gemm_fwd - none.gemm_fwd, (3 * 192) as f64);
        assert_eq!(none.row_fwd, 0.0);
    }
}
