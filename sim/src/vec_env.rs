//! Many environments stepped together, one contiguous run of envs per thread
//! ([`crate::fork`]: the calling thread steps one run itself).
//!
//! Each environment is stepped by one thread from start to end of its step, and its
//! episode seeds derive from (base seed, env index, episode number) only, so results are
//! bit-for-bit the same whatever the number of threads.

use crate::fork::{blocks, cut, for_each_piece, Split};
use crate::{Env, Metrics, ScenarioConfig, Setup, SimError};
use obs::ObsBatch;

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
        self.step_with(actions, None, |env, a| env.step_actions(a))
    }

    /// [`VecEnv::step_actions`] then [`VecEnv::observe`] in one pass: each env writes its
    /// observation right after its step (its state still in cache), one fork per call.
    pub fn step_actions_observe(
        &mut self,
        actions: &[u8],
        out: &mut ObsBatch,
    ) -> Result<(), SimError> {
        self.step_with(actions, Some(out), |env, a| env.step_actions(a))
    }

    /// Step every env with a velocity command (vx, vy) per robot (env-major): the path a
    /// safety filter's output takes (`Env::step_velocities`). Same resets as
    /// [`VecEnv::step_actions`].
    pub fn step_velocities(&mut self, cmds: &[[f32; 2]]) -> Result<(), SimError> {
        self.step_with(cmds, None, |env, c| env.step_velocities(c))
    }

    /// Bodies each robot touched in the last step (env-major, robot order): the cost a
    /// constrained learner budgets (the same count `Metrics::collisions` sums).
    pub fn contacts(&self) -> &[u32] {
        &self.contacts
    }

    fn step_with<C: Sync>(
        &mut self,
        cmds: &[C],
        out: Option<&mut ObsBatch>,
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
        let (ow, obs) = match out {
            Some(o) => obs_lanes(o, n, self.envs.len(), self.envs[0].obs_counts()),
            None => ([0; 4], Default::default()),
        };
        let observe = ow != [0; 4];
        let lanes = StepLanes {
            first: 0,
            n,
            ow,
            obs,
            envs: &mut self.envs,
            cmds,
            rewards: &mut self.rewards,
            contacts: &mut self.contacts,
            done: &mut self.done,
            finished: &mut self.finished,
            episode: &mut self.episode,
        };
        for_each_piece(lanes, &|l: StepLanes<C>| {
            let e = l.envs.len();
            let it = l
                .envs
                .iter_mut()
                .zip(l.cmds.chunks(n))
                .zip(l.rewards.chunks_mut(n));
            let it = it.zip(l.contacts.chunks_mut(n)).zip(l.done.iter_mut());
            let it = it.zip(l.finished.iter_mut()).zip(l.episode.iter_mut());
            let [o, mc, sc, pc] = l.obs;
            let blk = blocks(o, l.ow[0], e).zip(blocks(mc, l.ow[1], e));
            let mut blk = blk.zip(blocks(sc, l.ow[2], e)).zip(blocks(pc, l.ow[3], e));
            for (i, ((((((env, a), rew), con), done), fin), ep)) in it.enumerate() {
                step(env, a)?;
                rew.copy_from_slice(env.rewards());
                for (c, ev) in con.iter_mut().zip(env.events()) {
                    *c = ev.collisions;
                }
                // `done` and `finished` are packed, one cache line for many envs shared by
                // both threads' pieces: written only when they change, not every step
                // (which moves the line between the cores; 1-3 % at 14.10_4 x 32).
                let d = env.is_done();
                if *done != d {
                    *done = d;
                }
                if fin.is_some() {
                    *fin = None;
                }
                if d {
                    *fin = Some(*env.metrics());
                    *ep += 1;
                    env.reset(episode_seed(base, l.first + i, *ep))?;
                }
                if let Some((((o, mc), sc), pc)) = blk.next().filter(|_| observe) {
                    env.observe_into(o, mc, sc, pc);
                }
            }
            Ok(())
        })
    }

    /// Every robot's observation, env-major.
    pub fn observe(&self, out: &mut ObsBatch) {
        let n = self.robots_per_env();
        let (w, bufs) = obs_lanes(out, n, self.envs.len(), self.envs[0].obs_counts());
        let lanes = ObsLanes {
            envs: &self.envs,
            w,
            bufs,
        };
        let _ = for_each_piece(lanes, &|l: ObsLanes| {
            let e = l.envs.len();
            let [o, mc, sc, pc] = l.bufs;
            let it = blocks(o, l.w[0], e).zip(blocks(mc, l.w[1], e));
            let it = it.zip(blocks(sc, l.w[2], e)).zip(blocks(pc, l.w[3], e));
            for (env, (((o, mc), sc), pc)) in l.envs.iter().zip(it) {
                env.observe_into(o, mc, sc, pc);
            }
            Ok::<(), ()>(())
        });
    }
}

