//! Trainer state on disk and schedule changes: policy checkpoints with their training
//! metadata, the bit-exact trainer state, resume, and replacing or extending the schedule.

use super::super::config::TrainConfig;
use super::super::randomize::SetupRange;
use super::super::valuenorm::{ValueNorm, ValueNormBits};
use super::{format_curriculum, parse_curriculum, Stage, TrainError, Trainer};
use policy::checkpoint::{load_trainer_state, save_policy, save_trainer_state};
use policy::config::ModelKind;
use policy::Actor;
use serde::{Deserialize, Serialize};
use sim::ScenarioConfig;
use std::path::Path;

#[derive(Debug, Clone, Serialize, Deserialize)]
struct StateExtra {
    kind: ModelKind,
    config: TrainConfig,
    scenario_toml: String,
    schedule: String,
    seed: u64,
    update: u64,
    episodes: u64,
    agent_steps: u64,
    stage: usize,
    stage_episodes: u64,
    valuenorm: ValueNormBits,
    /// Setup range of a randomized run (absent in states saved before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    randomize: Option<String>,
    /// Lagrange multiplier (0 in states saved before constrained training existed).
    #[serde(default)]
    lambda: f32,
}

impl Trainer {
    /// Free-form training metadata stored in the policy checkpoint.
    pub fn training_meta(&self) -> serde_json::Value {
        serde_json::json!({
            "model": self.kind,
            "setup": match self.randomize {
                Some(r) => r.to_string(),
                None => self.current_setup().to_string(),
            },
            "schedule": self.schedule_string(),
            "randomize": self.randomize.map(|r| r.to_string()),
            "episodes": self.episodes,
            "updates": self.update,
            "agent_steps": self.agent_steps,
            "seed": self.seed,
            "init_actor": self.init_actor_from,
            "lambda": self.lambda,
            "k_speed": self.scenario.task.k_speed,
            "scenario": serde_json::to_value(&self.scenario).unwrap_or(serde_json::Value::Null),
            "train_config": serde_json::to_value(&self.cfg).unwrap_or(serde_json::Value::Null),
        })
    }

    /// Start from a trained actor (e.g. fine-tuning the bundled policy behind a safety
    /// filter): its weights replace the fresh ones, with a fresh Adam. Refused unless its
    /// architecture is exactly this run's.
    ///
    /// One exception: a target-action actor with the older 7-entry menu
    /// (`plan::targets::N_TARGET_ACTIONS_V1`) in a run with the current menu gets the new
    /// "matched" entry as a copy of its "nearest busy" output (`Actor::with_copied_output`):
    /// it starts acting exactly as before under argmax, and the fine-tune learns where
    /// matching beats the claim rule (docs/RESULTS.md 7.8).
    pub fn init_actor(&mut self, actor: &Actor) -> Result<(), TrainError> {
        let widened;
        let mut actor = actor;
        if actor.arch.actions == policy::ActionSpace::Targets
            && actor.arch.n_actions == plan::targets::N_TARGET_ACTIONS_V1
            && self.actor.arch.n_actions == plan::targets::N_TARGET_ACTIONS
        {
            widened = actor
                .with_copied_output(plan::targets::TargetAction::NearestBusy as usize)
                .map_err(TrainError::Config)?;
            actor = &widened;
        }
        if actor.arch != self.actor.arch {
            return Err(TrainError::Config(format!(
                "the initial actor's architecture {:?} differs from this run's {:?}",
                actor.arch, self.actor.arch
            )));
        }
        let mut a = actor.clone();
        a.opt = self.actor.opt.clone();
        self.actor = a;
        Ok(())
    }

    pub fn save_policy(&self, path: &Path) -> Result<(), TrainError> {
        save_policy(path, &self.actor, self.training_meta())?;
        Ok(())
    }

    /// Everything needed to continue bit-exactly.
    pub fn save_state(&self, path: &Path) -> Result<(), TrainError> {
        let extra = StateExtra {
            kind: self.kind,
            config: self.cfg.clone(),
            scenario_toml: self.scenario.to_toml(),
            schedule: format_curriculum(&self.schedule),
            seed: self.seed,
            update: self.update,
            episodes: self.episodes,
            agent_steps: self.agent_steps,
            stage: self.stage,
            stage_episodes: self.stage_episodes,
            valuenorm: self.vnorm.to_bits(),
            randomize: self.randomize.map(|r| r.to_string()),
            lambda: self.lambda,
        };
        let v = serde_json::to_value(&extra).map_err(|e| TrainError::Config(e.to_string()))?;
        save_trainer_state(path, &self.actor, &self.critic, v)?;
        Ok(())
    }

