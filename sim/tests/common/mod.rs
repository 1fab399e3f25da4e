#![allow(dead_code)]
use sim::layout::Layout;
use sim::{Env, ScenarioConfig, Setup};

/// A hand-made floor: robots, machines and storages at given positions, sizes of `setup`.
pub fn env_with(
    setup: &str,
    robots: &[[f32; 2]],
    machines: &[[f32; 2]],
    storages: &[[f32; 2]],
) -> Env {
    env_with_cfg(ScenarioConfig::default(), setup, robots, machines, storages)
}

pub fn env_with_cfg(
    cfg: ScenarioConfig,
    setup: &str,
    robots: &[[f32; 2]],
    machines: &[[f32; 2]],
    storages: &[[f32; 2]],
) -> Env {
    let setup: Setup = setup.parse().unwrap();
    Env::with_layout(
        cfg,
        setup,
        Layout {
            robots: robots.to_vec(),
            machines: machines.to_vec(),
            storages: storages.to_vec(),
        },
        0,
    )
    .unwrap()
}
