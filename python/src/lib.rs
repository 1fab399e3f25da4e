//! `tending._native`: the simulator (`sim::Env`) for Python, the layer under the pure-Python
//! PettingZoo env in `python/tending/`.
//!
//! - [`Sim`]: one environment. Observations come out as four numpy arrays (the `obs`
//!   crate's entity groups: self, machines, storages, peers), written by Rust straight into
//!   freshly allocated numpy buffers; robots, machines and storages can be added and
//!   removed between steps.
//! - [`VecSim`]: N environments stepped on rayon in one call with the GIL released,
//!   numpy in and out, no per-agent Python objects.
//!
//! Every error is a Python exception: simulator refusals (`sim::SimError`) become
//! `tending.SimError` (a `ValueError`), bad argument types `TypeError`/`ValueError`. No
//! code path here unwraps on user input, so nothing panics across the FFI boundary.

// Struct-of-arrays buffers indexed in lockstep, as in the sim crate.
#![allow(clippy::needless_range_loop)]

use numpy::ndarray::{Array2, Array3};
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn,
    PyUntypedArrayMethods,
};
use obs::greedy::GreedyParams;
use obs::{FlatLayout, ObsBatch, MACHINE_DIM, PEER_DIM, SELF_DIM, STORAGE_DIM};
use pyo3::create_exception;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rayon::prelude::*;
use sim::{episode_seed, Env, MachineId, Metrics, RobotId, ScenarioConfig, Setup, StorageId};

create_exception!(
    _native,
    SimError,
    PyValueError,
    "The simulator refused an input (setup, config, action, position or id)."
);

fn sim_err(context: &str, e: sim::SimError) -> PyErr {
    SimError::new_err(format!("{context}: {e}"))
}

/// The scenario config from TOML text or JSON text (Python converts dicts to JSON); the
/// defaults of `sim/src/config.rs` when both are None.
fn parse_config(toml: Option<&str>, json: Option<&str>) -> PyResult<ScenarioConfig> {
    let cfg = match (toml, json) {
        (Some(_), Some(_)) => {
            return Err(PyValueError::new_err(
                "config: give TOML or a dict, not both",
            ))
        }
        (Some(t), None) => {
            ScenarioConfig::from_toml(t, "config").map_err(|e| sim_err("config", e))?
        }
        (None, Some(j)) => serde_json::from_str::<ScenarioConfig>(j)
            .map_err(|e| SimError::new_err(format!("config: {e}")))?,
        (None, None) => ScenarioConfig::default(),
    };
    cfg.validate().map_err(|e| sim_err("config", e))?;
    Ok(cfg)
}

fn parse_setup(setup: &str) -> PyResult<Setup> {
    setup.parse().map_err(|e| sim_err("setup", e))
}

/// Discrete actions from any integer numpy array (uint8, int32, int64, ...), each checked
/// to be one of 0..5 so a bad value names its position instead of wrapping around.
fn read_actions(
    actions: &Bound<'_, PyAny>,
    expected: usize,
    n_actions: usize,
) -> PyResult<Vec<u8>> {
    // Fast path, no numpy calls: a contiguous uint8 or int64 array (what the vector API
    // and most policies hand in).
    if let Ok(arr) = actions.extract::<PyReadonlyArrayDyn<'_, u8>>() {
        if let Ok(s) = arr.as_slice() {
            return check_actions(
                s.iter().map(|&a| a as i64),
                expected,
                n_actions,
                arr.shape(),
            );
        }
    }
    if let Ok(arr) = actions.extract::<PyReadonlyArrayDyn<'_, i64>>() {
        if let Ok(s) = arr.as_slice() {
            return check_actions(s.iter().copied(), expected, n_actions, arr.shape());
        }
    }
    let np = actions.py().import("numpy")?;
    let arr = np.call_method1("ascontiguousarray", (actions,))?;
    let kind: String = arr.getattr("dtype")?.getattr("kind")?.extract()?;
    if kind != "i" && kind != "u" {
        return Err(PyTypeError::new_err(format!(
            "actions: expected integers, got an array of dtype {}",
            arr.getattr("dtype")?.str()?
        )));
    }
    let arr = arr.call_method1("astype", ("int64",))?;
    let arr: PyReadonlyArrayDyn<'_, i64> = arr.extract()?;
    let s = arr
        .as_slice()
        .map_err(|e| PyValueError::new_err(format!("actions: {e}")))?;
    check_actions(s.iter().copied(), expected, n_actions, arr.shape())
}

