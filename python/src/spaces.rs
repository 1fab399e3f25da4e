//! Actions and observations across the FFI boundary: integer actions read from any numpy
//! array and checked, observation arrays allocated for Rust to fill and read back.

use numpy::PyArrayDyn;
use numpy::PyReadonlyArrayDyn;
use numpy::PyUntypedArrayMethods;
use obs::MACHINE_DIM;
use obs::PEER_DIM;
use obs::SELF_DIM;
use obs::STORAGE_DIM;
use pyo3::exceptions::PyTypeError;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// Discrete actions from any integer numpy array (uint8, int32, int64, ...), each checked
/// to be one of 0..5 so a bad value names its position instead of wrapping around.
pub(crate) fn read_actions(
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
pub(crate) fn n_actions(diagonal: bool) -> usize {
    if diagonal {
        obs::action::N_ACTIONS_WITH_DIAGONALS
    } else {
        obs::action::N_AXIS_ACTIONS
    }
}

/// Four zeroed numpy arrays for `rows` observation rows with `c` entity counts, shaped
/// `lead + (group, dim)`.
pub(crate) type ObsArrays<'py> = (
    Bound<'py, PyArrayDyn<f32>>,
    Bound<'py, PyArrayDyn<f32>>,
    Bound<'py, PyArrayDyn<f32>>,
    Bound<'py, PyArrayDyn<f32>>,
);

pub(crate) fn obs_arrays<'py>(py: Python<'py>, lead: &[usize], c: obs::Counts) -> ObsArrays<'py> {
    let shape = |tail: &[usize]| -> Vec<usize> { lead.iter().chain(tail).copied().collect() };
    (
        PyArrayDyn::zeros(py, shape(&[SELF_DIM]), false),
        PyArrayDyn::zeros(py, shape(&[c.machines, MACHINE_DIM]), false),
        PyArrayDyn::zeros(py, shape(&[c.storages, STORAGE_DIM]), false),
        PyArrayDyn::zeros(py, shape(&[c.peers, PEER_DIM]), false),
    )
}

/// Read four observation arrays (as returned by `observe`) as contiguous f32 slices of
/// the expected sizes.
pub(crate) fn obs_inputs<'py>(
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
