//! [`Sim`]: one environment for Python.

use crate::body_id;
use crate::greedy::greedy_actions;
use crate::greedy::greedy_params;
use crate::metrics_dict;
use crate::parse_config;
use crate::parse_setup;
use crate::position;
use crate::render::render_rgb;
use crate::sim_err;
use crate::spaces::n_actions;
use crate::spaces::obs_arrays;
use crate::spaces::read_actions;
use crate::spaces::ObsArrays;
use crate::SimError;
use numpy::ndarray::Array2;
use numpy::IntoPyArray;
use numpy::PyArray1;
use numpy::PyArray2;
use numpy::PyArray3;
use numpy::PyArrayMethods;
use numpy::PyReadonlyArrayDyn;
use numpy::PyUntypedArrayMethods;
use obs::FlatLayout;
use obs::ObsBatch;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use sim::Env;
use sim::MachineId;
use sim::RobotId;
use sim::StorageId;

/// One tending environment (`sim::Env`). Robots are in robot order everywhere: row `i` of
/// every array is the robot `robot_ids()[i]`.
#[pyclass(module = "tending._native")]
pub struct Sim {
    env: Env,
    obs: ObsBatch,
    n_actions: usize,
}

#[pymethods]
impl Sim {
    /// `setup` `N.M_K`; the first episode laid out from `seed`; config as TOML text or JSON
    /// text (at most one).
    #[new]
    #[pyo3(signature = (setup, seed, config_toml=None, config_json=None, diagonal_actions=false))]
    fn new(
        setup: &str,
        seed: u64,
        config_toml: Option<&str>,
        config_json: Option<&str>,
        diagonal_actions: bool,
    ) -> PyResult<Self> {
        let cfg = parse_config(config_toml, config_json)?;
        let setup = parse_setup(setup)?;
        let env = Env::new(cfg, setup, seed).map_err(|e| sim_err("setup", e))?;
        Ok(Self {
            env,
            obs: ObsBatch::default(),
            n_actions: n_actions(diagonal_actions),
        })
    }

    /// Discrete actions per robot: 5, or 9 with `diagonal_actions`.
    #[getter]
    fn n_actions(&self) -> usize {
        self.n_actions
    }

    /// Start a new episode with the initial setup, laid out from `seed`.
    fn reset(&mut self, seed: u64) -> PyResult<()> {
        self.env.reset(seed).map_err(|e| sim_err("reset", e))
    }

    /// One step with one discrete action per robot (0 stay, 1 left, 2 right, 3 down, 4 up).
    fn step(&mut self, py: Python<'_>, actions: &Bound<'_, PyAny>) -> PyResult<()> {
        let a = read_actions(actions, self.env.n_robots(), self.n_actions)?;
        let env = &mut self.env;
        py.allow_threads(|| env.step_actions(&a))
            .map_err(|e| sim_err("actions", e))
    }

    /// One step with a velocity command (vx, vy) in m/s per robot, shape (n, 2): the
    /// simulator's native input (what ROS Twist messages drive).
    fn step_velocities(&mut self, py: Python<'_>, cmds: &Bound<'_, PyAny>) -> PyResult<()> {
        let np = py.import("numpy")?;
        let arr = np.call_method1("ascontiguousarray", (cmds, "float32"))?;
        let arr: PyReadonlyArrayDyn<'_, f32> = arr.extract()?;
        let n = self.env.n_robots();
        if arr.shape() != [n, 2] {
            return Err(PyValueError::new_err(format!(
                "velocities: expected shape ({n}, 2), got {:?}",
                arr.shape()
            )));
        }
        let s = arr
            .as_slice()
            .map_err(|e| PyValueError::new_err(format!("velocities: {e}")))?;
        let v: Vec<[f32; 2]> = s.chunks_exact(2).map(|c| [c[0], c[1]]).collect();
        let env = &mut self.env;
        py.allow_threads(|| env.step_velocities(&v))
            .map_err(|e| sim_err("velocities", e))
    }