fn check_actions(
    a: impl ExactSizeIterator<Item = i64>,
    expected: usize,
    n_actions: usize,
    shape: &[usize],
) -> PyResult<Vec<u8>> {
    if a.len() != expected {
        return Err(PyValueError::new_err(format!(
            "actions: expected {expected} actions (one per robot), got {} (shape {shape:?})",
            a.len()
        )));
    }
    a.enumerate()
        .map(|(i, a)| {
            if (0..n_actions as i64).contains(&a) {
                Ok(a as u8)
            } else {
                Err(PyValueError::new_err(format!(
                    "actions: action {a} at index {i} is not one of 0..{n_actions} ({})",
                    ACTION_NAMES
                )))
            }
        })
        .collect()
}

const ACTION_NAMES: &str = "0 stay, 1 left, 2 right, 3 down, 4 up; with diagonal_actions \
                            5 left-down, 6 right-down, 7 left-up, 8 right-up";

/// Actions per robot: the paper's 5, or 9 with the diagonals (`obs::action`).
fn n_actions(diagonal: bool) -> usize {
    if diagonal {
        obs::action::N_ACTIONS_WITH_DIAGONALS
    } else {
        obs::action::N_AXIS_ACTIONS
    }
}

fn metrics_dict<'py>(py: Python<'py>, m: &Metrics) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("parts_delivered", m.parts_delivered)?;
    d.set_item("parts_collected", m.parts_collected)?;
    d.set_item("collisions", m.collisions)?;
    d.set_item("collisions_robot_robot", m.collisions_robot_robot)?;
    d.set_item("collisions_robot_machine", m.collisions_robot_machine)?;
    d.set_item("collisions_robot_storage", m.collisions_robot_storage)?;
    d.set_item("collisions_robot_wall", m.collisions_robot_wall)?;
    d.set_item("p_max", m.p_max)?;
    d.set_item("mu", m.utilization())?;
    d.set_item("total_reward", m.total_reward)?;
    d.set_item("steps", m.steps)?;
    Ok(d)
}

fn position(pos: Option<(f32, f32)>) -> Option<[f32; 2]> {
    pos.map(|(x, y)| [x, y])
}

/// A numpy id (u32 in the simulator) from a Python int, refusing negatives clearly.
fn body_id(context: &str, kind: &str, id: i64) -> PyResult<u32> {
    u32::try_from(id).map_err(|_| SimError::new_err(format!("{context}: no {kind} with id {id}")))
}

/// Four zeroed numpy arrays for `rows` observation rows with `c` entity counts, shaped
/// `lead + (group, dim)`.
type ObsArrays<'py> = (
    Bound<'py, PyArrayDyn<f32>>,
    Bound<'py, PyArrayDyn<f32>>,
    Bound<'py, PyArrayDyn<f32>>,
    Bound<'py, PyArrayDyn<f32>>,
);

fn obs_arrays<'py>(py: Python<'py>, lead: &[usize], c: obs::Counts) -> ObsArrays<'py> {
    let shape = |tail: &[usize]| -> Vec<usize> { lead.iter().chain(tail).copied().collect() };
    (
        PyArrayDyn::zeros(py, shape(&[SELF_DIM]), false),
        PyArrayDyn::zeros(py, shape(&[c.machines, MACHINE_DIM]), false),
        PyArrayDyn::zeros(py, shape(&[c.storages, STORAGE_DIM]), false),
        PyArrayDyn::zeros(py, shape(&[c.peers, PEER_DIM]), false),
    )
}

