//! What a robot knows of the floor when it reads cell topics instead of every entity's
//! (`cell_size:=S`, docs/adr/0038-cell-topics.md): the latest state of each cell near it.
//! It reads the cells within `reach` of its own cell (3 x 3 for reach 1), and more rings
//! of cells while its k nearest of some group could still lie outside them (fewer than k
//! inside, or the k-th farther than the window's nearest inner edge): its observation is
//! then exactly the simulator's k nearest (`obs::nearest`), and what it reads is bounded
//! by the density around it, not the size of the fleet. Each cell topic is pinned to one writer like an entity topic
//! (docs/adr/0004-writer-pinning.md); the entities in a cell are the cell writer's word.
//!
//! DDS-free and deterministic, like [`crate::world`].

use std::cell::Cell as Shared;
use std::collections::BTreeMap;
use std::sync::Arc;

use msgs::cells::{Cell, CellEntry, CellGrid};
use msgs::Entity;

use crate::sample::{admit, Accepted, DropReason, PeerKey, Sample, WriterId};

/// One decoded cell message: its step stamp and entities.
#[derive(Debug, Clone, PartialEq)]
pub struct CellContent {
    pub stamp: i64,
    pub entries: Vec<CellEntry>,
    /// Its CDR size (traffic counters).
    pub bytes: usize,
}

/// The cells a robot reads: the grid, how far around its own cell it looks, and the
/// latest sample of each cell within one cell more (kept so a robot crossing into a
/// neighbouring cell already has it).
#[derive(Debug, Clone)]
pub struct CellView {
    pub grid: CellGrid,
    /// The fewest rings of cells read around the robot's own.
    pub reach: u32,
    /// The rings read now: `reach`, widened until the bound's k nearest are surely in.
    wide: Shared<u32>,
    latest: BTreeMap<Cell, Sample<Arc<CellContent>>>,
}

/// The entities of some cells in the simulator's order: machines and storages by id,
/// peers in natural name order (`robot_2` before `robot_10`), without the robot itself.
pub struct Gathered {
    pub machines: Vec<([f32; 2], bool)>,
    pub storages: Vec<[f32; 2]>,
    pub peers: Vec<([f32; 2], bool)>,
}

impl CellView {
    pub fn new(grid: CellGrid, reach: u32) -> Self {
        Self {
            grid,
            reach,
            wide: Shared::new(reach),
            latest: BTreeMap::new(),
        }
    }

    /// The rings of cells read now.
    pub fn rings(&self) -> u32 {
        self.wide.get()
    }

