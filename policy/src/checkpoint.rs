//! Checkpoints as safetensors files.
//!
//! Policy checkpoint (what `robot_node` loads): one F32 tensor per actor parameter under its
//! readable name (`encoder.att_machines.in_proj_weight`, `gru.weight_hh_l0`, ...), and
//! `__metadata__` = { "format": "tending-policy", "tending": <JSON [`CheckpointMeta`]> }.
//!
//! Trainer state (resume a run exactly): actor and critic parameters plus Adam moments
//! (`actor.param.<name>`, `actor.adam_m.<name>`, `actor.adam_v.<name>`, same for `critic.`)
//! and `__metadata__` = { "format": "tending-trainer-state", "tending": <JSON> } with both
//! architectures, the Adam step counts and configs, and a free-form `extra` object.
//!
//! Loading never panics on bad input: every problem is a [`CheckpointError`] naming it.

use crate::config::{ArchConfig, ModelKind};
use crate::nn::{AdamConfig, ParamStore};
use crate::{Actor, Critic};
use safetensors::tensor::{Dtype, SafeTensors, TensorView};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};

pub const FORMAT_VERSION: u32 = 1;
const POLICY_FORMAT: &str = "tending-policy";
const TRAINER_FORMAT: &str = "tending-trainer-state";

#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    #[error("cannot access checkpoint {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("checkpoint is not a valid safetensors file (truncated or corrupt?): {0}")]
    Corrupt(String),
    #[error("checkpoint metadata: {0}")]
    Metadata(String),
    #[error("checkpoint format version {found} is not supported (this build reads {expected})")]
    Version { found: u32, expected: u32 },
    #[error("checkpoint holds a {found} model, expected {expected}")]
    WrongKind {
        expected: ModelKind,
        found: ModelKind,
    },
    #[error("checkpoint architecture is not usable: {0}")]
    Architecture(String),
    #[error("checkpoint is missing tensor `{0}`")]
    MissingTensor(String),
    #[error("checkpoint has unexpected tensor `{0}` (not part of this architecture)")]
    ExtraTensor(String),
    #[error("tensor `{name}` has shape {found:?}, expected {expected:?}")]
    Shape {
        name: String,
        expected: Vec<usize>,
        found: Vec<usize>,
    },
    #[error("tensor `{name}` has dtype {found}, expected F32")]
    DType { name: String, found: String },
    #[error("tensor `{name}` has a non-finite value ({value}) at index {index}")]
    NonFinite {
        name: String,
        index: usize,
        value: f32,
    },
}

/// Observation layout a checkpoint was trained on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObsLayoutMeta {
    pub self_dim: usize,
    pub machine_dim: usize,
    pub storage_dim: usize,
    pub peer_dim: usize,
}

impl ObsLayoutMeta {
    pub fn current() -> Self {
        Self {
            self_dim: obs::SELF_DIM,
            machine_dim: obs::MACHINE_DIM,
            storage_dim: obs::STORAGE_DIM,
            peer_dim: obs::PEER_DIM,
        }
    }
}

/// The JSON carried in a policy checkpoint's metadata.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CheckpointMeta {
    pub format_version: u32,
    pub model_kind: ModelKind,
    pub arch: ArchConfig,
    pub obs_layout: ObsLayoutMeta,
    /// Free-form training setup (setup name, episodes, seed, k_speed...), filled by the
    /// trainer; `null` when absent.
    #[serde(default)]
    pub training: serde_json::Value,
}

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn write(
    path: &Path,
    tensors: Vec<(String, Vec<usize>, Vec<u8>)>,
    meta: HashMap<String, String>,
) -> Result<(), CheckpointError> {
    let views: Vec<(String, TensorView)> = tensors
        .iter()
        .map(|(n, s, b)| {
            TensorView::new(Dtype::F32, s.clone(), b)
                .map(|v| (n.clone(), v))
                .map_err(|e| CheckpointError::Corrupt(e.to_string()))
        })
        .collect::<Result<_, _>>()?;
    let bytes = safetensors::serialize(views, &Some(meta))
        .map_err(|e| CheckpointError::Corrupt(e.to_string()))?;
    // write to a temporary file then rename, so a crash never leaves a half-written file
    let tmp = path.with_extension("safetensors.tmp");
    std::fs::write(&tmp, bytes)
        .and_then(|_| std::fs::rename(&tmp, path))
        .map_err(|source| CheckpointError::Io {
            path: path.to_path_buf(),
            source,
        })
}