/// Greedy actions (the scripted baseline of `tending sim --policy greedy`, the same
/// `obs::greedy` code `robot_node` runs) from observation arrays of `rows` robots.
fn greedy_rows(
    p: &GreedyParams,
    c: obs::Counts,
    rows: usize,
    [own, machines, storages, peers]: [&[f32]; 4],
    out: &mut [u8],
) {
    let (wm, ws, wp) = (
        c.machines * MACHINE_DIM,
        c.storages * STORAGE_DIM,
        c.peers * PEER_DIM,
    );
    for r in 0..rows {
        out[r] = sim::baselines::greedy_action(
            &own[r * SELF_DIM..(r + 1) * SELF_DIM],
            &machines[r * wm..(r + 1) * wm],
            &storages[r * ws..(r + 1) * ws],
            &peers[r * wp..(r + 1) * wp],
            p,
        );
    }
}

fn greedy_params(env: &Env) -> GreedyParams {
    sim::baselines::greedy_params(env.sizes(), env.config())
}

/// Read four observation arrays (as returned by `observe`) as contiguous f32 slices of
/// the expected sizes.
fn obs_inputs<'py>(
    arrays: [&Bound<'py, PyAny>; 4],
    expected: [usize; 4],
) -> PyResult<[PyReadonlyArrayDyn<'py, f32>; 4]> {
    const NAMES: [&str; 4] = ["own", "machines", "storages", "peers"];
    let mut out = Vec::with_capacity(4);
    for ((a, want), name) in arrays.into_iter().zip(expected).zip(NAMES) {
        let np = a.py().import("numpy")?;
        let a = np.call_method1("ascontiguousarray", (a, "float32"))?;
        let r: PyReadonlyArrayDyn<'py, f32> = a.extract()?;
        if r.len() != want {
            return Err(PyValueError::new_err(format!(
                "{name}: expected {want} values for the current entity counts, got {} (shape {:?})",
                r.len(),
                r.shape()
            )));
        }
        out.push(r);
    }
    out.try_into()
        .map_err(|_| PyValueError::new_err("four observation arrays expected"))
}

// ---- rendering ------------------------------------------------------------------------

