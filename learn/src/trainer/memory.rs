//! Memory bounds of training: the size of one mini-batch part and the estimate of a run's
//! peak memory that [`Trainer::new`](super::Trainer::new) checks against the machine's.

use super::super::config::TrainConfig;
use policy::config::ModelKind;
use sim::Setup;

/// Default [`Trainer::part_rows`].
pub(super) const PART_ROWS: usize = 16_384;

/// Activation memory one mini-batch part may take (actor + critic), which caps the part's
/// rows where a row is large (the MAPPO critic's input grows with robots squared). A
/// constant, not the machine's free memory, so results never depend on the machine.
const PART_BYTES: usize = 1 << 30;

/// Bytes of training state per row, measured in floats from the caches the networks keep
/// for backward (attention per group: ~1,600 floats plus 4 per entity; encoder, GRU head
/// ~2,100), for actor plus critic. Calibrated against the peak RSS of `train_bench
/// 100.16_2 8 1 1` (1.16 GB measured, 1.2 GB estimated).
fn part_row_bytes(kind: ModelKind, setup: Setup, cfg: &TrainConfig) -> usize {
    let ents = setup.machines + setup.storages + setup.robots.saturating_sub(1);
    let floats = match kind {
        ModelKind::Smappo => 2 * (7_000 + 12 * ents),
        ModelKind::Mappo => {
            let fd = obs::SELF_DIM
                + cfg.mappo_max_machines * obs::MACHINE_DIM
                + cfg.mappo_max_storages * obs::STORAGE_DIM
                + cfg.mappo_max_robots.saturating_sub(1) * obs::PEER_DIM;
            // actor: input, its LayerNorm output and their gradients; critic: its own
            // block's copies (flat, gamma-scaled, xhat, gradient; `factored_input`) and the
            // env block once per env-step (~2 fd per row), plus both heads
            4 * fd + 6 * fd + 4_000
        }
    };
    4 * floats
}

/// Obs floats per row of `setup`.
fn obs_floats(setup: Setup) -> usize {
    obs::SELF_DIM
        + setup.machines * obs::MACHINE_DIM
        + setup.storages * obs::STORAGE_DIM
        + setup.robots.saturating_sub(1) * obs::PEER_DIM
}

/// Rows of one mini-batch part for `setup`: `part_rows`, lowered so a part's activations
/// stay within [`PART_BYTES`].
pub(super) fn part_rows_for(
    kind: ModelKind,
    setup: Setup,
    cfg: &TrainConfig,
    part_rows: usize,
) -> usize {
    part_rows.min(PART_BYTES / part_row_bytes(kind, setup, cfg).max(1))
}

/// Estimated peak memory of training `setup` (bytes): the rollout (observations and
/// per-row scalars of `n_envs` x robots x steps rows), one mini-batch part's activations
/// and its gathered copies, and the row index of a whole mini-batch.
pub fn estimate_train_bytes(
    kind: ModelKind,
    setup: Setup,
    cfg: &TrainConfig,
    episode_steps: usize,
    part_rows: usize,
) -> usize {
    let rows = cfg.n_envs * setup.robots * episode_steps;
    let of = obs_floats(setup);
    let rollout = rows * 4 * (of + 10) + rows * 4 * 2 * 64 / cfg.data_chunk_length.max(1);
    let chunk = setup.robots * cfg.data_chunk_length;
    let part = part_rows_for(kind, setup, cfg, part_rows).max(chunk);
    let mb_rows = rows.div_ceil(cfg.num_mini_batch.max(1));
    let part = part.min(mb_rows);
    rollout + part * (part_row_bytes(kind, setup, cfg) + 3 * 4 * of) + mb_rows * 8
}

/// MemAvailable of /proc/meminfo in bytes (None where there is none).
pub(super) fn mem_available() -> Option<usize> {
    let s = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = s.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: usize = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}