fn store_tensors(
    store: &ParamStore,
    prefix: &str,
    values: &[f32],
) -> Vec<(String, Vec<usize>, Vec<u8>)> {
    store
        .entries
        .iter()
        .map(|e| {
            (
                format!("{prefix}{}", e.name),
                e.shape.clone(),
                f32_bytes(&values[e.slot.r()]),
            )
        })
        .collect()
}

/// Save the actor of a policy checkpoint. `training` is the trainer's free-form setup
/// (use `serde_json::Value::Null` for none).
pub fn save_policy(
    path: &Path,
    actor: &Actor,
    training: serde_json::Value,
) -> Result<(), CheckpointError> {
    let meta = CheckpointMeta {
        format_version: FORMAT_VERSION,
        model_kind: actor.arch.kind,
        arch: actor.arch,
        obs_layout: ObsLayoutMeta::current(),
        training,
    };
    let json =
        serde_json::to_string(&meta).map_err(|e| CheckpointError::Metadata(e.to_string()))?;
    let md = HashMap::from([
        ("format".to_string(), POLICY_FORMAT.to_string()),
        ("tending".to_string(), json),
    ]);
    write(
        path,
        store_tensors(&actor.params, "", &actor.params.data),
        md,
    )
}

fn read(path: &Path) -> Result<Vec<u8>, CheckpointError> {
    std::fs::read(path).map_err(|source| CheckpointError::Io {
        path: path.to_path_buf(),
        source,
    })
}

fn parse_meta(bytes: &[u8], format: &str) -> Result<serde_json::Value, CheckpointError> {
    let (_, md) =
        SafeTensors::read_metadata(bytes).map_err(|e| CheckpointError::Corrupt(e.to_string()))?;
    let md = md
        .metadata()
        .as_ref()
        .ok_or_else(|| CheckpointError::Metadata("no __metadata__".into()))?;
    let f = md.get("format").map(String::as_str).unwrap_or("<absent>");
    if f != format {
        return Err(CheckpointError::Metadata(format!(
            "format is `{f}`, expected `{format}`"
        )));
    }
    let json = md
        .get("tending")
        .ok_or_else(|| CheckpointError::Metadata("no `tending` entry".into()))?;
    let v: serde_json::Value = serde_json::from_str(json)
        .map_err(|e| CheckpointError::Metadata(format!("invalid JSON: {e}")))?;
    let version = v
        .get("format_version")
        .and_then(|x| x.as_u64())
        .unwrap_or(0) as u32;
    if version != FORMAT_VERSION {
        return Err(CheckpointError::Version {
            found: version,
            expected: FORMAT_VERSION,
        });
    }
    Ok(v)
}

/// Refuse architectures that would panic or allocate absurdly when built.
fn check_arch(a: &ArchConfig) -> Result<(), CheckpointError> {
    let bad = |m: &str| Err(CheckpointError::Architecture(m.to_string()));
    let lim = 4096;
    if a.d_model == 0 || a.hidden == 0 || a.n_actions == 0 || a.heads == 0 {
        return bad("zero dimension");
    }
    if a.d_model > lim || a.hidden > lim || a.n_actions > 256 || a.heads > a.d_model {
        return bad("dimension out of range");
    }
    if !a.actions.allows(a.n_actions) {
        return Err(CheckpointError::Architecture(format!(
            "{} outputs do not fit the action space {:?}",
            a.n_actions, a.actions
        )));
    }
    if !a.d_model.is_multiple_of(a.heads) {
        return bad("d_model is not a multiple of heads");
    }
    if a.kind == ModelKind::Mappo {
        let Some(f) = a.flat else {
            return bad("MAPPO without a flat observation layout");
        };
        let Some(r) = a.max_robots else {
            return bad("MAPPO without max_robots");
        };
        if f.max_machines > lim || f.max_storages > lim || f.max_peers > lim || r > lim {
            return bad("MAPPO layout out of range");
        }
    }
    Ok(())
}

