//! The greedy scripted baseline on observation arrays (what `greedy_actions` returns).

use obs::greedy::GreedyParams;
use obs::MACHINE_DIM;
use obs::PEER_DIM;
use obs::SELF_DIM;
use obs::STORAGE_DIM;
use sim::Env;

/// Greedy actions (the scripted baseline of `tending sim --policy greedy`, the same
/// `obs::greedy` code `robot_node` runs) from observation arrays of `rows` robots.
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
        out[r] = sim::baselines::greedy_action(
            &own[r * SELF_DIM..(r + 1) * SELF_DIM],
            &machines[r * wm..(r + 1) * wm],
            &storages[r * ws..(r + 1) * ws],
            &peers[r * wp..(r + 1) * wp],
            p,
        );
    }
}

pub(crate) fn greedy_params(env: &Env) -> GreedyParams {
    sim::baselines::greedy_params(env.sizes(), env.config())
}
