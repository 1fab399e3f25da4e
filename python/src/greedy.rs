//! The greedy scripted baseline on observation arrays (what `greedy_actions` returns).

use crate::spaces::obs_inputs;
use obs::MACHINE_DIM;
use obs::PEER_DIM;
use obs::SELF_DIM;
use obs::STORAGE_DIM;
use plan::greedy::GreedyParams;
use pyo3::prelude::*;
use rayon::prelude::*;
use sim::Env;

/// Greedy actions (the scripted baseline of `tending sim --policy greedy`, the same
/// `plan::greedy` code `robot_node` runs) from observation arrays of `rows` robots.
pub(crate) fn greedy_rows(
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
        out[r] = plan::greedy::greedy_action(
            &own[r * SELF_DIM..(r + 1) * SELF_DIM],
            &machines[r * wm..(r + 1) * wm],
            &storages[r * ws..(r + 1) * ws],
            &peers[r * wp..(r + 1) * wp],
            p,
        );
    }
}

/// `greedy_actions` of `Env` (one env) and `VectorEnv`: the actions of `envs` envs of `n`
/// robots from observation arrays in the layout of `observe()` (lengths checked), env
/// after env, computed on rayon with the GIL released.
pub(crate) fn greedy_actions(
    py: Python<'_>,
    p: &GreedyParams,
    c: obs::Counts,
    envs: usize,
    n: usize,
    arrays: [&Bound<'_, PyAny>; 4],
) -> PyResult<Vec<u8>> {
    // floats per env of each array
    let w = [
        n * SELF_DIM,
        n * c.machines * MACHINE_DIM,
        n * c.storages * STORAGE_DIM,
        n * c.peers * PEER_DIM,
    ];
    let [o, m, s, q] = obs_inputs(arrays, w.map(|w| envs * w))?;
    let (o, m, s, q) = (o.as_slice()?, m.as_slice()?, s.as_slice()?, q.as_slice()?);
    let mut out = vec![0u8; envs * n];
    if n == 0 {
        return Ok(out);
    }
    py.allow_threads(|| {
        out.par_chunks_mut(n).enumerate().for_each(|(e, out)| {
            fn sl(x: &[f32], w: usize, e: usize) -> &[f32] {
                &x[e * w..(e + 1) * w]
            }
            let rows = [
                sl(o, w[0], e),
                sl(m, w[1], e),
                sl(s, w[2], e),
                sl(q, w[3], e),
            ];
            greedy_rows(p, c, n, rows, out);
        })
    });
    Ok(out)
}

pub(crate) fn greedy_params(env: &Env) -> GreedyParams {
    learn::baselines::fleet_params(env.sizes(), env.config()).greedy_params()
}
