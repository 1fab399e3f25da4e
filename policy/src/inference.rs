//! On-robot inference: load a checkpoint, keep a GRU state per robot, pick actions.
//! After the first call with given counts, `act` does not allocate.

use crate::checkpoint::{load_policy, CheckpointError, CheckpointMeta};
use crate::config::ModelKind;
use crate::error::PolicyError;
use crate::Actor;
use nn::categorical;
use obs::ObsBatch;
use std::path::Path;

/// Recurrent state of one robot (GRU hidden, zero at the start of an episode).
#[derive(Debug, Clone, PartialEq)]
pub struct PolicyState {
    pub h: Vec<f32>,
}

impl PolicyState {
    /// Zero the hidden state (a new episode).
    pub fn reset(&mut self) {
        self.h.iter_mut().for_each(|v| *v = 0.0);
    }
}

/// How to pick the action from the logits.
pub enum ActMode<'a> {
    /// Most probable action (deployment default).
    Greedy,
    /// Sample from the categorical distribution.
    Sample(&'a mut dyn rand::RngCore),
}

/// A frozen actor, SMAPPO or MAPPO.
#[derive(Debug, Clone)]
pub struct Policy {
    actor: Actor,
    meta: CheckpointMeta,
}

impl Policy {
    /// Load a policy checkpoint (either kind).
    pub fn load(path: impl AsRef<Path>) -> Result<Policy, CheckpointError> {
        let (actor, meta) = load_policy(path.as_ref(), None)?;
        Ok(Policy { actor, meta })
    }

    /// Load, refusing a checkpoint of another kind.
    pub fn load_expecting(
        path: impl AsRef<Path>,
        kind: ModelKind,
    ) -> Result<Policy, CheckpointError> {
        let (actor, meta) = load_policy(path.as_ref(), Some(kind))?;
        Ok(Policy { actor, meta })
    }

    /// Wrap a trained actor (e.g. for evaluation without a file round trip).
    pub fn from_actor(actor: Actor, training: serde_json::Value) -> Policy {
        let meta = CheckpointMeta {
            format_version: crate::checkpoint::FORMAT_VERSION,
            model_kind: actor.arch.kind,
            arch: actor.arch,
            obs_layout: crate::checkpoint::ObsLayoutMeta::current(),
            training,
        };
        Policy { actor, meta }
    }

    pub fn kind(&self) -> ModelKind {
        self.meta.model_kind
    }

    pub fn meta(&self) -> &CheckpointMeta {
        &self.meta
    }

    pub fn actor(&self) -> &Actor {
        &self.actor
    }

    /// Whether the checkpoint was trained with the ORCA safety filter in its action path
    /// (`train_config.orca_filter` in its training metadata): such a policy learned with
    /// the filter as part of its world, so evaluation and robot_node run it behind the
    /// filter unless told otherwise.
    pub fn trained_with_orca_filter(&self) -> bool {
        self.meta
            .training
            .pointer("/train_config/orca_filter")
            .and_then(|v| v.as_bool())
            .unwrap_or(false)
    }

    pub fn new_state(&self) -> PolicyState {
        PolicyState {
            h: vec![0.0; self.actor.hidden()],
        }
    }

    /// Logits for one observation row; advances `state`.
    pub fn logits(
        &mut self,
        obs: &ObsBatch,
        state: &mut PolicyState,
    ) -> Result<&[f32], PolicyError> {
        if obs.rows != 1 {
            return Err(PolicyError::NotOneRow(obs.rows));
        }
        obs.validate()?;
        if state.h.len() != self.actor.hidden() {
            return Err(PolicyError::Shape {
                what: "policy state",
                got: state.h.len(),
                expected: self.actor.hidden(),
            });
        }
        self.actor.forward_step(obs, &mut state.h, &[1.0])
    }

    /// One decision for one robot: action index 0 stay, 1 left, 2 right, 3 down, 4 up.
    pub fn act(
        &mut self,
        obs: &ObsBatch,
        state: &mut PolicyState,
        mode: ActMode,
    ) -> Result<u8, PolicyError> {
        let logits = self.logits(obs, state)?;
        let a = match mode {
            ActMode::Greedy => categorical::argmax(logits),
            ActMode::Sample(rng) => {
                let u = (rng.next_u32() >> 8) as f32 / (1u32 << 24) as f32;
                categorical::sample(logits, u)
            }
        };
        Ok(a as u8)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::net_tests::{rand_obs, small_arch};
    use obs::Counts;
    use rand::SeedableRng;

    fn c(m: usize, s: usize, p: usize) -> Counts {
        Counts {
            machines: m,
            storages: s,
            peers: p,
        }
    }

    #[test]
    fn act_validates_input_and_refuses_oversized_mappo_counts() {
        let mut pol = Policy::from_actor(
            Actor::new(small_arch(ModelKind::Mappo), 1),
            serde_json::Value::Null,
        );
        let mut st = pol.new_state();
        assert!(pol
            .act(&rand_obs(1, c(3, 2, 3), 1), &mut st, ActMode::Greedy)
            .is_ok());
        let e = pol
            .act(&rand_obs(1, c(3, 2, 4), 1), &mut st, ActMode::Greedy)
            .unwrap_err();
        assert!(
            matches!(
                e,
                PolicyError::TooMany {
                    field: "peers",
                    got: 4,
                    max: 3
                }
            ),
            "{e}"
        );
        let mut nan = rand_obs(1, c(1, 1, 1), 2);
        nan.storages[1] = f32::NAN;
        assert!(matches!(
            pol.act(&nan, &mut st, ActMode::Greedy),
            Err(PolicyError::Obs(_))
        ));
        let two = rand_obs(2, c(1, 1, 1), 2);
        assert_eq!(
            pol.act(&two, &mut st, ActMode::Greedy),
            Err(PolicyError::NotOneRow(2))
        );
    }

    #[test]
    fn smappo_acts_for_a_lone_robot_and_sampling_is_reproducible() {
        let mut pol = Policy::from_actor(
            Actor::new(small_arch(ModelKind::Smappo), 2),
            serde_json::Value::Null,
        );
        let mut st = pol.new_state();
        let lone = rand_obs(1, c(2, 1, 0), 3);
        let a = pol.act(&lone, &mut st, ActMode::Greedy).unwrap();
        assert!(a < 5);
        assert!(st.h.iter().any(|v| *v != 0.0));
        let run = |pol: &mut Policy| {
            let mut rng = rand::rngs::StdRng::seed_from_u64(4);
            let mut st = pol.new_state();
            (0..20)
                .map(|i| {
                    pol.act(
                        &rand_obs(1, c(3, 2, 1), i),
                        &mut st,
                        ActMode::Sample(&mut rng),
                    )
                    .unwrap()
                })
                .collect::<Vec<_>>()
        };
        assert_eq!(run(&mut pol), run(&mut pol));
        st.reset();
        assert!(st.h.iter().all(|v| *v == 0.0));
    }
}
