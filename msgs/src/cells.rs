//! Spatial cell topics (docs/adr/0038-cell-topics.md): the floor cut into square cells,
//! each cell's state (every robot, machine and storage in it) published as one
//! `nav_msgs/msg/Path` per step on `/tending/cells/c<i>_<j>`, so a robot reads the cells
//! around it instead of every entity's topics.
//!
//! One pose per entity: `header.frame_id` names it (`robot_3`, `machine_2`, `storage_0`,
//! the namespaces of the per-entity topics), `header.stamp` is the step's stamp,
//! `pose.position` its centre and `pose.position.z` its flag (1 = has a part / part ready,
//! 0 = not; always 0 for a storage). The Path's own header is `map` and the step's stamp.
//! Cell (i, j) covers x in [-h + i s, -h + (i+1) s) and y likewise, for a room of half
//! extent h and cells of side s; positions outside the room fall in the nearest cell.

use crate::topics::{parse_topic, Entity, FRAME_ID};
use crate::types::{Header, Path, PoseStamped, Time};
use crate::validate::{self, InvalidMsg, RoomBounds};

/// Prefix of every cell topic.
pub const PREFIX: &str = "/tending/cells/";

/// One cell of a [`CellGrid`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Cell {
    pub i: u32,
    pub j: u32,
}

impl Cell {
    /// The cell's topic, `/tending/cells/c<i>_<j>`.
    pub fn ros_name(&self) -> String {
        format!("{PREFIX}c{}_{}", self.i, self.j)
    }

    /// Chebyshev distance in cells.
    pub fn steps_to(&self, o: &Cell) -> u32 {
        self.i.abs_diff(o.i).max(self.j.abs_diff(o.j))
    }
}

/// A cell topic's name (ROS form `/tending/cells/c3_4` or DDS form `rt/tending/...`).
pub fn parse_cell_topic(name: &str) -> Option<Cell> {
    let ros = name.strip_prefix("rt").unwrap_or(name);
    let (i, j) = ros
        .strip_prefix(PREFIX)?
        .strip_prefix('c')?
        .split_once('_')?;
    let num = |s: &str| {
        (!s.is_empty()
            && s.bytes().all(|b| b.is_ascii_digit())
            && (s == "0" || !s.starts_with('0')))
        .then(|| s.parse().ok())
        .flatten()
    };
    Some(Cell {
        i: num(i)?,
        j: num(j)?,
    })
}

/// The floor's cells: a square room of half extent `half_extent` centred at the origin,
/// cut into cells of side `size` (the last row and column may be narrower).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellGrid {
    pub half_extent: f64,
    pub size: f64,
}

/// A grid that cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("cell size {size} m for a room of {room} m: must be positive and finite")]
pub struct BadGrid {
    pub size: f64,
    pub room: f64,
}

impl CellGrid {
    pub fn new(room_size: f64, size: f64) -> Result<Self, BadGrid> {
        if !(size.is_finite() && size > 0.0 && room_size.is_finite() && room_size > 0.0) {
            return Err(BadGrid {
                size,
                room: room_size,
            });
        }
        Ok(Self {
            half_extent: room_size / 2.0,
            size,
        })
    }

    /// Cells per side.
    pub fn per_side(&self) -> u32 {
        ((2.0 * self.half_extent / self.size).ceil() as u32).max(1)
    }

    fn index(&self, v: f64) -> u32 {
        let k = ((v + self.half_extent) / self.size).floor();
        if k.is_nan() || k < 0.0 {
            0
        } else {
            (k as u32).min(self.per_side() - 1)
        }
    }

    /// The cell holding (x, y) (the nearest one for a point outside the room).
    pub fn cell_of(&self, xy: [f64; 2]) -> Cell {
        Cell {
            i: self.index(xy[0]),
            j: self.index(xy[1]),
        }
    }

