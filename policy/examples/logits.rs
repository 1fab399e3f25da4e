//! The Rust side of the torch/Rust equality test (python/tests/test_smappo_torch.py): the
//! logits of a policy checkpoint for observations given as JSON, and fresh checkpoints to
//! compare on.
//!
//! ```text
//! cargo run --release -p policy --example logits -- CHECKPOINT < cases.json > logits.json
//! cargo run --release -p policy --example logits -- init KIND SEED OUT.safetensors
//! ```
//!
//! Input: `{"cases": [case, ...]}`, a case being `{"machines": M, "storages": K, "peers":
//! P, "rows": B, "steps": [step, ...]}` and a step `{"own": [B*3], "machines": [B*M*3],
//! "storages": [B*K*2], "peers": [B*P*3], "masks": [B]}` (the `obs` crate's layout, row-major;
//! mask 0.0 = that robot's episode starts at this step, its GRU state zeroed first).
//!
//! Output: `{"meta": <the checkpoint's metadata>, "cases": [{"inference": [[B*A], ...],
//! "batched": [[B*A], ...]}, ...]}`, one list of logits per step, by two routes through the
//! same network: `inference` is what robot_node runs ([`policy::Policy::logits`], one robot
//! at a time, a GRU state each, reset where the mask is 0), `batched` the trainer's chunk
//! forward ([`policy::Actor::forward_seq`], all T x B rows at once).
//!
//! `init` writes a fresh actor ([`policy::Actor::new`] from SEED) with every parameter moved
//! by uniform noise in [-0.2, 0.2], so that the output layer (initialised at gain 0.01) and
//! the LayerNorms (at 1 and 0) give logits of order 1 that show a difference. KIND: `smappo`
//! (the paper's, 5 moves), `targets` (the target-action menu), `small` (d_model 16, 2 heads,
//! hidden 24, 9 moves) or `mappo` (flat layout 4 machines, 2 storages, 5 peers; critic 6 robots).
//!
//! The critic likewise, from a trainer state (`tending-trainer-state`, which holds it):
//!
//! ```text
//! logits values TRAINER_STATE < cases.json > values.json
//! logits init-state KIND SEED OUT.safetensors
//! ```
//!
//! A case then also gives `"robots": n`, the robots of one environment (`rows` = envs x n,
//! env-major as `policy::Critic` reads them); the output has `"batched"` only (the critic
//! runs in training alone), one list of B values per step.

use obs::{Counts, ObsBatch};
use policy::checkpoint::save_policy;
use policy::checkpoint::{load_trainer_state, save_trainer_state};
use policy::{ActionSpace, Actor, ArchConfig, Critic, Policy};
use rand::{Rng, SeedableRng};
use serde::Deserialize;
use std::io::Read;

#[derive(Deserialize)]
struct Input {
    cases: Vec<Case>,
}

#[derive(Deserialize)]
struct Case {
    machines: usize,
    storages: usize,
    peers: usize,
    rows: usize,
    #[serde(default)]
    robots: usize,
    steps: Vec<Step>,
}

#[derive(Deserialize)]
struct Step {
    own: Vec<f32>,
    machines: Vec<f32>,
    storages: Vec<f32>,
    peers: Vec<f32>,
    masks: Vec<f32>,
}

type Res<T> = Result<T, Box<dyn std::error::Error>>;

fn step_batch(case: &Case, s: &Step) -> Res<ObsBatch> {
    let counts = Counts {
        machines: case.machines,
        storages: case.storages,
        peers: case.peers,
    };
    let b = ObsBatch {
        rows: case.rows,
        counts,
        own: s.own.clone(),
        machines: s.machines.clone(),
        storages: s.storages.clone(),
        peers: s.peers.clone(),
    };
    b.validate()?;
    if s.masks.len() != case.rows {
        return Err(format!("masks: {} values for {} rows", s.masks.len(), case.rows).into());
    }
    Ok(b)
}

fn run_case(pol: &Policy, case: &Case) -> Res<serde_json::Value> {
    let (b, t) = (case.rows, case.steps.len());
    let steps = case
        .steps
        .iter()
        .map(|s| step_batch(case, s))
        .collect::<Res<Vec<_>>>()?;
    // robot_node's route: one Policy per robot, one row per call
    let mut robots: Vec<(Policy, policy::PolicyState)> = (0..b)
        .map(|_| {
            let p = pol.clone();
            let st = p.new_state();
            (p, st)
        })
        .collect();
    let mut inference = Vec::with_capacity(t);
    for (obs, s) in steps.iter().zip(&case.steps) {
        let mut out = vec![];
        for (r, (p, st)) in robots.iter_mut().enumerate() {
            if s.masks[r] == 0.0 {
                st.reset();
            }
            out.extend_from_slice(p.logits(&obs.row(r), st)?);
        }
        inference.push(out);
    }
    // the trainer's route: T x B rows, step-major, in one forward
    let mut all = ObsBatch::zeros(0, steps[0].counts);
    for obs in &steps {
        all.extend_from(obs)?;
    }
    let masks: Vec<f32> = case.steps.iter().flat_map(|s| s.masks.clone()).collect();
    let mut actor: Actor = pol.actor().clone();
    let h0 = vec![0.0; b * actor.hidden()];
    let y = actor.forward_seq(&all, t, b, &h0, &masks)?;
    let a = y.len() / (t * b).max(1);
    let batched: Vec<Vec<f32>> = (0..t)
        .map(|i| y[i * b * a..(i + 1) * b * a].to_vec())
        .collect();
    Ok(serde_json::json!({ "inference": inference, "batched": batched }))
}

