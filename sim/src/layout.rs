//! Deterministic layout generator: body sizes for a setup, and non-overlapping positions.
//!
//! Size rule: the unscaled footprint F = N*pi*r^2 + sum over boxes of (w+g)(h+g), where g
//! is the free gap kept around boxes (`box_gap_diameters` robot diameters). If F exceeds
//! `occupancy` x room area, every length is multiplied by s = sqrt(occupancy * room_area /
//! F) (all terms are areas, so they scale by s^2 and the covered fraction of the floor
//! stays at `occupancy`); otherwise s = 1. Reach scales with s too.
//!
//! Placement: storages, then machines, then robots, each sampled uniformly in the room
//! with rejection. Boxes keep `box_gap_diameters` robot diameters from each other and from
//! the walls, so a robot can pass between any two; robots keep a small clearance from
//! everything. A layout that cannot be placed in bounded tries is refused as not fitting.

use crate::entities::{Sizes, StaticBox};
use crate::{Floor, ScenarioConfig, Setup, SimError};
use rand::Rng;

const TRIES_PER_BODY: usize = 4000;
const LAYOUT_ATTEMPTS: usize = 20;

/// The unscaled footprint F of `setup`'s bodies, m^2 (module docs).
pub fn footprint(setup: Setup, cfg: &ScenarioConfig) -> f32 {
    let s = &cfg.sizes;
    let g = s.box_gap_diameters * 2.0 * s.robot_radius;
    setup.robots as f32 * std::f32::consts::PI * s.robot_radius * s.robot_radius
        + setup.machines as f32 * (s.machine_size[0] + g) * (s.machine_size[1] + g)
        + setup.storages as f32 * (s.storage_size[0] + g) * (s.storage_size[1] + g)
}

/// The setup whose density a grown floor keeps: the paper's first and training setup.
pub const GROWN_REFERENCE: Setup = Setup::new(6, 4, 2);

/// Side of the room `setup` is laid out in, metres: `world.room_size` on the paper's floor;
/// on a grown floor, the side at which the setup's unscaled footprint covers the fraction
/// of the floor that 6.4_2's covers in a room of `world.room_size` (never smaller than
/// that room). For the default sizes: 100.66_33 9.37 m, 300.200_100 16.2 m, 1000.666_333
/// 29.6 m.
pub fn room_for(setup: Setup, cfg: &ScenarioConfig) -> f32 {
    let room = cfg.world.room_size;
    match cfg.world.floor {
        Floor::Paper => room,
        Floor::Grown => {
            let density = footprint(GROWN_REFERENCE, cfg) / (room * room);
            (footprint(setup, cfg) / density).sqrt().max(room)
        }
    }
}