    /// Every cell, row by row.
    pub fn all(&self) -> impl Iterator<Item = Cell> {
        let n = self.per_side();
        (0..n).flat_map(move |j| (0..n).map(move |i| Cell { i, j }))
    }

    /// The cells at most `reach` cells from `c` (3 x 3 for reach 1), inside the room.
    pub fn around(&self, c: Cell, reach: u32) -> impl Iterator<Item = Cell> {
        let n = self.per_side();
        let lo = |v: u32| v.saturating_sub(reach);
        let hi = move |v: u32| (v + reach).min(n - 1);
        let (i0, i1, j0, j1) = (lo(c.i), hi(c.i), lo(c.j), hi(c.j));
        (j0..=j1).flat_map(move |j| (i0..=i1).map(move |i| Cell { i, j }))
    }

    /// How far from `xy` everything is surely in the cells within `reach` of its cell:
    /// the distance to the nearest edge of that window that is not a wall (beyond a wall
    /// there is nothing to miss). Infinite when the window is the whole room.
    pub fn covered_radius(&self, xy: [f64; 2], reach: u32) -> f64 {
        let c = self.cell_of(xy);
        let n = self.per_side();
        let h = self.half_extent;
        let mut r = f64::INFINITY;
        for (v, k) in [(xy[0], c.i), (xy[1], c.j)] {
            if k >= reach {
                r = r.min(v - (-h + (k - reach) as f64 * self.size));
            }
            if k + reach + 1 < n {
                r = r.min((-h + (k + reach + 1) as f64 * self.size) - v);
            }
        }
        r.max(0.0)
    }
}

/// One entity of a cell's state.
#[derive(Debug, Clone, PartialEq)]
pub struct CellEntry {
    pub entity: Entity,
    pub xy: [f64; 2],
    /// has_part (robot), part_ready (machine), false (storage).
    pub flag: bool,
}

/// A cell message that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BadCell {
    #[error("pose {index}: {source}")]
    Pose { index: usize, source: InvalidMsg },
    #[error("pose {index}: frame_id {name:?} names no robot, machine or storage")]
    Name { index: usize, name: String },
    #[error("pose {index} ({name}): position.z {z} is not a flag (0 or 1)")]
    Flag { index: usize, name: String, z: f64 },
}

/// The name an entity goes by in a cell message (its namespace without the slash).
pub fn entity_name(e: &Entity) -> String {
    e.namespace().trim_start_matches('/').to_string()
}

/// One cell's state at `stamp`.
pub fn encode(stamp: Time, entries: &[CellEntry]) -> Path {
    Path {
        header: Header {
            stamp,
            frame_id: FRAME_ID.to_string(),
        },
        poses: entries
            .iter()
            .map(|e| {
                let mut p = PoseStamped::planar(stamp, &entity_name(&e.entity), e.xy[0], e.xy[1]);
                p.pose.position.z = if e.flag { 1.0 } else { 0.0 };
                p
            })
            .collect(),
    }
}