    /// Every robot's observation: (self (n,3), machines (n,M,3), storages (n,K,2),
    /// peers (n,n-1,3)), fresh arrays written in place by Rust.
    fn observe<'py>(&self, py: Python<'py>) -> PyResult<ObsArrays<'py>> {
        let n = self.env.n_robots();
        let arrs = obs_arrays(py, &[n], self.env.obs_counts());
        {
            let (mut o, mut m, mut s, mut p) = (
                arrs.0.readwrite(),
                arrs.1.readwrite(),
                arrs.2.readwrite(),
                arrs.3.readwrite(),
            );
            let slices = (
                o.as_slice_mut()?,
                m.as_slice_mut()?,
                s.as_slice_mut()?,
                p.as_slice_mut()?,
            );
            self.env
                .observe_into(slices.0, slices.1, slices.2, slices.3);
        }
        Ok(arrs)
    }

    /// The MAPPO baseline's zero-padded flat rows (`obs::FlatLayout`), shape (n, dim).
    fn observe_flat<'py>(
        &mut self,
        py: Python<'py>,
        max_machines: usize,
        max_storages: usize,
        max_peers: usize,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let layout = FlatLayout {
            max_machines,
            max_storages,
            max_peers,
        };
        self.env.observe(&mut self.obs);
        let mut flat = Vec::new();
        layout.write(&self.obs, &mut flat).map_err(|e| {
            PyValueError::new_err(format!(
                "flat observation: {e} (the flat layout's maximum is smaller than the live count)"
            ))
        })?;
        let a = Array2::from_shape_vec((self.obs.rows, layout.dim()), flat)
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(a.into_pyarray(py))
    }

    /// Per-robot rewards of the last step.
    fn rewards<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        PyArray1::from_slice(py, self.env.rewards())
    }

    /// Per-robot events of the last step: (picked machine id or -1, placed storage id or
    /// -1, bodies touched).
    fn events<'py>(&self, py: Python<'py>) -> Events<'py> {
        let ev = self.env.events();
        let picked: Vec<i64> = ev
            .iter()
            .map(|e| e.picked.map_or(-1, |m| m.0 as i64))
            .collect();
        let placed: Vec<i64> = ev
            .iter()
            .map(|e| e.placed.map_or(-1, |s| s.0 as i64))
            .collect();
        let coll: Vec<u32> = ev.iter().map(|e| e.collisions).collect();
        (
            picked.into_pyarray(py),
            placed.into_pyarray(py),
            coll.into_pyarray(py),
        )
    }

    /// The episode's metrics so far (paper section IV-E), `mu` = parts collected / P_max.
    fn metrics<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        metrics_dict(py, self.env.metrics())
    }

    /// Greedy baseline actions from observation arrays in the layout of `observe()`.
    fn greedy_actions<'py>(
        &self,
        py: Python<'py>,
        own: &Bound<'py, PyAny>,
        machines: &Bound<'py, PyAny>,
        storages: &Bound<'py, PyAny>,
        peers: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<u8>>> {
        let (n, c) = (self.env.n_robots(), self.env.obs_counts());
        let arrays = [own, machines, storages, peers];
        let out = greedy_actions(py, &greedy_params(&self.env), c, 1, n, arrays)?;
        Ok(out.into_pyarray(py))
    }

    /// An RGB frame, shape (px, px, 3), uint8.
    #[pyo3(signature = (px=460))]
    fn render<'py>(&self, py: Python<'py>, px: usize) -> PyResult<Bound<'py, PyArray3<u8>>> {
        if !(16..=4096).contains(&px) {
            return Err(PyValueError::new_err(format!(
                "render_size: {px} pixels is outside 16..=4096"
            )));
        }
        Ok(render_rgb(&self.env, px).into_pyarray(py))
    }

    fn robot_ids(&self) -> Vec<u32> {
        self.env.robot_ids().iter().map(|r| r.0).collect()
    }
    fn machine_ids(&self) -> Vec<u32> {
        self.env.machines().map(|m| m.id.0).collect()
    }
    fn storage_ids(&self) -> Vec<u32> {
        self.env.storages().map(|s| s.id.0).collect()
    }
    /// (robots, machines, storages) now.
    fn counts(&self) -> (usize, usize, usize) {
        let c = self.env.counts();
        (c.robots, c.machines, c.storages)
    }
    /// The setup the env was made with (N.M_K).
    fn setup(&self) -> String {
        self.env.setup().to_string()
    }
    fn steps(&self) -> u32 {
        self.env.steps()
    }
    fn is_done(&self) -> bool {
        self.env.is_done()
    }
    fn episode_steps(&self) -> u32 {
        self.env.config().world.episode_steps
    }
    fn room_size(&self) -> f32 {
        self.env.config().world.room_size
    }
    fn dt(&self) -> f32 {
        self.env.config().world.dt
    }
    /// Speed of the discrete actions and the velocity commands' clamp, m/s.
    fn k_speed(&self) -> f32 {
        self.env.config().task.k_speed
    }
    /// The full scenario config in effect, as TOML.
    fn config_toml(&self) -> String {
        self.env.config().to_toml()
    }
    /// Robots (id, x, y, vx, vy, has_part) in robot order.
    fn robot_states(&self) -> Vec<(u32, f32, f32, f32, f32, bool)> {
        self.env
            .robots()
            .map(|r| (r.id.0, r.pos[0], r.pos[1], r.vel[0], r.vel[1], r.has_part))
            .collect()
    }

    // ---- live add / remove (between steps) ----

    /// Add a robot at (x, y) or at a free spot; returns its id.
    #[pyo3(signature = (pos=None))]
    fn add_robot(&mut self, pos: Option<(f32, f32)>) -> PyResult<u32> {
        self.env
            .add_robot(position(pos))
            .map(|r| r.0)
            .map_err(|e| sim_err("add_robot", e))
    }
    fn remove_robot(&mut self, id: i64) -> PyResult<()> {
        let id = body_id("remove_robot", "robot", id)?;
        if self.env.n_robots() == 1 && self.env.robot_index(RobotId(id)).is_some() {
            // An env with no robot has no agents and nothing to observe: refuse it here
            // rather than hand PettingZoo an empty, still-running episode.
            return Err(SimError::new_err(
                "remove_robot: cannot remove the last robot",
            ));
        }
        self.env
            .remove_robot(RobotId(id))
            .map_err(|e| sim_err("remove_robot", e))
    }
    #[pyo3(signature = (pos=None))]
    fn add_machine(&mut self, pos: Option<(f32, f32)>) -> PyResult<u32> {
        self.env
            .add_machine(position(pos))
            .map(|m| m.0)
            .map_err(|e| sim_err("add_machine", e))
    }
    fn remove_machine(&mut self, id: i64) -> PyResult<()> {
        let id = body_id("remove_machine", "machine", id)?;
        self.env
            .remove_machine(MachineId(id))
            .map_err(|e| sim_err("remove_machine", e))
    }
    #[pyo3(signature = (pos=None))]
    fn add_storage(&mut self, pos: Option<(f32, f32)>) -> PyResult<u32> {
        self.env
            .add_storage(position(pos))
            .map(|s| s.0)
            .map_err(|e| sim_err("add_storage", e))
    }
    fn remove_storage(&mut self, id: i64) -> PyResult<()> {
        let id = body_id("remove_storage", "storage", id)?;
        self.env
            .remove_storage(StorageId(id))
            .map_err(|e| sim_err("remove_storage", e))
    }
}

type Events<'py> = (
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<u32>>,
);
