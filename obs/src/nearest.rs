//! The k nearest entities of a group: the one selection rule of a bounded observation,
//! used by the simulator and by robot_node alike, so the two cannot disagree on which
//! entities a robot sees.
//!
//! Rule: squared centre distance, ties broken by the lower index; the chosen indices are
//! returned in increasing index order (the group's own order), so that k at least the
//! group's size gives exactly the unbounded observation.

use std::cmp::Ordering;

/// What each robot observes (docs/adr/0037). `None` (the default, the paper's) observes
/// every entity of the group; `Some(k)` only the k nearest by centre distance, listed in
/// the group's own order, so that with k at least the group's size the observation is
/// exactly the unbounded one. Every row of a batch then has min(k, count) entities.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Bound {
    pub nearest_machines: Option<usize>,
    pub nearest_storages: Option<usize>,
    pub nearest_peers: Option<usize>,
}

impl Bound {
    /// Observe everything (the paper's observation).
    pub const EVERYTHING: Self = Self {
        nearest_machines: None,
        nearest_storages: None,
        nearest_peers: None,
    };

    /// The k nearest of every group.
    pub const fn nearest(k: usize) -> Self {
        Self {
            nearest_machines: Some(k),
            nearest_storages: Some(k),
            nearest_peers: Some(k),
        }
    }

    pub fn is_bounded(&self) -> bool {
        *self != Self::EVERYTHING
    }

    /// How many of `available` entities of a group bounded by `k` a robot observes.
    pub fn observed(k: Option<usize>, available: usize) -> usize {
        k.map_or(available, |k| k.min(available))
    }

    /// A short label for tables: "all" or "k 8/8/4" (machines/storages/peers).
    pub fn label(&self) -> String {
        if !self.is_bounded() {
            return "all".into();
        }
        let f = |k: Option<usize>| k.map_or("all".to_string(), |k| k.to_string());
        format!(
            "nearest {}/{}/{}",
            f(self.nearest_machines),
            f(self.nearest_storages),
            f(self.nearest_peers)
        )
    }
}

/// Reusable buffers for [`Nearest::select`] (no allocation once warm).
#[derive(Debug, Clone, Default)]
pub struct Nearest {
    cand: Vec<(f32, usize)>,
    out: Vec<usize>,
}

impl Nearest {
    /// Indices of the `k` entities of `centres` nearest to `p` (every one when `k` is None
    /// or not smaller than the group), leaving out index `skip` (the robot itself among its
    /// peers), in increasing index order.
    pub fn select(
        &mut self,
        p: [f32; 2],
        centres: &[[f32; 2]],
        k: Option<usize>,
        skip: Option<usize>,
    ) -> &[usize] {
        self.out.clear();
        let available = centres.len() - usize::from(skip.is_some_and(|s| s < centres.len()));
        let keep = |j: &usize| Some(*j) != skip;
        match k {
            Some(k) if k < available => {
                self.cand.clear();
                self.cand
                    .extend(
                        centres
                            .iter()
                            .enumerate()
                            .filter(|(j, _)| keep(j))
                            .map(|(j, c)| {
                                let (dx, dy) = (c[0] - p[0], c[1] - p[1]);
                                (dx * dx + dy * dy, j)
                            }),
                    );
                if k > 0 {
                    let by = |a: &(f32, usize), b: &(f32, usize)| -> Ordering {
                        a.0.total_cmp(&b.0).then(a.1.cmp(&b.1))
                    };
                    self.cand.select_nth_unstable_by(k - 1, by);
                    self.out.extend(self.cand[..k].iter().map(|c| c.1));
                    self.out.sort_unstable();
                }
            }
            _ => self.out.extend((0..centres.len()).filter(keep)),
        }
        &self.out
    }
}