    /// The cells the robot at `own` reads now.
    pub fn needed(&self, own: [f64; 2]) -> impl Iterator<Item = Cell> + '_ {
        self.grid.around(self.grid.cell_of(own), self.wide.get())
    }

    /// Widen (or narrow back) the window around `own` to the fewest rings, from `reach`
    /// on, whose cells surely hold the `bound`'s nearest of every group: every cell of
    /// it `usable`, and in each bounded group at least k entities (peers other than `me`)
    /// with the k-th nearer than [`CellGrid::covered_radius`]; an unbounded group needs
    /// the whole room. Stops at the first ring with an unusable cell (waited for).
    /// Returns the cells of the window that are not usable.
    pub fn settle_window(
        &self,
        me: &str,
        own: [f64; 2],
        bound: &obs::Bound,
        usable: impl Fn(&Sample<Arc<CellContent>>) -> bool,
    ) -> usize {
        let whole = self.grid.per_side();
        let mut r = self.reach;
        loop {
            self.wide.set(r);
            let (cells, missing) = self.split(own, &usable);
            if missing > 0 || r >= whole {
                return missing;
            }
            let radius = self.grid.covered_radius(own, r);
            if radius.is_infinite() {
                return 0;
            }
            let entries = cells.iter().flat_map(|c| &c.entries);
            let mut d: [Vec<f64>; 3] = Default::default();
            for e in entries {
                let g = match &e.entity {
                    Entity::Machine(_) => 0,
                    Entity::Storage(_) => 1,
                    Entity::Robot(n) if n != me => 2,
                    Entity::Robot(_) => continue,
                };
                d[g].push(((e.xy[0] - own[0]).powi(2) + (e.xy[1] - own[1]).powi(2)).sqrt());
            }
            let ks = [
                bound.nearest_machines,
                bound.nearest_storages,
                bound.nearest_peers,
            ];
            let covered = ks.iter().zip(d.iter_mut()).all(|(k, ds)| match *k {
                None => false,
                Some(0) => true,
                Some(k) if ds.len() < k => false,
                Some(k) => {
                    ds.select_nth_unstable_by(k - 1, f64::total_cmp);
                    // a margin over f32 rounding: the simulator ranks in f32
                    ds[k - 1] < radius - 1e-4
                }
            });
            if covered {
                return 0;
            }
            r += 1;
        }
    }

    /// A cell's state arrived. Cells more than one ring outside the window are not its
    /// business (another robot of the process reads them): `Ok(None)`, not stored. Others
    /// are stored if the cell's writer pin allows, as for an entity topic; `Ok(Some(_))`
    /// for a cell of the window (what the robot reads and counts), `Ok(None)` for the ring
    /// kept around it.
    pub fn on_cell(
        &mut self,
        cell: Cell,
        content: &Arc<CellContent>,
        writer: WriterId,
        own: Option<[f64; 2]>,
        now: f64,
        release_s: f64,
    ) -> Result<Option<Accepted>, DropReason> {
        if let Some(own) = own {
            let mine = self.grid.cell_of(own);
            let keep = self.wide.get() + 1;
            if cell.steps_to(&mine) > keep {
                return Ok(None);
            }
            // forget what the robot has moved away from
            self.latest.retain(|c, _| c.steps_to(&mine) <= keep);
        }
        let held = self.latest.get(&cell).cloned();
        let accepted = admit(&held, writer, now, release_s)?;
        // kept but outside the window: not read now (a robot alone would not subscribe)
        let read = own.is_none_or(|o| cell.steps_to(&self.grid.cell_of(o)) <= self.wide.get());
        self.latest.insert(
            cell,
            Sample {
                value: Arc::clone(content),
                at: now,
                stamp: Some(content.stamp),
                writer,
            },
        );
        Ok(read.then_some(accepted))
    }

    /// Cells the robot at `own` reads that satisfy `usable` (fresh, or of one stamp), and
    /// how many it reads that do not.
    fn split(
        &self,
        own: [f64; 2],
        usable: impl Fn(&Sample<Arc<CellContent>>) -> bool,
    ) -> (Vec<&CellContent>, usize) {
        let mut ok = Vec::new();
        let mut missing = 0;
        for c in self.needed(own) {
            match self.latest.get(&c).filter(|s| usable(s)) {
                Some(s) => ok.push(s.value.as_ref()),
                None => missing += 1,
            }
        }
        (ok, missing)
    }

    /// Cells the robot `me` at `own` reads (its window settled on step `stamp`) whose
    /// latest sample is not of that step.
    pub fn missing_at(&self, me: &str, own: [f64; 2], bound: &obs::Bound, stamp: i64) -> usize {
        self.settle_window(me, own, bound, |s| s.stamp == Some(stamp))
    }

    /// Cells the robot `me` at `own` reads with no sample at all yet.
    pub fn without_data(&self, me: &str, own: [f64; 2], bound: &obs::Bound) -> usize {
        self.settle_window(me, own, bound, |_| true)
    }

    /// The entities of the cells the robot `me` at `own` reads, taking each cell's
    /// latest sample if `usable`.
    pub fn gather(
        &self,
        me: &str,
        own: [f64; 2],
        usable: impl Fn(&Sample<Arc<CellContent>>) -> bool,
    ) -> Gathered {
        let (cells, _) = self.split(own, usable);
        let f = |p: [f64; 2]| [p[0] as f32, p[1] as f32];
        let mut machines = Vec::new();
        let mut storages = Vec::new();
        let mut peers = Vec::new();
        for e in cells.iter().flat_map(|c| &c.entries) {
            match &e.entity {
                Entity::Machine(j) => machines.push((*j, f(e.xy), e.flag)),
                Entity::Storage(k) => storages.push((*k, f(e.xy))),
                Entity::Robot(r) if r != me => peers.push((PeerKey::new(r), f(e.xy), e.flag)),
                Entity::Robot(_) => {}
            }
        }
        machines.sort_by_key(|m| m.0);
        storages.sort_by_key(|s| s.0);
        peers.sort_by(|a, b| a.0.cmp(&b.0));
        Gathered {
            machines: machines.into_iter().map(|(_, p, r)| (p, r)).collect(),
            storages: storages.into_iter().map(|(_, p)| p).collect(),
            peers: peers.into_iter().map(|(_, p, h)| (p, h)).collect(),
        }
    }

    /// How far from `own` the robot surely sees everything (see
    /// [`CellGrid::covered_radius`]).
    pub fn covered_radius(&self, own: [f64; 2]) -> f64 {
        self.grid.covered_radius(own, self.wide.get())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn content(stamp: i64, entries: Vec<CellEntry>) -> Arc<CellContent> {
        Arc::new(CellContent {
            stamp,
            entries,
            bytes: 0,
        })
    }
    fn robot(name: &str, x: f64, y: f64) -> CellEntry {
        CellEntry {
            entity: Entity::Robot(name.into()),
            xy: [x, y],
            flag: false,
        }
    }
    const W: WriterId = [1; 16];

    /// A 10 m room in 1 m cells; the robot at (0.5, 0.5) is in cell (5, 5).
    fn view() -> CellView {
        CellView::new(CellGrid::new(10.0, 1.0).unwrap(), 1)
    }

    #[test]
    fn reads_only_the_cells_around_it_and_orders_peers_naturally() {
        let mut v = view();
        let own = [0.5, 0.5];
        let c = |i, j| Cell { i, j };
        let near = content(
            7,
            vec![robot("robot_10", 1.2, 0.5), robot("robot_2", 1.4, 0.2)],
        );
        let self_cell = content(7, vec![robot("me", 0.5, 0.5)]);
        let two_away = content(7, vec![robot("robot_1", 2.5, 0.5)]);
        let far = content(7, vec![robot("robot_0", 4.5, 0.5)]);
        assert!(v
            .on_cell(c(6, 5), &near, W, Some(own), 0.0, 1.0)
            .unwrap()
            .is_some());
        assert!(v
            .on_cell(c(5, 5), &self_cell, W, Some(own), 0.0, 1.0)
            .unwrap()
            .is_some());
        // one cell beyond the reach is kept (the robot may move there), not observed
        assert_eq!(
            v.on_cell(c(7, 5), &two_away, W, Some(own), 0.0, 1.0),
            Ok(None)
        );
        assert_eq!(v.on_cell(c(9, 5), &far, W, Some(own), 0.0, 1.0), Ok(None));
        let g = v.gather("me", own, |_| true);
        assert_eq!(g.peers, vec![([1.4, 0.2], false), ([1.2, 0.5], false)]);
        let b = obs::Bound::nearest(1);
        assert_eq!(v.missing_at("me", own, &b, 7), 9 - 2);
        assert_eq!(v.without_data("me", own, &b), 7);
        assert!((v.covered_radius(own) - 1.5).abs() < 1e-12);
    }

    #[test]
    fn the_window_widens_until_the_k_nearest_are_surely_inside() {
        let mut v = view();
        let own = [0.5, 0.5]; // cell (5, 5); reach 1 covers 1.5 m around
        let b = obs::Bound::nearest(1);
        let m = |j, x: f64| CellEntry {
            entity: Entity::Machine(j),
            xy: [x, 0.5],
            flag: false,
        };
        let s = |k, x: f64| CellEntry {
            entity: Entity::Storage(k),
            xy: [x, 0.5],
            flag: false,
        };
        // a machine and a peer next door, the nearest storage 2.5 m away (cell (8, 5))
        for i in 3..=7 {
            for j in 3..=7 {
                let e = match (i, j) {
                    (6, 5) => vec![m(0, 1.2), robot("robot_1", 1.3, 0.5)],
                    _ => vec![],
                };
                v.on_cell(Cell { i, j }, &content(3, e), W, Some(own), 0.0, 1.0)
                    .unwrap();
            }
        }
        // no storage in 3 x 3 nor 5 x 5: widened to 7 x 7, whose outer ring is missing
        assert_eq!(v.missing_at("me", own, &b, 3), 7 * 7 - 5 * 5);
        assert_eq!(v.rings(), 3);
        let far = content(3, vec![s(0, 3.0)]);
        for j in 2..=8 {
            for i in [2, 8] {
                let e = if (i, j) == (8, 5) {
                    far.clone()
                } else {
                    content(3, vec![])
                };
                v.on_cell(Cell { i, j }, &e, W, Some(own), 0.0, 1.0)
                    .unwrap();
            }
            if (3..=7).contains(&j) {
                continue;
            }
            for i in 3..=7 {
                v.on_cell(Cell { i, j }, &content(3, vec![]), W, Some(own), 0.0, 1.0)
                    .unwrap();
            }
        }
        // with 7 x 7 (3.5 m covered) the storage 2.5 m away is surely the nearest
        assert_eq!(v.missing_at("me", own, &b, 3), 0);
        assert_eq!(v.rings(), 3);
        assert_eq!(v.gather("me", own, |_| true).storages, vec![[3.0, 0.5]]);
    }

    #[test]
    fn a_second_writer_is_refused_while_the_first_is_fresh() {
        let mut v = view();
        let own = Some([0.5, 0.5]);
        let cell = Cell { i: 5, j: 5 };
        let a = content(1, vec![]);
        assert!(v.on_cell(cell, &a, W, own, 0.0, 1.0).is_ok());
        assert_eq!(
            v.on_cell(cell, &a, [2; 16], own, 0.5, 1.0),
            Err(DropReason::ForeignWriter)
        );
        assert_eq!(
            v.on_cell(cell, &a, [2; 16], own, 2.0, 1.0),
            Ok(Some(Accepted::NewWriter))
        );
    }
}
