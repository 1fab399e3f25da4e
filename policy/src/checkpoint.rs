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
use crate::{Actor, Critic};
use nn::{AdamConfig, ParamStore};
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
    #[error(transparent)]
    Input(#[from] inputs::InputError),
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
    Ok(inputs::read_bytes("checkpoint", path)?)
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
mod tests;

#[cfg(test)]
mod action_space_tests {
    use super::check_arch;
    use crate::{ActionSpace, ArchConfig};

    /// Outputs must fit what they mean: 5 or 9 moves, 8 targets (or the older 7); a checkpoint written
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
        a.n_actions = plan::targets::N_TARGET_ACTIONS;
        assert!(check_arch(&a).is_ok());
        a.actions = ActionSpace::Moves;
        assert!(check_arch(&a).is_err());
        let mut json = serde_json::to_value(ArchConfig::smappo()).unwrap();
        json.as_object_mut().unwrap().remove("actions");
        let old: ArchConfig = serde_json::from_value(json).unwrap();
        assert_eq!(old.actions, ActionSpace::Moves);
    }
}