/// A uniform grid over a group's centres, for k-nearest queries whose cost is bounded by
/// the neighbourhood rather than the group: a query visits rings of cells outward from
/// the robot's cell and stops once the k-th candidate is nearer than any unvisited cell
/// can be. Same rule and same answer as [`Nearest::select`] (tested against it); written
/// here because the k-d tree crates answer k-nearest without our tie rule and rebuild
/// slower than this counting sort, which runs every step for the robots.
#[derive(Debug, Clone, Default)]
pub struct Grid {
    cell: f32,
    origin: [f32; 2],
    nx: usize,
    ny: usize,
    /// Cell c holds `items[starts[c]..starts[c + 1]]`.
    starts: Vec<usize>,
    items: Vec<usize>,
    centres: Vec<[f32; 2]>,
    cand: Vec<(f32, usize)>,
}

impl Grid {
    /// Index `centres` in cells holding about two centres each.
    pub fn build(&mut self, centres: &[[f32; 2]]) {
        self.centres.clear();
        self.centres.extend_from_slice(centres);
        let (mut lo, mut hi) = ([f32::MAX; 2], [f32::MIN; 2]);
        for c in centres {
            for a in 0..2 {
                lo[a] = lo[a].min(c[a]);
                hi[a] = hi[a].max(c[a]);
            }
        }
        if centres.is_empty() {
            (lo, hi) = ([0.0; 2], [0.0; 2]);
        }
        let span = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-3);
        let per_side = ((centres.len() as f32 / 2.0).sqrt().ceil() as usize).max(1);
        self.cell = span / per_side as f32;
        self.origin = lo;
        self.nx = ((hi[0] - lo[0]) / self.cell) as usize + 1;
        self.ny = ((hi[1] - lo[1]) / self.cell) as usize + 1;
        let cells = self.nx * self.ny;
        self.starts.clear();
        self.starts.resize(cells + 1, 0);
        for c in centres {
            let cell = self.cell_of(*c);
            self.starts[cell + 1] += 1;
        }
        for i in 0..cells {
            self.starts[i + 1] += self.starts[i];
        }
        self.items.clear();
        self.items.resize(centres.len(), 0);
        let mut fill = self.starts.clone();
        for (j, c) in centres.iter().enumerate() {
            let cell = self.cell_of(*c);
            self.items[fill[cell]] = j;
            fill[cell] += 1;
        }
    }

    fn coords(&self, p: [f32; 2]) -> (isize, isize) {
        (
            ((p[0] - self.origin[0]) / self.cell).floor() as isize,
            ((p[1] - self.origin[1]) / self.cell).floor() as isize,
        )
    }

    fn cell_of(&self, p: [f32; 2]) -> usize {
        let (x, y) = self.coords(p);
        let x = x.clamp(0, self.nx as isize - 1) as usize;
        let y = y.clamp(0, self.ny as isize - 1) as usize;
        y * self.nx + x
    }

    /// The `k` centres nearest `p` (every one when `k` is None), leaving out `skip`, in
    /// increasing index order: [`Nearest::select`]'s answer, into `out`.
    pub fn select(
        &mut self,
        p: [f32; 2],
        k: Option<usize>,
        skip: Option<usize>,
        out: &mut Vec<usize>,
    ) {
        out.clear();
        let n = self.centres.len();
        let available = n - usize::from(skip.is_some_and(|s| s < n));
        let k = match k {
            Some(k) if k < available => k,
            _ => {
                out.extend((0..n).filter(|j| Some(*j) != skip));
                return;
            }
        };
        if k == 0 {
            return;
        }
        self.cand.clear();
        let (cx, cy) = self.coords(p);
        let max_ring = (self.nx.max(self.ny) as isize) + cx.abs().max(cy.abs()) + 1;
        for ring in 0..=max_ring {
            for (x, y) in ring_cells(cx, cy, ring) {
                if x < 0 || y < 0 || x >= self.nx as isize || y >= self.ny as isize {
                    continue;
                }
                let c = y as usize * self.nx + x as usize;
                for &j in &self.items[self.starts[c]..self.starts[c + 1]] {
                    if Some(j) != skip {
                        let q = self.centres[j];
                        let (dx, dy) = (q[0] - p[0], q[1] - p[1]);
                        self.cand.push((dx * dx + dy * dy, j));
                    }
                }
            }
            if self.cand.len() >= k {
                let by = |a: &(f32, usize), b: &(f32, usize)| -> Ordering {
                    a.0.total_cmp(&b.0).then(a.1.cmp(&b.1))
                };
                self.cand.select_nth_unstable_by(k - 1, by);
                // Every centre outside rings 0..=ring is at least `ring` cells away
                // (strictly less would let a tie of a lower index hide beyond it).
                let reach = ring as f32 * self.cell;
                if self.cand[k - 1].0 < reach * reach {
                    break;
                }
            }
        }
        out.extend(self.cand[..k].iter().map(|c| c.1));
        out.sort_unstable();
    }
}

