//! [`VecSim`]: many environments stepped together on rayon, the GIL released.

use crate::greedy::greedy_actions;
use crate::greedy::greedy_params;
use crate::metrics_dict;
use crate::parse_config;
use crate::parse_setup;
use crate::sim_err;
use crate::spaces::n_actions;
use crate::spaces::obs_arrays;
use crate::spaces::read_actions;
use crate::spaces::ObsArrays;
use numpy::ndarray::Array2;
use numpy::IntoPyArray;
use numpy::PyArray1;
use numpy::PyArray2;
use numpy::PyArrayMethods;
use obs::MACHINE_DIM;
use obs::PEER_DIM;
use obs::SELF_DIM;
use obs::STORAGE_DIM;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rayon::prelude::*;
use sim::episode_seed;
use sim::fork::{blocks, cut, for_each_piece, Split};
use sim::Env;

/// `n_envs` environments of one setup stepped together on rayon, the GIL released. Each
/// env's episode seeds are `episode_seed(seed, env, episode)`, as `sim::VecEnv` and
/// `tending sim` use, so env `e`'s episodes are those of `tending sim --seed seed` for
/// e = 0 and bit-for-bit the same whatever the thread count. Episodes all last
/// `episode_steps`; an env whose episode ends is reset in the same call (its final
/// observation is returned separately).
#[pyclass(module = "tending._native")]
pub struct VecSim {
    envs: Vec<Env>,
    base_seed: u64,
    episode: Vec<u64>,
    n: usize,
    counts: obs::Counts,
    n_actions: usize,
}

/// A run of envs and their blocks of the step's outputs (env-major): the piece of a
/// batched call one thread does (`sim::fork`: the calling thread does one itself).
struct Lanes<'a> {
    envs: &'a mut [Env],
    /// Actions (steps only; empty for a plain observation).
    actions: &'a [u8],
    rewards: &'a mut [f32],
    done: &'a mut [bool],
    /// Values per env: actions/rewards, then the four observation groups.
    w: [usize; 5],
    obs: [&'a mut [f32]; 4],
}

impl Split for Lanes<'_> {
    fn len(&self) -> usize {
        self.envs.len()
    }
    fn split_at(self, mid: usize) -> (Self, Self) {
        let w = self.w;
        let (e0, e1) = self.envs.split_at_mut(mid);
        let (a0, a1) = self.actions.split_at((w[0] * mid).min(self.actions.len()));
        let (r0, r1) = self
            .rewards
            .split_at_mut((w[0] * mid).min(self.rewards.len()));
        let (d0, d1) = self.done.split_at_mut(mid.min(self.done.len()));
        let [o, m, s, p] = self.obs;
        let ((o0, o1), (m0, m1)) = (cut(o, w[1], mid), cut(m, w[2], mid));
        let ((s0, s1), (p0, p1)) = (cut(s, w[3], mid), cut(p, w[4], mid));
        (
            Lanes {
                envs: e0,
                actions: a0,
                rewards: r0,
                done: d0,
                w,
                obs: [o0, m0, s0, p0],
            },
            Lanes {
                envs: e1,
                actions: a1,
                rewards: r1,
                done: d1,
                w,
                obs: [o1, m1, s1, p1],
            },
        )
    }
}

impl Lanes<'_> {
    /// Step each env (when there are actions) and write its observation: one pass per
    /// env, its state still in cache.
    fn run(self) -> Result<(), sim::SimError> {
        let e_n = self.envs.len();
        let [o, m, s, p] = self.obs;
        let w = self.w;
        let obs = blocks(o, w[1], e_n).zip(blocks(m, w[2], e_n));
        let obs = obs.zip(blocks(s, w[3], e_n)).zip(blocks(p, w[4], e_n));
        for (i, (env, (((o, m), s), p))) in self.envs.iter_mut().zip(obs).enumerate() {
            if !self.actions.is_empty() {
                env.step_actions(&self.actions[i * w[0]..(i + 1) * w[0]])?;
                self.rewards[i * w[0]..(i + 1) * w[0]].copy_from_slice(env.rewards());
                self.done[i] = env.is_done();
            }
            env.observe_into(o, m, s, p);
        }
        Ok(())
    }
}