/// `out` sized for `e` envs of `n` robots, as values per env and the four buffers.
fn obs_lanes(
    out: &mut ObsBatch,
    n: usize,
    e: usize,
    counts: obs::Counts,
) -> ([usize; 4], [&mut [f32]; 4]) {
    out.resize(n * e, counts);
    let (m, k, p) = (counts.machines, counts.storages, counts.peers);
    let ObsBatch {
        own,
        machines,
        storages,
        peers,
        ..
    } = out;
    (
        [
            n * obs::SELF_DIM,
            n * m * obs::MACHINE_DIM,
            n * k * obs::STORAGE_DIM,
            n * p * obs::PEER_DIM,
        ],
        [own, machines, storages, peers],
    )
}

/// A run of envs and their slices of the step's outputs (env-major).
struct StepLanes<'a, C> {
    /// Index of `envs[0]` in the whole batch (for episode seeds).
    first: usize,
    n: usize,
    /// Observation values per env (all 0 when the step does not observe) and buffers.
    ow: [usize; 4],
    obs: [&'a mut [f32]; 4],
    envs: &'a mut [Env],
    cmds: &'a [C],
    rewards: &'a mut [f32],
    contacts: &'a mut [u32],
    done: &'a mut [bool],
    finished: &'a mut [Option<Metrics>],
    episode: &'a mut [u64],
}

impl<C: Sync> Split for StepLanes<'_, C> {
    fn len(&self) -> usize {
        self.envs.len()
    }
    fn split_at(self, mid: usize) -> (Self, Self) {
        let n = self.n;
        let (e0, e1) = self.envs.split_at_mut(mid);
        let (c0, c1) = self.cmds.split_at(n * mid);
        let (r0, r1) = cut(self.rewards, n, mid);
        let (k0, k1) = cut(self.contacts, n, mid);
        let (d0, d1) = self.done.split_at_mut(mid);
        let (f0, f1) = self.finished.split_at_mut(mid);
        let (p0, p1) = self.episode.split_at_mut(mid);
        let (ow, [a, b, c, d]) = (self.ow, self.obs);
        let ((a0, a1), (b0, b1)) = (cut(a, ow[0], mid), cut(b, ow[1], mid));
        let ((c0_, c1_), (d0_, d1_)) = (cut(c, ow[2], mid), cut(d, ow[3], mid));
        let first = self.first;
        (
            StepLanes {
                first,
                n,
                ow,
                obs: [a0, b0, c0_, d0_],
                envs: e0,
                cmds: c0,
                rewards: r0,
                contacts: k0,
                done: d0,
                finished: f0,
                episode: p0,
            },
            StepLanes {
                first: first + mid,
                n,
                ow,
                obs: [a1, b1, c1_, d1_],
                envs: e1,
                cmds: c1,
                rewards: r1,
                contacts: k1,
                done: d1,
                finished: f1,
                episode: p1,
            },
        )
    }
}

/// A run of envs and their blocks of the four observation buffers.
struct ObsLanes<'a> {
    envs: &'a [Env],
    /// Values per env in each buffer.
    w: [usize; 4],
    bufs: [&'a mut [f32]; 4],
}

impl Split for ObsLanes<'_> {
    fn len(&self) -> usize {
        self.envs.len()
    }
    fn split_at(self, mid: usize) -> (Self, Self) {
        let (e0, e1) = self.envs.split_at(mid);
        let [a, b, c, d] = self.bufs;
        let (a0, a1) = cut(a, self.w[0], mid);
        let (b0, b1) = cut(b, self.w[1], mid);
        let (c0, c1) = cut(c, self.w[2], mid);
        let (d0, d1) = cut(d, self.w[3], mid);
        (
            ObsLanes {
                envs: e0,
                w: self.w,
                bufs: [a0, b0, c0, d0],
            },
            ObsLanes {
                envs: e1,
                w: self.w,
                bufs: [a1, b1, c1, d1],
            },
        )
    }
}
