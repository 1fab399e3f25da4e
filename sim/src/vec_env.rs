//! Many environments stepped together on rayon's pool.
//!
//! Each environment is stepped by one thread from start to end of its step, and its
//! episode seeds derive from (base seed, env index, episode number) only, so results are
//! bit-for-bit the same whatever the number of threads.

use crate::{Env, Metrics, ScenarioConfig, Setup, SimError};
use obs::ObsBatch;
use rayon::prelude::*;

/// Seed of episode `episode` of environment `env` (splitmix64 mixing).
pub fn episode_seed(base: u64, env: usize, episode: u64) -> u64 {
    let mut z = base
        ^ (env as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ episode.wrapping_mul(0xD1B5_4A32_D192_ED03);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

pub struct VecEnv {
    envs: Vec<Env>,
    base_seed: u64,
    episode: Vec<u64>,
    /// Set by the last step: which envs ended an episode (and were reset).
    done: Vec<bool>,
    /// Metrics of the episodes that ended in the last step, by env.
    finished: Vec<Option<Metrics>>,
    rewards: Vec<f32>,
    /// Bodies each robot touched in the last step.
    contacts: Vec<u32>,
}

impl VecEnv {
    pub fn new(
        cfg: ScenarioConfig,
        setup: Setup,
        n_envs: usize,
        seed: u64,
    ) -> Result<Self, SimError> {
        if n_envs == 0 {
            return Err(SimError::BadConfig {
                field: "n_envs".into(),
                reason: "must be >= 1".into(),
            });
        }
        let envs = (0..n_envs)
            .map(|e| Env::new(cfg.clone(), setup, episode_seed(seed, e, 0)))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            rewards: vec![0.0; n_envs * setup.robots],
            contacts: vec![0; n_envs * setup.robots],
            envs,
            base_seed: seed,
            episode: vec![0; n_envs],
            done: vec![false; n_envs],
            finished: vec![None; n_envs],
        })
    }

    pub fn n_envs(&self) -> usize {
        self.envs.len()
    }
    /// Robots per environment (all envs have the same count).
    pub fn robots_per_env(&self) -> usize {
        self.envs[0].n_robots()
    }
    pub fn envs(&self) -> &[Env] {
        &self.envs
    }
    pub fn done(&self) -> &[bool] {
        &self.done
    }
    pub fn finished(&self) -> &[Option<Metrics>] {
        &self.finished
    }
    /// Rewards of the last step, env-major then robot order.
    pub fn rewards(&self) -> &[f32] {
        &self.rewards
    }

    /// Step every env with its robots' discrete actions (env-major); envs whose episode
    /// ends are reset with their next episode seed, and their final metrics kept in
    /// `finished()`.
    pub fn step_actions(&mut self, actions: &[u8]) -> Result<(), SimError> {
        self.step_with(actions, |env, a| env.step_actions(a))
    }

    /// Step every env with a velocity command (vx, vy) per robot (env-major): the path a
    /// safety filter's output takes (`Env::step_velocities`). Same resets as
    /// [`VecEnv::step_actions`].
    pub fn step_velocities(&mut self, cmds: &[[f32; 2]]) -> Result<(), SimError> {
        self.step_with(cmds, |env, c| env.step_velocities(c))
    }

    /// Bodies each robot touched in the last step (env-major, robot order): the cost a
    /// constrained learner budgets (the same count `Metrics::collisions` sums).
    pub fn contacts(&self) -> &[u32] {
        &self.contacts
    }

    fn step_with<C: Sync>(
        &mut self,
        cmds: &[C],
        step: impl Fn(&mut Env, &[C]) -> Result<(), SimError> + Sync,
    ) -> Result<(), SimError> {
        let n = self.robots_per_env();
        if cmds.len() != n * self.envs.len() {
            return Err(SimError::WrongCommandCount {
                expected: n * self.envs.len(),
                got: cmds.len(),
            });
        }
        let base = self.base_seed;
        self.envs
            .par_iter_mut()
            .zip(cmds.par_chunks(n))
            .zip(self.rewards.par_chunks_mut(n))
            .zip(self.contacts.par_chunks_mut(n))
            .zip(self.done.par_iter_mut())
            .zip(self.finished.par_iter_mut())
            .zip(self.episode.par_iter_mut())
            .enumerate()
            .try_for_each(|(e, ((((((env, a), rew), con), done), fin), ep))| {
                step(env, a)?;
                rew.copy_from_slice(env.rewards());
                for (c, ev) in con.iter_mut().zip(env.events()) {
                    *c = ev.collisions;
                }
                *done = env.is_done();
                *fin = None;
                if *done {
                    *fin = Some(*env.metrics());
                    *ep += 1;
                    env.reset(episode_seed(base, e, *ep))?;
                }
                Ok(())
            })
    }

    /// Every robot's observation, env-major.
    pub fn observe(&self, out: &mut ObsBatch) {
        let n = self.robots_per_env();
        let counts = self.envs[0].obs_counts();
        out.resize(n * self.envs.len(), counts);
        let (m, k, p) = (counts.machines, counts.storages, counts.peers);
        let ObsBatch {
            own,
            machines,
            storages,
            peers,
            ..
        } = out;
        let e = self.envs.len();
        self.envs
            .par_iter()
            .zip(chunks(own, n * obs::SELF_DIM, e))
            .zip(chunks(machines, n * m * obs::MACHINE_DIM, e))
            .zip(chunks(storages, n * k * obs::STORAGE_DIM, e))
            .zip(chunks(peers, n * p * obs::PEER_DIM, e))
            .for_each(|((((env, o), mc), sc), pc)| env.observe_into(o, mc, sc, pc));
    }
}

/// `n` chunks of `size`; empty slices when `size` is 0 (a group with no entities), where
/// `par_chunks_mut` would yield no chunk at all and silently skip every env.
fn chunks(s: &mut [f32], size: usize, n: usize) -> impl IndexedParallelIterator<Item = &mut [f32]> {
    if size == 0 {
        rayon::iter::Either::Left((0..n).into_par_iter().map(|_| -> &mut [f32] { &mut [] }))
    } else {
        rayon::iter::Either::Right(s.par_chunks_mut(size))
    }
}
