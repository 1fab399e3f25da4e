//! Checkpoint tests: round trips, refused tensors, files and metadata, exact trainer-state
//! resume.

use super::*;
use crate::net_tests::{rand_obs, small_arch};
use crate::{ActMode, Policy, Sequences};
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
        Err(CheckpointError::Input(inputs::InputError::Missing { .. }))
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
            let seq = Sequences::new(&obs, 2, 2, &h0, &masks);
            a.ppo_grads(
                seq,
                &[0, 1, 2, 3],
                &old,
                &[1.0, -1.0, 0.5, 2.0],
                Default::default(),
            )
            .unwrap();
            a.step(10.0);
            c.value_grads(seq, 2, &[0.0; 4], &[1.0; 4], Default::default())
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