/// Copy the tensors `prefix<name>` of `st` into `dst` (laid out as `store`), checking
/// presence, dtype, shape and finiteness. Returns the names consumed.
fn load_into(
    st: &SafeTensors,
    store: &ParamStore,
    prefix: &str,
    dst: &mut [f32],
    seen: &mut BTreeSet<String>,
) -> Result<(), CheckpointError> {
    for e in &store.entries {
        let name = format!("{prefix}{}", e.name);
        let t = st
            .tensor(&name)
            .map_err(|_| CheckpointError::MissingTensor(name.clone()))?;
        if t.dtype() != Dtype::F32 {
            return Err(CheckpointError::DType {
                name,
                found: format!("{:?}", t.dtype()),
            });
        }
        if t.shape() != e.shape.as_slice() {
            return Err(CheckpointError::Shape {
                name,
                expected: e.shape.clone(),
                found: t.shape().to_vec(),
            });
        }
        let out = &mut dst[e.slot.r()];
        for (i, (o, c)) in out.iter_mut().zip(t.data().chunks_exact(4)).enumerate() {
            let v = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
            if !v.is_finite() {
                return Err(CheckpointError::NonFinite {
                    name,
                    index: i,
                    value: v,
                });
            }
            *o = v;
        }
        seen.insert(name);
    }
    Ok(())
}

fn no_extra(st: &SafeTensors, seen: &BTreeSet<String>) -> Result<(), CheckpointError> {
    let mut names = st.names();
    names.sort();
    match names.into_iter().find(|n| !seen.contains(*n)) {
        Some(n) => Err(CheckpointError::ExtraTensor(n.clone())),
        None => Ok(()),
    }
}