/// Values per env: robots, then each observation group.
fn widths(n: usize, c: obs::Counts) -> [usize; 5] {
    [
        n,
        n * SELF_DIM,
        n * c.machines * MACHINE_DIM,
        n * c.storages * STORAGE_DIM,
        n * c.peers * PEER_DIM,
    ]
}

type VecStep<'py> = (
    ObsArrays<'py>,
    Bound<'py, PyArray2<f32>>,
    Bound<'py, PyArray1<bool>>,
    Option<ObsArrays<'py>>,
    Vec<Option<Bound<'py, PyDict>>>,
);

#[pymethods]
impl VecSim {
    #[new]
    #[pyo3(signature = (setup, n_envs, seed, config_toml=None, config_json=None, diagonal_actions=false))]
    fn new(
        setup: &str,
        n_envs: usize,
        seed: u64,
        config_toml: Option<&str>,
        config_json: Option<&str>,
        diagonal_actions: bool,
    ) -> PyResult<Self> {
        if n_envs == 0 {
            return Err(PyValueError::new_err("n_envs: must be at least 1"));
        }
        let cfg = parse_config(config_toml, config_json)?;
        let setup = parse_setup(setup)?;
        let envs = (0..n_envs)
            .into_par_iter()
            .map(|e| Env::new(cfg.clone(), setup, episode_seed(seed, e, 0)))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| sim_err("setup", e))?;
        let counts = envs[0].obs_counts();
        Ok(Self {
            n: setup.robots,
            envs,
            base_seed: seed,
            episode: vec![0; n_envs],
            counts,
            n_actions: n_actions(diagonal_actions),
        })
    }

    #[getter]
    fn n_envs(&self) -> usize {
        self.envs.len()
    }
    #[getter]
    fn robots_per_env(&self) -> usize {
        self.n
    }
    /// Discrete actions per robot: 5, or 9 with `diagonal_actions`.
    #[getter]
    fn n_actions(&self) -> usize {
        self.n_actions
    }
    /// (machines, storages, peers) per observation row.
    #[getter]
    fn obs_counts(&self) -> (usize, usize, usize) {
        (
            self.counts.machines,
            self.counts.storages,
            self.counts.peers,
        )
    }
    #[getter]
    fn episode_steps(&self) -> u32 {
        self.envs[0].config().world.episode_steps
    }
    #[getter]
    fn room_size(&self) -> f32 {
        self.envs[0].config().world.room_size
    }

    /// Reset every env (new base seed if given) and return the observations, each array
    /// shaped (n_envs, n_robots, ...).
    #[pyo3(signature = (seed=None))]
    fn reset<'py>(&mut self, py: Python<'py>, seed: Option<u64>) -> PyResult<ObsArrays<'py>> {
        if let Some(s) = seed {
            self.base_seed = s;
        }
        let base = self.base_seed;
        let envs = &mut self.envs;
        py.allow_threads(|| {
            envs.par_iter_mut()
                .enumerate()
                .try_for_each(|(e, env)| env.reset(episode_seed(base, e, 0)))
        })
        .map_err(|e| sim_err("reset", e))?;
        self.episode.iter_mut().for_each(|e| *e = 0);
        self.observe(py)
    }

    /// The current observations, each array shaped (n_envs, n_robots, ...).
    fn observe<'py>(&mut self, py: Python<'py>) -> PyResult<ObsArrays<'py>> {
        let arrs = obs_arrays(py, &[self.envs.len(), self.n], self.counts);
        {
            let (mut o, mut m, mut s, mut p) = (
                arrs.0.readwrite(),
                arrs.1.readwrite(),
                arrs.2.readwrite(),
                arrs.3.readwrite(),
            );
            let lanes = Lanes {
                envs: &mut self.envs,
                actions: &[],
                rewards: &mut [],
                done: &mut [],
                w: widths(self.n, self.counts),
                obs: [
                    o.as_slice_mut()?,
                    m.as_slice_mut()?,
                    s.as_slice_mut()?,
                    p.as_slice_mut()?,
                ],
            };
            py.allow_threads(|| for_each_piece(lanes, &Lanes::run))
                .map_err(|e| sim_err("observe", e))?;
        }
        Ok(arrs)
    }

    /// Step every env with `actions` (n_envs x n_robots integers, any int dtype, flat or
    /// 2-D). Returns (observations, rewards (n_envs, n_robots), done (n_envs,),
    /// final observations or None, final metrics per env or None). Envs that are done were
    /// reset: their row of `observations` is the first of the next episode and the last
    /// one of the finished episode is in `final observations`.
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        actions: &Bound<'py, PyAny>,
    ) -> PyResult<VecStep<'py>> {
        let (e_n, n) = (self.envs.len(), self.n);
        let a = read_actions(actions, e_n * n, self.n_actions)?;
        let rewards = PyArray2::<f32>::zeros(py, [e_n, n], false);
        let mut done = vec![false; e_n];
        let obs = obs_arrays(py, &[e_n, n], self.counts);
        {
            let mut rw = rewards.readwrite();
            let rs = rw.as_slice_mut()?;
            let (mut o, mut m, mut s, mut p) = (
                obs.0.readwrite(),
                obs.1.readwrite(),
                obs.2.readwrite(),
                obs.3.readwrite(),
            );
            let lanes = Lanes {
                envs: &mut self.envs,
                actions: &a,
                rewards: rs,
                done: &mut done,
                w: widths(n, self.counts),
                obs: [
                    o.as_slice_mut()?,
                    m.as_slice_mut()?,
                    s.as_slice_mut()?,
                    p.as_slice_mut()?,
                ],
            };
            py.allow_threads(|| for_each_piece(lanes, &Lanes::run))
                .map_err(|e| sim_err("actions", e))?;
        }
        let mut finals = None;
        let mut metrics: Vec<Option<Bound<'py, PyDict>>> = vec![None; e_n];
        if done.iter().any(|&d| d) {
            // The arrays just filled hold the final observations; the next episode's first
            // ones go into fresh arrays.
            for (e, env) in self.envs.iter().enumerate() {
                if done[e] {
                    metrics[e] = Some(metrics_dict(py, env.metrics())?);
                }
            }
            let base = self.base_seed;
            let (envs, eps) = (&mut self.envs, &mut self.episode);
            py.allow_threads(|| {
                envs.par_iter_mut()
                    .zip(eps.par_iter_mut())
                    .zip(done.par_iter())
                    .enumerate()
                    .try_for_each(|(e, ((env, ep), &d))| {
                        if d {
                            *ep += 1;
                            env.reset(episode_seed(base, e, *ep))?;
                        }
                        Ok::<(), sim::SimError>(())
                    })
            })
            .map_err(|e| sim_err("reset", e))?;
            let next = self.observe(py)?;
            finals = Some(obs);
            let done_arr = PyArray1::from_slice(py, &done);
            return Ok((next, rewards, done_arr, finals, metrics));
        }
        let done_arr = PyArray1::from_slice(py, &done);
        Ok((obs, rewards, done_arr, finals, metrics))
    }

    /// Greedy baseline actions for observations in the layout of `observe()`, shape
    /// (n_envs, n_robots), computed on rayon with the GIL released.
    fn greedy_actions<'py>(
        &self,
        py: Python<'py>,
        own: &Bound<'py, PyAny>,
        machines: &Bound<'py, PyAny>,
        storages: &Bound<'py, PyAny>,
        peers: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<u8>>> {
        let (e_n, n, c) = (self.envs.len(), self.n, self.counts);
        let arrays = [own, machines, storages, peers];
        let out = greedy_actions(py, &greedy_params(&self.envs[0]), c, e_n, n, arrays)?;
        let a = Array2::from_shape_vec((e_n, n), out)
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(a.into_pyarray(py))
    }

    /// Metrics of every env's current episode.
    fn metrics<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.envs
            .iter()
            .map(|e| metrics_dict(py, e.metrics()))
            .collect()
    }
}