/// Read one cell's state, every pose validated as a per-entity pose is (finite, inside
/// `room`): the first bad entry refuses the whole message.
pub fn decode(path: &Path, room: &RoomBounds) -> Result<Vec<CellEntry>, BadCell> {
    path.poses
        .iter()
        .enumerate()
        .map(|(index, p)| {
            let name = &p.header.frame_id;
            let entity = parse_topic(&format!("/{name}/pose"))
                .map(|t| t.entity)
                .ok_or_else(|| BadCell::Name {
                    index,
                    name: name.clone(),
                })?;
            let xy = validate::pose_stamped(p, room)
                .map_err(|source| BadCell::Pose { index, source })?;
            let z = p.pose.position.z;
            let flag = if z == 1.0 {
                true
            } else if z == 0.0 {
                false
            } else {
                return Err(BadCell::Flag {
                    index,
                    name: name.clone(),
                    z,
                });
            };
            Ok(CellEntry { entity, xy, flag })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> CellGrid {
        CellGrid::new(10.0, 3.0).unwrap() // 4 cells per side, the last 1 m wide
    }

    #[test]
    fn cells_cover_the_room() {
        let g = grid();
        assert_eq!(g.per_side(), 4);
        assert_eq!(g.cell_of([-5.0, -5.0]), Cell { i: 0, j: 0 });
        assert_eq!(g.cell_of([-2.01, 0.5]), Cell { i: 0, j: 1 });
        assert_eq!(g.cell_of([-1.99, 0.5]), Cell { i: 1, j: 1 });
        assert_eq!(g.cell_of([4.9, 5.2]), Cell { i: 3, j: 3 }); // beyond the wall: nearest
        assert_eq!(g.cell_of([-7.0, f64::NAN]), Cell { i: 0, j: 0 });
        assert_eq!(g.all().count(), 16);
        assert!(CellGrid::new(10.0, 0.0).is_err());
        assert!(CellGrid::new(10.0, f64::NAN).is_err());
    }

    #[test]
    fn neighbourhood_is_clipped_at_the_walls() {
        let g = grid();
        assert_eq!(g.around(Cell { i: 1, j: 1 }, 1).count(), 9);
        assert_eq!(g.around(Cell { i: 0, j: 0 }, 1).count(), 4);
        assert_eq!(g.around(Cell { i: 3, j: 1 }, 1).count(), 6);
        assert_eq!(g.around(Cell { i: 0, j: 0 }, 9).count(), 16);
    }

    #[test]
    fn covered_radius_ignores_walls() {
        let g = grid();
        // in cell (1,1) = [-2, 1) x [-2, 1): the window [-5, 4) x [-5, 4), walls at -5
        assert!((g.covered_radius([0.0, 0.5], 1) - 3.5).abs() < 1e-12);
        assert_eq!(g.covered_radius([0.0, 0.0], 3), f64::INFINITY);
    }

    #[test]
    fn topic_names_round_trip() {
        let c = Cell { i: 12, j: 0 };
        assert_eq!(c.ros_name(), "/tending/cells/c12_0");
        assert_eq!(parse_cell_topic("/tending/cells/c12_0"), Some(c));
        assert_eq!(parse_cell_topic("rt/tending/cells/c12_0"), Some(c));
        for bad in [
            "/tending/cells/c1",
            "/tending/cells/c01_2",
            "/tending/cells/x1_2",
            "/c1_2",
        ] {
            assert_eq!(parse_cell_topic(bad), None, "{bad}");
        }
    }

    #[test]
    fn entries_round_trip_and_bad_ones_are_named() {
        let room = RoomBounds {
            half_extent: 5.0,
            margin: 0.25,
        };
        let e = vec![
            CellEntry {
                entity: Entity::Robot("robot_3".into()),
                xy: [1.0, -2.0],
                flag: true,
            },
            CellEntry {
                entity: Entity::Machine(2),
                xy: [0.5, 0.5],
                flag: false,
            },
            CellEntry {
                entity: Entity::Storage(0),
                xy: [-4.0, 4.0],
                flag: false,
            },
        ];
        let p = encode(Time { sec: 1, nanosec: 5 }, &e);
        assert_eq!(p.poses[0].header.frame_id, "robot_3");
        assert_eq!(decode(&p, &room).unwrap(), e);
        let mut bad = p.clone();
        bad.poses[1].pose.position.x = f64::NAN;
        assert!(matches!(
            decode(&bad, &room),
            Err(BadCell::Pose { index: 1, .. })
        ));
        let mut bad = p.clone();
        bad.poses[2].header.frame_id = "tending".into();
        assert!(matches!(
            decode(&bad, &room),
            Err(BadCell::Name { index: 2, .. })
        ));
        let mut bad = p;
        bad.poses[0].pose.position.z = 0.5;
        assert!(matches!(
            decode(&bad, &room),
            Err(BadCell::Flag { index: 0, .. })
        ));
    }
}