    /// Continue from a saved state. `schedule`, when given, replaces the saved schedule
    /// (e.g. to extend a run); stage and episode counters are kept.
    pub fn resume(path: &Path, schedule: Option<Vec<Stage>>) -> Result<Self, TrainError> {
        let meta = policy::checkpoint::read_trainer_extra(path)?;
        let extra: StateExtra = serde_json::from_value(meta)
            .map_err(|e| TrainError::Config(format!("trainer state extra: {e}")))?;
        let scenario = ScenarioConfig::from_toml(&extra.scenario_toml, "trainer state")?;
        let saved = parse_curriculum(&extra.schedule)?;
        let mut t = Self::new(
            extra.kind,
            extra.config.clone(),
            scenario,
            saved.clone(),
            extra.seed,
        )?;
        load_trainer_state(path, &mut t.actor, &mut t.critic)?;
        t.update = extra.update;
        t.episodes = extra.episodes;
        t.agent_steps = extra.agent_steps;
        t.stage = extra.stage;
        t.stage_episodes = extra.stage_episodes;
        t.vnorm = ValueNorm::from_bits(extra.valuenorm);
        t.lambda = extra.lambda;
        if let Some(r) = &extra.randomize {
            let range: SetupRange = r.parse()?;
            Self::check_range(t.kind, &t.cfg, &t.scenario, range)?;
            t.randomize = Some(range);
        }
        if let Some(s) = schedule {
            if s != saved {
                t.set_schedule(s)?;
            }
        }
        Ok(t)
    }

    /// Replace the schedule (e.g. to extend a resumed run): the stage is re-derived from
    /// the episodes trained so far; refused when it would change the network shapes.
    /// A randomized run becomes a fixed-setup one (see [`Trainer::set_randomize`]).
    pub fn set_schedule(&mut self, s: Vec<Stage>) -> Result<(), TrainError> {
        if s.is_empty() {
            return Err(TrainError::Config("empty schedule".into()));
        }
        let (a, c) = Self::archs(self.kind, &self.cfg, &s)?;
        if a != self.actor.arch || c != self.critic.arch {
            return Err(TrainError::Config(
                "the new schedule changes the network shapes (MAPPO critic padding)".into(),
            ));
        }
        self.randomize = None;
        self.schedule = s;
        let mut left = self.episodes;
        self.stage = 0;
        self.stage_episodes = 0;
        for st in &self.schedule {
            if left >= st.episodes {
                left -= st.episodes;
                self.stage += 1;
            } else {
                self.stage_episodes = left;
                break;
            }
        }
        Ok(())
    }

    /// Train on setups drawn from `range` until `episodes` episodes in total (counted
    /// from the start of the run), e.g. to switch a resumed run to, or extend, a
    /// randomized schedule. Same refusals as [`Trainer::new_randomized`] and
    /// [`Trainer::set_schedule`].
    pub fn set_randomize(&mut self, range: SetupRange, episodes: u64) -> Result<(), TrainError> {
        Self::check_range(self.kind, &self.cfg, &self.scenario, range)?;
        if episodes == 0 {
            return Err(TrainError::Config(format!(
                "setup range {range}: 0 episodes to train"
            )));
        }
        self.set_schedule(vec![Stage {
            setup: range.hi,
            episodes,
        }])?;
        self.randomize = Some(range);
        Ok(())
    }

    /// A new total episode budget: the last stage (the only one of a randomized run)
    /// absorbs the difference; refused when it would end before the last stage starts.
    pub fn set_total_episodes(&mut self, total: u64) -> Result<(), TrainError> {
        let before: u64 = self.schedule[..self.schedule.len() - 1]
            .iter()
            .map(|x| x.episodes)
            .sum();
        if total <= before {
            return Err(TrainError::Config(format!(
                "{total} episodes end before the last curriculum stage (which starts at \
                 episode {before})"
            )));
        }
        match self.randomize {
            Some(r) => self.set_randomize(r, total),
            None => {
                let mut s = self.schedule.clone();
                s.last_mut().expect("non-empty").episodes = total - before;
                self.set_schedule(s)
            }
        }
    }
}