fn arch_of(kind: &str) -> Res<ArchConfig> {
    let mut arch = ArchConfig::smappo();
    match kind {
        "smappo" => {}
        "targets" => {
            arch.n_actions = plan::targets::N_TARGET_ACTIONS;
            arch.actions = ActionSpace::Targets;
        }
        "small" => {
            (arch.d_model, arch.heads, arch.hidden, arch.n_actions) = (16, 2, 24, 9);
        }
        "mappo" => {
            let flat = obs::FlatLayout {
                max_machines: 4,
                max_storages: 2,
                max_peers: 5,
            };
            arch = ArchConfig::mappo(flat, 6);
        }
        _ => return Err(format!("KIND {kind}: smappo, targets, small or mappo").into()),
    }
    Ok(arch)
}

/// Every value moved by uniform noise in [-0.2, 0.2].
fn perturb(data: &mut [f32], seed: u64) {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    for x in data.iter_mut() {
        *x += rng.gen_range(-0.2..=0.2);
    }
}

fn init(kind: &str, seed: &str, out: &str, state: bool) -> Res<()> {
    let seed: u64 = seed.parse().map_err(|e| format!("SEED {seed}: {e}"))?;
    let arch = arch_of(kind)?;
    let mut actor = Actor::new(arch, seed);
    perturb(&mut actor.params.data, seed ^ 0x5eed);
    let training = serde_json::json!({
        "written_by": "policy/examples/logits.rs init",
        "kind": kind,
        "seed": seed,
    });
    if state {
        let mut critic = Critic::new(arch, seed + 1);
        perturb(&mut critic.params.data, seed ^ 0xc417);
        save_trainer_state(std::path::Path::new(out), &actor, &critic, training)?;
    } else {
        save_policy(std::path::Path::new(out), &actor, training)?;
    }
    Ok(())
}

/// The actor and critic architectures of a trainer state, from its metadata.
fn trainer_archs(path: &str) -> Res<(ArchConfig, ArchConfig)> {
    let bytes = std::fs::read(path)?;
    let (_, md) = safetensors::SafeTensors::read_metadata(&bytes)?;
    let json = md
        .metadata()
        .as_ref()
        .and_then(|m| m.get("tending"))
        .ok_or("no `tending` metadata")?;
    let v: serde_json::Value = serde_json::from_str(json)?;
    let arch = |k: &str| serde_json::from_value::<ArchConfig>(v[k].clone());
    Ok((arch("actor_arch")?, arch("critic_arch")?))
}

fn values_case(critic: &mut Critic, case: &Case) -> Res<serde_json::Value> {
    let (b, t, n) = (case.rows, case.steps.len(), case.robots);
    let mut all: Option<ObsBatch> = None;
    for s in &case.steps {
        let obs = step_batch(case, s)?;
        match &mut all {
            None => all = Some(obs),
            Some(a) => a.extend_from(&obs)?,
        }
    }
    let all = all.ok_or("a case without steps")?;
    let masks: Vec<f32> = case.steps.iter().flat_map(|s| s.masks.clone()).collect();
    let h0 = vec![0.0; b * critic.arch.hidden];
    let y = critic.forward_seq(&all, t, b, n, &h0, &masks)?;
    let batched: Vec<Vec<f32>> = (0..t).map(|i| y[i * b..(i + 1) * b].to_vec()).collect();
    Ok(serde_json::json!({ "batched": batched }))
}

fn read_input() -> Res<Input> {
    let mut text = String::new();
    std::io::stdin().read_to_string(&mut text)?;
    Ok(serde_json::from_str(&text)?)
}

fn main() -> Res<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.as_slice() {
        [cmd, kind, seed, out] if cmd == "init" => init(kind, seed, out, false),
        [cmd, kind, seed, out] if cmd == "init-state" => init(kind, seed, out, true),
        [cmd, path] if cmd == "values" => {
            let (aa, ca) = trainer_archs(path)?;
            let (mut actor, mut critic) = (Actor::new(aa, 0), Critic::new(ca, 0));
            load_trainer_state(std::path::Path::new(path), &mut actor, &mut critic)?;
            let cases = read_input()?
                .cases
                .iter()
                .map(|c| values_case(&mut critic, c))
                .collect::<Res<Vec<_>>>()?;
            println!("{}", serde_json::json!({ "cases": cases }));
            Ok(())
        }
        [ckpt] => {
            let pol = Policy::load(ckpt)?;
            let input = read_input()?;
            let cases = input
                .cases
                .iter()
                .map(|c| run_case(&pol, c))
                .collect::<Res<Vec<_>>>()?;
            let out = serde_json::json!({ "meta": pol.meta(), "cases": cases });
            println!("{out}");
            Ok(())
        }
        _ => Err(
            "usage: logits CHECKPOINT < cases.json | logits values TRAINER_STATE < cases.json \
             | logits init KIND SEED OUT | logits init-state KIND SEED OUT"
                .into(),
        ),
    }
}
