//! Uniform-grid broad phase for robot-robot pairs.
//!
//! Written here rather than taken from parry2d: parry's BVH is built for persistent,
//! heterogeneous colliders and costs a rebuild per step, while every robot here is a disc
//! of one radius and the room is small and bounded, so a counting sort into cells of one
//! interaction distance is exact, allocation-free after the first step, and keeps the cost
//! of a step linear in the robot count.

/// Up to this many robots, all pairs are visited directly (measured faster than the grid
/// walk, which visits every cell, at 14 robots in a 14x14 grid).
const BRUTE_FORCE_MAX: usize = 32;

#[derive(Debug, Clone, Default)]
pub(crate) struct Grid {
    cell: f32,
    origin: f32,
    dim: usize,
    /// start index of each cell in `sorted` (len dim*dim + 1)
    start: Vec<u32>,
    /// robot indices ordered by cell, stable in robot index within a cell
    sorted: Vec<u32>,
    cell_of: Vec<u32>,
}

impl Grid {
    /// A grid covering a square room of side `room` (centred at 0) with cells of side
    /// >= `interaction`. Bodies outside the room are clamped into the border cells.
    pub fn new(room: f32, interaction: f32) -> Self {
        let dim = ((room / interaction).floor() as usize).clamp(1, 4096);
        Self {
            cell: room / dim as f32,
            origin: -room / 2.0,
            dim,
            start: vec![0; dim * dim + 1],
            sorted: Vec::new(),
            cell_of: Vec::new(),
        }
    }

    #[inline]
    fn coord(&self, v: f32) -> usize {
        let c = ((v - self.origin) / self.cell) as isize;
        c.clamp(0, self.dim as isize - 1) as usize
    }

    pub fn rebuild(&mut self, pos: &[[f32; 2]]) {
        let n = pos.len();
        self.cell_of.resize(n, 0);
        self.sorted.resize(n, 0);
        if n <= BRUTE_FORCE_MAX {
            return; // for_each_pair visits all pairs directly
        }
        self.start.iter_mut().for_each(|s| *s = 0);
        for (i, p) in pos.iter().enumerate() {
            let c = (self.coord(p[1]) * self.dim + self.coord(p[0])) as u32;
            self.cell_of[i] = c;
            self.start[c as usize + 1] += 1;
        }
        for k in 1..self.start.len() {
            self.start[k] += self.start[k - 1];
        }
        // Stable placement: walk robots in index order with a moving cursor per cell.
        // `start[c]` is used as the cursor and restored afterwards.
        for i in 0..n {
            let c = self.cell_of[i] as usize;
            let at = self.start[c];
            self.sorted[at as usize] = i as u32;
            self.start[c] += 1;
        }
        for c in (1..self.start.len()).rev() {
            self.start[c] = self.start[c - 1];
        }
        self.start[0] = 0;
    }

    /// Calls `f(i, j)` once for every pair i < j of robots in the same or adjacent cells
    /// (for small fleets: every pair, which is cheaper than walking mostly empty cells).
    #[inline]
    pub fn for_each_pair(&self, mut f: impl FnMut(usize, usize)) {
        let n = self.cell_of.len();
        if n <= BRUTE_FORCE_MAX {
            for i in 0..n {
                for j in i + 1..n {
                    f(i, j);
                }
            }
            return;
        }
        let d = self.dim;
        for cy in 0..d {
            for cx in 0..d {
                let c = cy * d + cx;
                let (s, e) = (self.start[c] as usize, self.start[c + 1] as usize);
                if s == e {
                    continue;
                }
                // Same cell.
                for a in s..e {
                    for b in a + 1..e {
                        let (i, j) = (self.sorted[a] as usize, self.sorted[b] as usize);
                        f(i.min(j), i.max(j));
                    }
                }
                // Half of the neighbours (E, NE, N, NW) so each cell pair is visited once.
                for (dx, dy) in [(1isize, 0isize), (1, 1), (0, 1), (-1, 1)] {
                    let nx = cx as isize + dx;
                    let ny = cy as isize + dy;
                    if nx < 0 || ny < 0 || nx >= d as isize || ny >= d as isize {
                        continue;
                    }
                    let nc = ny as usize * d + nx as usize;
                    let (ns, ne) = (self.start[nc] as usize, self.start[nc + 1] as usize);
                    for a in s..e {
                        for b in ns..ne {
                            let (i, j) = (self.sorted[a] as usize, self.sorted[b] as usize);
                            f(i.min(j), i.max(j));
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn small_fleets_visit_all_pairs_once() {
        let pos: Vec<[f32; 2]> = (0..5).map(|i| [i as f32 * 0.3 - 0.6, 0.0]).collect();
        let mut g = Grid::new(2.3, 0.1);
        g.rebuild(&pos);
        let mut n = 0;
        g.for_each_pair(|i, j| {
            assert!(i < j);
            n += 1;
        });
        assert_eq!(n, 10);
    }

    #[test]
    fn finds_every_close_pair_exactly_once() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let pos: Vec<[f32; 2]> = (0..300)
            .map(|_| [rng.gen_range(-1.15..1.15), rng.gen_range(-1.15..1.15)])
            .collect();
        let r = 0.1;
        let mut g = Grid::new(2.3, r);
        g.rebuild(&pos);
        let mut found = std::collections::HashSet::new();
        g.for_each_pair(|i, j| {
            assert!(i < j);
            assert!(found.insert((i, j)), "pair visited twice");
        });
        for i in 0..pos.len() {
            for j in i + 1..pos.len() {
                let d = ((pos[i][0] - pos[j][0]).powi(2) + (pos[i][1] - pos[j][1]).powi(2)).sqrt();
                if d < r {
                    assert!(found.contains(&(i, j)), "missed close pair {i},{j}");
                }
            }
        }
    }
}