/// An RGB frame of `env`, `px` x `px`, in the colours of `tending sim --render` (the
/// paper's Fig. 3: robots red with a yellow dot when carrying, ready machines green, idle
/// ones pale green, storages blue; a bar along the top edge shows episode time). A small
/// rasteriser of our own: the CLI's plotters renderer lives in the binary crate.
fn render_rgb(env: &Env, px: usize) -> Array3<u8> {
    let mut img = Array3::<u8>::from_elem((px, px, 3), 255);
    let room = env.config().world.room_size;
    let s = px as f32 / room;
    let to_px = |p: [f32; 2]| ((p[0] + room / 2.0) * s, (room / 2.0 - p[1]) * s);
    let clamp = |v: f32| (v.max(0.0) as usize).min(px);
    let fill_rect = |img: &mut Array3<u8>, x0: f32, y0: f32, x1: f32, y1: f32, c: [u8; 3]| {
        for y in clamp(y0)..clamp(y1) {
            for x in clamp(x0)..clamp(x1) {
                for k in 0..3 {
                    img[[y, x, k]] = c[k];
                }
            }
        }
    };
    let fill_disc = |img: &mut Array3<u8>, cx: f32, cy: f32, r: f32, c: [u8; 3]| {
        for y in clamp(cy - r)..clamp(cy + r + 1.0) {
            for x in clamp(cx - r)..clamp(cx + r + 1.0) {
                let (dx, dy) = (x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
                if dx * dx + dy * dy <= r * r {
                    for k in 0..3 {
                        img[[y, x, k]] = c[k];
                    }
                }
            }
        }
    };
    let mut boxes: Vec<([f32; 2], [f32; 2], [u8; 3])> = Vec::new();
    boxes.extend(env.storages().map(|b| (b.centre, b.half, [60, 90, 220])));
    boxes.extend(env.machines().map(|m| {
        let col = if m.part_ready {
            [30, 170, 60]
        } else {
            [170, 210, 170]
        };
        (m.centre, m.half, col)
    }));
    for (c, h, col) in boxes {
        let (x0, y0) = to_px([c[0] - h[0], c[1] + h[1]]);
        let (x1, y1) = to_px([c[0] + h[0], c[1] - h[1]]);
        fill_rect(&mut img, x0, y0, x1, y1, col);
    }
    let rp = (env.sizes().robot_radius * s).max(2.0);
    for r in env.robots() {
        let (cx, cy) = to_px(r.pos);
        fill_disc(&mut img, cx, cy, rp, [210, 40, 40]);
        if r.has_part {
            fill_disc(&mut img, cx, cy, (rp / 2.0).max(1.0), [250, 220, 40]);
        }
    }
    // Walls (2 px) and the episode-time bar.
    let w = px as f32;
    let border = (w / 230.0).max(1.0);
    for (x0, y0, x1, y1) in [
        (0.0, 0.0, w, border),
        (0.0, w - border, w, w),
        (0.0, 0.0, border, w),
        (w - border, 0.0, w, w),
    ] {
        fill_rect(&mut img, x0, y0, x1, y1, [0, 0, 0]);
    }
    let frac = env.steps() as f32 / env.config().world.episode_steps.max(1) as f32;
    fill_rect(
        &mut img,
        0.0,
        0.0,
        w * frac.min(1.0),
        2.0 * border,
        [0, 0, 0],
    );
    img
}

// ---- one environment ------------------------------------------------------------------

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
        let n = self.env.n_robots();
        let c = self.env.obs_counts();
        let [o, m, s, p] = obs_inputs(
            [own, machines, storages, peers],
            [
                n * SELF_DIM,
                n * c.machines * MACHINE_DIM,
                n * c.storages * STORAGE_DIM,
                n * c.peers * PEER_DIM,
            ],
        )?;
        let mut out = vec![0u8; n];
        greedy_rows(
            &greedy_params(&self.env),
            c,
            n,
            [o.as_slice()?, m.as_slice()?, s.as_slice()?, p.as_slice()?],
            &mut out,
        );
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

// ---- many environments ----------------------------------------------------------------

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

/// `n` chunks of `w` values; empty slices when `w` is 0 (a group with no entities, e.g.
/// the peers of a 1-robot setup), where `chunks_mut` would panic.
fn chunks(buf: &mut [f32], w: usize, n: usize) -> Vec<&mut [f32]> {
    if w == 0 {
        (0..n).map(|_| -> &mut [f32] { &mut [] }).collect()
    } else {
        buf.chunks_mut(w).collect()
    }
}

/// Write every env's observation into the four flat buffers (env-major), in parallel.
fn observe_all(envs: &[Env], n: usize, c: obs::Counts, bufs: [&mut [f32]; 4]) {
    let [o, m, s, p] = bufs;
    let w = [
        n * SELF_DIM,
        n * c.machines * MACHINE_DIM,
        n * c.storages * STORAGE_DIM,
        n * c.peers * PEER_DIM,
    ];
    let e_n = envs.len();
    let (co, cm, cs, cp) = (
        chunks(o, w[0], e_n),
        chunks(m, w[1], e_n),
        chunks(s, w[2], e_n),
        chunks(p, w[3], e_n),
    );
    envs.par_iter()
        .zip(co)
        .zip(cm)
        .zip(cs)
        .zip(cp)
        .for_each(|((((env, o), m), s), p)| env.observe_into(o, m, s, p));
}

type Events<'py> = (
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<u32>>,
);

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
    fn observe<'py>(&self, py: Python<'py>) -> PyResult<ObsArrays<'py>> {
        let arrs = obs_arrays(py, &[self.envs.len(), self.n], self.counts);
        {
            let (mut o, mut m, mut s, mut p) = (
                arrs.0.readwrite(),
                arrs.1.readwrite(),
                arrs.2.readwrite(),
                arrs.3.readwrite(),
            );
            let bufs = [
                o.as_slice_mut()?,
                m.as_slice_mut()?,
                s.as_slice_mut()?,
                p.as_slice_mut()?,
            ];
            let (envs, n, c) = (&self.envs, self.n, self.counts);
            py.allow_threads(|| observe_all(envs, n, c, bufs));
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
            let c = self.counts;
            // Each env steps and writes its observation in one task: one rayon pass, its
            // state still in cache.
            let (co, cm, cs, cp) = (
                chunks(o.as_slice_mut()?, n * SELF_DIM, e_n),
                chunks(m.as_slice_mut()?, n * c.machines * MACHINE_DIM, e_n),
                chunks(s.as_slice_mut()?, n * c.storages * STORAGE_DIM, e_n),
                chunks(p.as_slice_mut()?, n * c.peers * PEER_DIM, e_n),
            );
            let envs = &mut self.envs;
            py.allow_threads(|| {
                envs.par_iter_mut()
                    .zip(a.par_chunks(n))
                    .zip(rs.par_chunks_mut(n))
                    .zip(done.par_iter_mut())
                    .zip(co.into_par_iter().zip(cm).zip(cs).zip(cp))
                    .try_for_each(|((((env, a), r), d), (((o, m), s), p))| {
                        env.step_actions(a)?;
                        r.copy_from_slice(env.rewards());
                        *d = env.is_done();
                        env.observe_into(o, m, s, p);
                        Ok::<(), sim::SimError>(())
                    })
            })
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
        let w = [
            n * SELF_DIM,
            n * c.machines * MACHINE_DIM,
            n * c.storages * STORAGE_DIM,
            n * c.peers * PEER_DIM,
        ];
        let [o, m, s, p] = obs_inputs(
            [own, machines, storages, peers],
            [e_n * w[0], e_n * w[1], e_n * w[2], e_n * w[3]],
        )?;
        let (o, m, s, p) = (o.as_slice()?, m.as_slice()?, s.as_slice()?, p.as_slice()?);
        let mut out = vec![0u8; e_n * n];
        let params = greedy_params(&self.envs[0]);
        py.allow_threads(|| {
            out.par_chunks_mut(n).enumerate().for_each(|(e, out)| {
                fn sl(x: &[f32], w: usize, e: usize) -> &[f32] {
                    &x[e * w..(e + 1) * w]
                }
                greedy_rows(
                    &params,
                    c,
                    n,
                    [
                        sl(o, w[0], e),
                        sl(m, w[1], e),
                        sl(s, w[2], e),
                        sl(p, w[3], e),
                    ],
                    out,
                );
            })
        });
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

/// Seed of episode `episode` of environment `env` for base seed `base` (what `tending sim
/// --seed base` uses for its episode `episode` with env 0).
#[pyfunction(name = "episode_seed")]
fn py_episode_seed(base: u64, env: usize, episode: u64) -> u64 {
    episode_seed(base, env, episode)
}

/// Number of rayon threads the vector API steps on.
#[pyfunction]
fn num_threads() -> usize {
    rayon::current_num_threads()
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Sim>()?;
    m.add_class::<VecSim>()?;
    m.add_function(wrap_pyfunction!(py_episode_seed, m)?)?;
    m.add_function(wrap_pyfunction!(num_threads, m)?)?;
    m.add("SimError", m.py().get_type::<SimError>())?;
    m.add("N_ACTIONS", sim::N_ACTIONS)?;
    Ok(())
}