/// Load a policy checkpoint's actor (with a fresh optimizer) and its metadata.
/// With `expect = Some(kind)`, a checkpoint of another kind is refused.
pub fn load_policy(
    path: &Path,
    expect: Option<ModelKind>,
) -> Result<(Actor, CheckpointMeta), CheckpointError> {
    let bytes = read(path)?;
    let v = parse_meta(&bytes, POLICY_FORMAT)?;
    let meta: CheckpointMeta =
        serde_json::from_value(v).map_err(|e| CheckpointError::Metadata(e.to_string()))?;
    if let Some(k) = expect {
        if k != meta.model_kind {
            return Err(CheckpointError::WrongKind {
                expected: k,
                found: meta.model_kind,
            });
        }
    }
    if meta.arch.kind != meta.model_kind {
        return Err(CheckpointError::Architecture(
            "model_kind disagrees with arch.kind".into(),
        ));
    }
    if meta.obs_layout != ObsLayoutMeta::current() {
        return Err(CheckpointError::Architecture(format!(
            "observation layout {:?} differs from this build's {:?}",
            meta.obs_layout,
            ObsLayoutMeta::current()
        )));
    }
    check_arch(&meta.arch)?;
    let st =
        SafeTensors::deserialize(&bytes).map_err(|e| CheckpointError::Corrupt(e.to_string()))?;
    let mut actor = Actor::new(meta.arch, 0);
    let mut data = std::mem::take(&mut actor.params.data);
    let mut seen = BTreeSet::new();
    load_into(&st, &actor.params, "", &mut data, &mut seen)?;
    actor.params.data = data;
    no_extra(&st, &seen)?;
    Ok((actor, meta))
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct TrainerMeta {
    format_version: u32,
    actor_arch: ArchConfig,
    critic_arch: ArchConfig,
    actor_adam: AdamConfig,
    critic_adam: AdamConfig,
    actor_adam_t: u64,
    critic_adam_t: u64,
    #[serde(default)]
    extra: serde_json::Value,
}

/// Save actor + critic parameters and Adam state; `extra` is free-form (iteration,
/// RNG seeds, value normaliser...).
pub fn save_trainer_state(
    path: &Path,
    actor: &Actor,
    critic: &Critic,
    extra: serde_json::Value,
) -> Result<(), CheckpointError> {
    let meta = TrainerMeta {
        format_version: FORMAT_VERSION,
        actor_arch: actor.arch,
        critic_arch: critic.arch,
        actor_adam: actor.opt.cfg,
        critic_adam: critic.opt.cfg,
        actor_adam_t: actor.opt.t,
        critic_adam_t: critic.opt.t,
        extra,
    };
    let mut t = vec![];
    for (pre, store, opt) in [
        ("actor", &actor.params, &actor.opt),
        ("critic", &critic.params, &critic.opt),
    ] {
        t.extend(store_tensors(store, &format!("{pre}.param."), &store.data));
        t.extend(store_tensors(store, &format!("{pre}.adam_m."), &opt.m));
        t.extend(store_tensors(store, &format!("{pre}.adam_v."), &opt.v));
    }
    let json =
        serde_json::to_string(&meta).map_err(|e| CheckpointError::Metadata(e.to_string()))?;
    let md = HashMap::from([
        ("format".to_string(), TRAINER_FORMAT.to_string()),
        ("tending".to_string(), json),
    ]);
    write(path, t, md)
}

/// The free-form `extra` object of a trainer state, read without touching any network
/// (the trainer needs it to build networks of the right shape before loading them).
pub fn read_trainer_extra(path: &Path) -> Result<serde_json::Value, CheckpointError> {
    let bytes = read(path)?;
    let v = parse_meta(&bytes, TRAINER_FORMAT)?;
    let meta: TrainerMeta =
        serde_json::from_value(v).map_err(|e| CheckpointError::Metadata(e.to_string()))?;
    Ok(meta.extra)
}

/// Restore a state saved by [`save_trainer_state`] into networks of the same
/// architectures (refused otherwise). Returns the `extra` object.
pub fn load_trainer_state(
    path: &Path,
    actor: &mut Actor,
    critic: &mut Critic,
) -> Result<serde_json::Value, CheckpointError> {
    let bytes = read(path)?;
    let v = parse_meta(&bytes, TRAINER_FORMAT)?;
    let meta: TrainerMeta =
        serde_json::from_value(v).map_err(|e| CheckpointError::Metadata(e.to_string()))?;
    if meta.actor_arch != actor.arch || meta.critic_arch != critic.arch {
        return Err(CheckpointError::Architecture(format!(
            "trainer state is for actor {:?} / critic {:?}",
            meta.actor_arch, meta.critic_arch
        )));
    }
    let st =
        SafeTensors::deserialize(&bytes).map_err(|e| CheckpointError::Corrupt(e.to_string()))?;
    let mut seen = BTreeSet::new();
    // load into copies first so a failure leaves the networks untouched
    let mut bufs = vec![];
    for (pre, store) in [("actor", &actor.params), ("critic", &critic.params)] {
        for kind in ["param", "adam_m", "adam_v"] {
            let mut b = vec![0.0; store.len()];
            load_into(&st, store, &format!("{pre}.{kind}."), &mut b, &mut seen)?;
            bufs.push(b);
        }
    }
    no_extra(&st, &seen)?;
    let mut it = bufs.into_iter();
    let mut next = || it.next().expect("six buffers");
    actor.params.data = next();
    actor.opt.m = next();
    actor.opt.v = next();
    critic.params.data = next();
    critic.opt.m = next();
    critic.opt.v = next();
    actor.opt.cfg = meta.actor_adam;
    critic.opt.cfg = meta.critic_adam;
    actor.opt.t = meta.actor_adam_t;
    critic.opt.t = meta.critic_adam_t;
    actor.params.zero_grad();
    critic.params.zero_grad();
    Ok(meta.extra)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::net_tests::{rand_obs, small_arch};
    use crate::{ActMode, Policy};
    use obs::Counts;

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("policy-ckpt-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d.join(name)
    }

    type Parts = (Vec<(String, Vec<usize>, Vec<u8>)>, HashMap<String, String>);

    fn parts(actor: &Actor) -> Parts {
        let meta = CheckpointMeta {
            format_version: FORMAT_VERSION,
            model_kind: actor.arch.kind,
            arch: actor.arch,
            obs_layout: ObsLayoutMeta::current(),
            training: serde_json::Value::Null,
        };
        let md = HashMap::from([
            ("format".to_string(), POLICY_FORMAT.to_string()),
            ("tending".to_string(), serde_json::to_string(&meta).unwrap()),
        ]);
        (store_tensors(&actor.params, "", &actor.params.data), md)
    }

    fn err_of(path: &Path) -> String {
        load_policy(path, None).unwrap_err().to_string()
    }

    #[test]
    fn roundtrip_keeps_weights_metadata_and_decisions() {
        let c = Counts {
            machines: 3,
            storages: 2,
            peers: 2,
        };
        for kind in [ModelKind::Smappo, ModelKind::Mappo] {
            let actor = Actor::new(small_arch(kind), 5);
            let p = tmp(&format!("rt-{kind}.safetensors"));
            let setup = serde_json::json!({"setup": "14.10_4", "seed": 3, "k_speed": 1.0});
            save_policy(&p, &actor, setup.clone()).unwrap();
            let mut pol = Policy::load(&p).unwrap();
            assert_eq!(pol.kind(), kind);
            assert_eq!(pol.meta().training, setup);
            assert_eq!(pol.actor().params.data, actor.params.data);
            let mut direct = Policy::from_actor(actor.clone(), serde_json::Value::Null);
            let (mut s1, mut s2) = (pol.new_state(), direct.new_state());
            for i in 0..5 {
                let o = rand_obs(1, c, 100 + i);
                let a = pol.act(&o, &mut s1, ActMode::Greedy).unwrap();
                let b = direct.act(&o, &mut s2, ActMode::Greedy).unwrap();
                assert_eq!(a, b);
                assert_eq!(s1, s2);
            }
            let other = if kind == ModelKind::Smappo {
                ModelKind::Mappo
            } else {
                ModelKind::Smappo
            };
            let e = Policy::load_expecting(&p, other).unwrap_err();
            assert!(matches!(e, CheckpointError::WrongKind { .. }), "{e}");
        }
    }

    #[test]
    fn refuses_missing_extra_misshapen_and_nonfinite_tensors() {
        let actor = Actor::new(small_arch(ModelKind::Smappo), 1);
        let p = tmp("bad.safetensors");
        let (t, md) = parts(&actor);

        let mut missing = t.clone();
        let gone = missing.remove(3).0;
        write(&p, missing, md.clone()).unwrap();
        let e = err_of(&p);
        assert!(e.contains("missing") && e.contains(&gone), "{e}");

        let mut extra = t.clone();
        extra.push(("rogue.weight".into(), vec![2], f32_bytes(&[1.0, 2.0])));
        write(&p, extra, md.clone()).unwrap();
        let e = err_of(&p);
        assert!(
            e.contains("unexpected") && e.contains("rogue.weight"),
            "{e}"
        );

        let mut shape = t.clone();
        let i = shape
            .iter()
            .position(|x| x.0 == "gru.weight_hh_l0")
            .unwrap();
        let n = shape[i].1.iter().product::<usize>();
        shape[i].1 = vec![n];
        write(&p, shape, md.clone()).unwrap();
        let e = err_of(&p);
        assert!(e.contains("gru.weight_hh_l0") && e.contains("shape"), "{e}");

        let mut nan = t.clone();
        let i = nan.iter().position(|x| x.0 == "action_out.bias").unwrap();
        nan[i].2[4..8].copy_from_slice(&f32::NAN.to_le_bytes());
        write(&p, nan, md.clone()).unwrap();
        let e = err_of(&p);
        assert!(
            e.contains("action_out.bias") && e.contains("non-finite"),
            "{e}"
        );

        let mut inf = t.clone();
        inf[0].2[0..4].copy_from_slice(&f32::INFINITY.to_le_bytes());
        write(&p, inf, md.clone()).unwrap();
        assert!(err_of(&p).contains(&t[0].0));
    }

    #[test]
    fn refuses_truncated_corrupt_and_foreign_files() {
        let actor = Actor::new(small_arch(ModelKind::Mappo), 1);
        let p = tmp("trunc.safetensors");
        save_policy(&p, &actor, serde_json::Value::Null).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() - 7]).unwrap();
        assert!(matches!(
            load_policy(&p, None),
            Err(CheckpointError::Corrupt(_))
        ));
        std::fs::write(&p, &bytes[..5]).unwrap();
        assert!(matches!(
            load_policy(&p, None),
            Err(CheckpointError::Corrupt(_))
        ));
        let mut garbage = bytes.clone();
        garbage[9] = b'#';
        std::fs::write(&p, &garbage).unwrap();
        assert!(load_policy(&p, None).is_err());
        assert!(matches!(
            load_policy(&tmp("does-not-exist"), None),
            Err(CheckpointError::Io { .. })
        ));
    }

    #[test]
    fn refuses_bad_metadata() {
        let actor = Actor::new(small_arch(ModelKind::Smappo), 1);
        let p = tmp("meta.safetensors");
        let (t, md) = parts(&actor);
        let edit = |f: &dyn Fn(&mut serde_json::Value)| {
            let mut v: serde_json::Value = serde_json::from_str(&md["tending"]).unwrap();
            f(&mut v);
            let mut m = md.clone();
            m.insert("tending".into(), v.to_string());
            write(&p, t.clone(), m).unwrap();
            err_of(&p)
        };
        assert!(edit(&|v| v["format_version"] = 99.into()).contains("version 99"));
        assert!(edit(&|v| v["arch"]["heads"] = 3.into()).contains("multiple of heads"));
        assert!(edit(&|v| v["arch"]["kind"] = "mappo".into()).contains("disagrees"));
        assert!(edit(&|v| v["model_kind"] = "transformer".into()).contains("metadata"));
        assert!(edit(&|v| v["obs_layout"]["peer_dim"] = 4.into()).contains("observation layout"));
        // a SMAPPO checkpoint's tensors under MAPPO metadata: architecture mismatch
        let e = edit(&|v| {
            v["model_kind"] = "mappo".into();
            v["arch"] = serde_json::to_value(small_arch(ModelKind::Mappo)).unwrap();
        });
        assert!(e.contains("missing tensor"), "{e}");
        let mut m = md.clone();
        m.insert("format".into(), "something-else".into());
        write(&p, t.clone(), m).unwrap();
        assert!(err_of(&p).contains("format"));
    }

    #[test]
    fn trainer_state_resumes_exactly() {
        let arch = small_arch(ModelKind::Smappo);
        let obs = rand_obs(
            4,
            Counts {
                machines: 2,
                storages: 1,
                peers: 1,
            },
            9,
        );
        let h0 = vec![0.0; 2 * 8];
        let masks = vec![1.0; 4];
        let train = |a: &mut Actor, c: &mut Critic, steps: usize| {
            for _ in 0..steps {
                let old = vec![-1.6; 4];
                a.ppo_grads(
                    &obs,
                    2,
                    2,
                    &h0,
                    &masks,
                    &[0, 1, 2, 3],
                    &old,
                    &[1.0, -1.0, 0.5, 2.0],
                    Default::default(),
                )
                .unwrap();
                a.step(10.0);
                c.value_grads(
                    &obs,
                    2,
                    2,
                    2,
                    &h0,
                    &masks,
                    &[0.0; 4],
                    &[1.0; 4],
                    Default::default(),
                )
                .unwrap();
                c.step(10.0);
            }
        };
        let (mut a, mut c) = (Actor::new(arch, 1), Critic::new(arch, 2));
        train(&mut a, &mut c, 3);
        let p = tmp("trainer.safetensors");
        save_trainer_state(&p, &a, &c, serde_json::json!({"iteration": 3})).unwrap();
        train(&mut a, &mut c, 3);
        let (mut a2, mut c2) = (Actor::new(arch, 77), Critic::new(arch, 78));
        let extra = load_trainer_state(&p, &mut a2, &mut c2).unwrap();
        assert_eq!(extra["iteration"], 3);
        assert_eq!(a2.opt.t, 3);
        train(&mut a2, &mut c2, 3);
        assert_eq!(a.params.data, a2.params.data);
        assert_eq!(c.params.data, c2.params.data);
        assert_eq!(a.opt, a2.opt);
        // a different architecture is refused, leaving the networks untouched
        let mut other = Actor::new(small_arch(ModelKind::Mappo), 1);
        let before = other.params.data.clone();
        assert!(load_trainer_state(&p, &mut other, &mut c2).is_err());
        assert_eq!(other.params.data, before);
        // a policy file is not a trainer state
        save_policy(&p, &a, serde_json::Value::Null).unwrap();
        assert!(load_trainer_state(&p, &mut a2, &mut c2).is_err());
    }
}

#[cfg(test)]
mod action_space_tests {
    use super::check_arch;
    use crate::{ActionSpace, ArchConfig};

    /// Outputs must fit what they mean: 5 or 9 moves, 7 targets; a checkpoint written
    /// before the field existed reads as moves.
    #[test]
    fn outputs_must_fit_the_action_space() {
        let mut a = ArchConfig::smappo();
        assert!(check_arch(&a).is_ok());
        a.n_actions = 9;
        assert!(check_arch(&a).is_ok());
        a.actions = ActionSpace::Targets;
        let e = check_arch(&a).unwrap_err().to_string();
        assert!(e.contains("9 outputs") && e.contains("Targets"), "{e}");
        a.n_actions = obs::targets::N_TARGET_ACTIONS;
        assert!(check_arch(&a).is_ok());
        a.actions = ActionSpace::Moves;
        assert!(check_arch(&a).is_err());
        let mut json = serde_json::to_value(ArchConfig::smappo()).unwrap();
        json.as_object_mut().unwrap().remove("actions");
        let old: ArchConfig = serde_json::from_value(json).unwrap();
        assert_eq!(old.actions, ActionSpace::Moves);
    }
}