pub fn sizes_for(setup: Setup, cfg: &ScenarioConfig) -> Sizes {
    let s = &cfg.sizes;
    let room = room_for(setup, cfg);
    let room_area = room * room;
    let footprint = footprint(setup, cfg);
    let scale = if footprint > s.occupancy * room_area {
        (s.occupancy * room_area / footprint).sqrt()
    } else {
        1.0
    };
    Sizes {
        scale,
        robot_radius: s.robot_radius * scale,
        machine_half: [
            s.machine_size[0] * scale / 2.0,
            s.machine_size[1] * scale / 2.0,
        ],
        storage_half: [
            s.storage_size[0] * scale / 2.0,
            s.storage_size[1] * scale / 2.0,
        ],
        reach: cfg.task.reach * scale,
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    pub robots: Vec<[f32; 2]>,
    pub machines: Vec<[f32; 2]>,
    pub storages: Vec<[f32; 2]>,
}

/// Clearance between robots, and between robots and boxes, at spawn time (in radii).
const ROBOT_CLEARANCE_RADII: f32 = 0.25;

pub(crate) fn box_fits(room: f32, gap: f32, candidate: &StaticBox, boxes: &[StaticBox]) -> bool {
    let lim = room / 2.0;
    let [cx, cy] = candidate.centre;
    let [hx, hy] = candidate.half;
    if cx - hx < -lim + gap || cx + hx > lim - gap || cy - hy < -lim + gap || cy + hy > lim - gap {
        return false;
    }
    boxes.iter().all(|b| {
        (b.centre[0] - cx).abs() >= b.half[0] + hx + gap
            || (b.centre[1] - cy).abs() >= b.half[1] + hy + gap
    })
}

pub(crate) fn robot_fits(
    room: f32,
    radius: f32,
    p: [f32; 2],
    boxes: &[StaticBox],
    robots: &[[f32; 2]],
) -> bool {
    let lim = room / 2.0;
    let clear = radius * ROBOT_CLEARANCE_RADII;
    if p[0].abs() > lim - radius - clear || p[1].abs() > lim - radius - clear {
        return false;
    }
    if boxes
        .iter()
        .any(|b| !b.far(p, radius + clear) && b.signed_distance(p).0 < radius + clear)
    {
        return false;
    }
    let min2 = (2.0 * radius + clear) * (2.0 * radius + clear);
    robots.iter().all(|q| {
        let dx = q[0] - p[0];
        let dy = q[1] - p[1];
        dx * dx + dy * dy >= min2
    })
}

pub(crate) fn sample_box<R: Rng>(
    rng: &mut R,
    room: f32,
    gap: f32,
    half: [f32; 2],
    boxes: &[StaticBox],
    robots: &[[f32; 2]],
    robot_radius: f32,
) -> Option<StaticBox> {
    let lim = room / 2.0;
    let (mx, my) = (lim - half[0] - gap, lim - half[1] - gap);
    if mx <= 0.0 || my <= 0.0 {
        return None;
    }
    for _ in 0..TRIES_PER_BODY {
        let b = StaticBox {
            centre: [rng.gen_range(-mx..mx), rng.gen_range(-my..my)],
            half,
        };
        let clear_of_robots = robots
            .iter()
            .all(|&p| b.signed_distance(p).0 > robot_radius * (1.0 + ROBOT_CLEARANCE_RADII));
        if clear_of_robots && box_fits(room, gap, &b, boxes) {
            return Some(b);
        }
    }
    None
}

pub(crate) fn sample_robot<R: Rng>(
    rng: &mut R,
    room: f32,
    radius: f32,
    boxes: &[StaticBox],
    robots: &[[f32; 2]],
) -> Option<[f32; 2]> {
    let m = room / 2.0 - radius * (1.0 + ROBOT_CLEARANCE_RADII);
    if m <= 0.0 {
        return None;
    }
    for _ in 0..TRIES_PER_BODY {
        let p = [rng.gen_range(-m..m), rng.gen_range(-m..m)];
        if robot_fits(room, radius, p, boxes, robots) {
            return Some(p);
        }
    }
    None
}

/// Place every body of `setup`; the same rng state gives the same layout.
pub fn generate<R: Rng>(
    setup: Setup,
    cfg: &ScenarioConfig,
    sizes: &Sizes,
    rng: &mut R,
) -> Result<Layout, SimError> {
    let room = cfg.world.room_size;
    if sizes.robot_radius < cfg.sizes.min_robot_radius {
        return Err(SimError::DoesNotFit {
            setup: setup.to_string(),
            room,
            reason: format!(
                "robots would shrink to radius {:.4} m, below sizes.min_robot_radius {} m",
                sizes.robot_radius, cfg.sizes.min_robot_radius
            ),
        });
    }
    let gap = cfg.sizes.box_gap_diameters * 2.0 * sizes.robot_radius;
    let mut last_reason = String::new();
    'attempt: for _ in 0..LAYOUT_ATTEMPTS {
        let mut boxes: Vec<StaticBox> = Vec::with_capacity(setup.machines + setup.storages);
        let mut storages = Vec::with_capacity(setup.storages);
        let mut machines = Vec::with_capacity(setup.machines);
        for k in 0..setup.storages {
            match sample_box(rng, room, gap, sizes.storage_half, &boxes, &[], 0.0) {
                Some(b) => {
                    storages.push(b.centre);
                    boxes.push(b);
                }
                None => {
                    last_reason = format!("no room for storage {k} of {}", setup.storages);
                    continue 'attempt;
                }
            }
        }
        for j in 0..setup.machines {
            match sample_box(rng, room, gap, sizes.machine_half, &boxes, &[], 0.0) {
                Some(b) => {
                    machines.push(b.centre);
                    boxes.push(b);
                }
                None => {
                    last_reason = format!("no room for machine {j} of {}", setup.machines);
                    continue 'attempt;
                }
            }
        }
        let mut robots = Vec::with_capacity(setup.robots);
        for i in 0..setup.robots {
            match sample_robot(rng, room, sizes.robot_radius, &boxes, &robots) {
                Some(p) => robots.push(p),
                None => {
                    last_reason = format!("no room for robot {i} of {}", setup.robots);
                    continue 'attempt;
                }
            }
        }
        return Ok(Layout {
            robots,
            machines,
            storages,
        });
    }
    Err(SimError::DoesNotFit {
        setup: setup.to_string(),
        room,
        reason: format!("{last_reason} after {LAYOUT_ATTEMPTS} attempts"),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn check(setup: &str) {
        let cfg = ScenarioConfig::default();
        let setup: Setup = setup.parse().unwrap();
        let sizes = sizes_for(setup, &cfg);
        for seed in 0..5 {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let l = generate(setup, &cfg, &sizes, &mut rng)
                .unwrap_or_else(|e| panic!("{setup} seed {seed}: {e}"));
            assert_eq!(l.robots.len(), setup.robots);
            assert_eq!(l.machines.len(), setup.machines);
            let boxes: Vec<StaticBox> = l
                .machines
                .iter()
                .map(|&c| StaticBox {
                    centre: c,
                    half: sizes.machine_half,
                })
                .chain(l.storages.iter().map(|&c| StaticBox {
                    centre: c,
                    half: sizes.storage_half,
                }))
                .collect();
            for (i, &p) in l.robots.iter().enumerate() {
                assert!(robot_fits(
                    cfg.world.room_size,
                    sizes.robot_radius,
                    p,
                    &boxes,
                    &l.robots[..i]
                ));
            }
        }
    }

    #[test]
    fn every_paper_setup_fits() {
        for s in [
            "2.2_2", "4.2_2", "6.4_2", "8.6_2", "10.6_4", "12.8_4", "14.10_4", "18.12_6",
            "24.16_8", "30.20_10", "36.24_12", "42.28_14", "100.16_2",
        ] {
            check(s);
        }
    }

    #[test]
    fn sizes_shrink_only_when_needed() {
        let cfg = ScenarioConfig::default();
        let small = sizes_for("6.4_2".parse().unwrap(), &cfg);
        let big = sizes_for("100.16_2".parse().unwrap(), &cfg);
        assert_eq!(small.scale, 1.0);
        assert!(big.scale < 0.7 && big.robot_radius < small.robot_radius);
    }

    #[test]
    fn same_seed_same_layout() {
        let cfg = ScenarioConfig::default();
        let setup: Setup = "14.10_4".parse().unwrap();
        let sizes = sizes_for(setup, &cfg);
        let a = generate(
            setup,
            &cfg,
            &sizes,
            &mut rand_chacha::ChaCha8Rng::seed_from_u64(9),
        )
        .unwrap();
        let b = generate(
            setup,
            &cfg,
            &sizes,
            &mut rand_chacha::ChaCha8Rng::seed_from_u64(9),
        )
        .unwrap();
        let c = generate(
            setup,
            &cfg,
            &sizes,
            &mut rand_chacha::ChaCha8Rng::seed_from_u64(10),
        )
        .unwrap();
        assert_eq!(a, b);
        assert_ne!(a, c);
    }

    #[test]
    fn impossible_setup_is_refused() {
        let mut cfg = ScenarioConfig::default();
        cfg.sizes.occupancy = 0.6;
        cfg.sizes.box_gap_diameters = 6.0;
        let setup: Setup = "10.60_30".parse().unwrap();
        let sizes = sizes_for(setup, &cfg);
        let e = generate(
            setup,
            &cfg,
            &sizes,
            &mut rand_chacha::ChaCha8Rng::seed_from_u64(1),
        );
        assert!(matches!(e, Err(SimError::DoesNotFit { .. })), "{e:?}");
    }
}
