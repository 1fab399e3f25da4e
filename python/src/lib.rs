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
//!
//! Where things are: [`env`] (`Sim`), [`vector`] (`VecSim`), [`spaces`] (actions and
//! observation arrays across the boundary), [`greedy`] (the scripted baseline on
//! observation arrays), [`render`] (RGB frames); here the module, its exception and the
//! argument conversions every class shares.

// Struct-of-arrays buffers indexed in lockstep, as in the sim crate.
#![allow(clippy::needless_range_loop)]

mod env;
mod greedy;
mod render;
mod spaces;
mod vector;

pub use env::Sim;
pub use vector::VecSim;

use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use sim::{episode_seed, Metrics, ScenarioConfig, Setup};

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