/// The cells at Chebyshev distance `r` from (cx, cy).
fn ring_cells(cx: isize, cy: isize, r: isize) -> impl Iterator<Item = (isize, isize)> {
    let side = (-r..=r).flat_map(move |d| {
        let edges = [(cx + d, cy - r), (cx + d, cy + r)];
        let sides = [(cx - r, cy + d), (cx + r, cy + d)];
        let inner = d > -r && d < r;
        edges
            .into_iter()
            .chain(sides.into_iter().filter(move |_| inner))
    });
    let centre = std::iter::once((cx, cy)).filter(move |_| r == 0);
    centre.chain(side.filter(move |_| r > 0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn picks_the_nearest_in_index_order_and_skips_self() {
        let c = [[0.0, 0.0], [5.0, 0.0], [1.0, 0.0], [0.0, 2.0], [0.5, 0.0]];
        let mut n = Nearest::default();
        // from robot 0 at the origin, its 2 nearest others: 4 (0.5 m) and 2 (1 m)
        assert_eq!(n.select([0.0, 0.0], &c, Some(2), Some(0)), &[2, 4]);
        assert_eq!(n.select([0.0, 0.0], &c, Some(3), Some(0)), &[2, 3, 4]);
        assert_eq!(n.select([0.0, 0.0], &c, Some(0), Some(0)), &[] as &[usize]);
    }

    #[test]
    fn k_at_least_the_group_is_everything_in_order() {
        let c = [[3.0, 0.0], [1.0, 0.0], [2.0, 0.0]];
        let mut n = Nearest::default();
        assert_eq!(n.select([0.0, 0.0], &c, None, None), &[0, 1, 2]);
        assert_eq!(n.select([0.0, 0.0], &c, Some(3), None), &[0, 1, 2]);
        assert_eq!(n.select([0.0, 0.0], &c, Some(2), Some(1)), &[0, 2]);
        assert_eq!(n.select([0.0, 0.0], &c, Some(1), None), &[1]);
    }

    #[test]
    fn ties_go_to_the_lower_index() {
        let c = [[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0]];
        let mut n = Nearest::default();
        assert_eq!(n.select([0.0, 0.0], &c, Some(2), None), &[0, 1]);
    }

    #[test]
    fn the_grid_answers_as_the_scan_does() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let mut scan = Nearest::default();
        let mut grid = Grid::default();
        let mut out = Vec::new();
        for n in [1usize, 2, 5, 40, 300] {
            let mut centres: Vec<[f32; 2]> = (0..n)
                .map(|_| [rng.gen_range(-9.0..9.0), rng.gen_range(-3.0..3.0)])
                .collect();
            if n > 4 {
                centres[3] = centres[1]; // an exact tie
            }
            grid.build(&centres);
            for q in 0..n.min(60) {
                let p = centres[q];
                for k in [None, Some(0), Some(1), Some(3), Some(8), Some(n)] {
                    grid.select(p, k, Some(q), &mut out);
                    assert_eq!(
                        out,
                        scan.select(p, &centres, k, Some(q)),
                        "n {n} q {q} k {k:?}"
                    );
                }
                let far = [40.0, -40.0];
                grid.select(far, Some(4), None, &mut out);
                assert_eq!(out, scan.select(far, &centres, Some(4), None));
            }
        }
    }
}
