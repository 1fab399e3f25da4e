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
}
