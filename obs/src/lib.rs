//! The one observation type of `tending`.
//!
//! The simulator builds it for every robot in training; `robot_node` builds it from ROS
//! topics on the robot. Both go through [`ObsBatch`], so the two paths cannot drift apart.
//!
//! An observation is a set of variable-size entity groups (paper section IV-C):
//! - self: absolute position (x, y) in metres, room centre at the origin, and `has_part`;
//! - machines: relative position (dx, dy) = machine - self, and `part_ready`;
//! - storages: relative position (dx, dy);
//! - peers (other robots): relative position (dx, dy) and their `has_part`.
//!
//! Flags are 0.0 or 1.0. A batch holds many rows (robots, possibly from many environments)
//! that share the same entity counts, stored row-major and contiguous so networks can run
//! one GEMM per group.
//!
//! The move table ([`action`]) lives here too: it is what an observation's actions mean, to the
//! simulator and to every controller above.
//!
//! What a robot does with its observation (the scripted controllers, the target menu, the
//! ORCA filter, the shield) is the planner's, in the `plan` crate above this one.

pub mod action;
pub mod defaults;
mod flat;
pub mod nearest;

pub use flat::{FlatLayout, FLAT_PAD};
pub use nearest::Bound;

/// Features of the robot itself: x, y, has_part.
pub const SELF_DIM: usize = 3;
/// Features of one machine: dx, dy, part_ready.
pub const MACHINE_DIM: usize = 3;
/// Features of one storage area: dx, dy.
pub const STORAGE_DIM: usize = 2;
/// Features of one other robot: dx, dy, has_part.
pub const PEER_DIM: usize = 3;

/// Entity counts shared by every row of a batch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Counts {
    pub machines: usize,
    pub storages: usize,
    pub peers: usize,
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ObsError {
    #[error("observation field `{field}` has a non-finite value ({value}) at index {index}")]
    NonFinite {
        field: &'static str,
        index: usize,
        value: f32,
    },
    #[error("observation field `{field}` has {got} values, expected {expected}")]
    WrongLength {
        field: &'static str,
        got: usize,
        expected: usize,
    },
    #[error("observation flag `{field}` at index {index} is {value}, expected 0 or 1")]
    BadFlag {
        field: &'static str,
        index: usize,
        value: f32,
    },
    #[error("observation batches have different entity counts: {a:?} vs {b:?}")]
    CountsMismatch { a: Counts, b: Counts },
}

/// A batch of observations; row `r` is one robot's view.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ObsBatch {
    pub rows: usize,
    pub counts: Counts,
    /// rows x SELF_DIM
    pub own: Vec<f32>,
    /// rows x machines x MACHINE_DIM
    pub machines: Vec<f32>,
    /// rows x storages x STORAGE_DIM
    pub storages: Vec<f32>,
    /// rows x peers x PEER_DIM
    pub peers: Vec<f32>,
}

impl ObsBatch {
    /// A zeroed batch of `rows` rows with the given counts.
    pub fn zeros(rows: usize, counts: Counts) -> Self {
        let mut b = Self::default();
        b.resize(rows, counts);
        b
    }

    /// Resize in place (reuses the allocations; values are zeroed only where new).
    pub fn resize(&mut self, rows: usize, counts: Counts) {
        self.rows = rows;
        self.counts = counts;
        self.own.resize(rows * SELF_DIM, 0.0);
        self.machines
            .resize(rows * counts.machines * MACHINE_DIM, 0.0);
        self.storages
            .resize(rows * counts.storages * STORAGE_DIM, 0.0);
        self.peers.resize(rows * counts.peers * PEER_DIM, 0.0);
    }

    pub fn own_row(&self, r: usize) -> &[f32] {
        &self.own[r * SELF_DIM..(r + 1) * SELF_DIM]
    }
    pub fn machines_row(&self, r: usize) -> &[f32] {
        let w = self.counts.machines * MACHINE_DIM;
        &self.machines[r * w..(r + 1) * w]
    }
    pub fn storages_row(&self, r: usize) -> &[f32] {
        let w = self.counts.storages * STORAGE_DIM;
        &self.storages[r * w..(r + 1) * w]
    }
    pub fn peers_row(&self, r: usize) -> &[f32] {
        let w = self.counts.peers * PEER_DIM;
        &self.peers[r * w..(r + 1) * w]
    }

    /// Append the rows of `other` (same counts required).
    pub fn extend_from(&mut self, other: &ObsBatch) -> Result<(), ObsError> {
        if self.rows == 0 && self.own.is_empty() {
            self.counts = other.counts;
        }
        if self.counts != other.counts {
            return Err(ObsError::CountsMismatch {
                a: self.counts,
                b: other.counts,
            });
        }
        self.rows += other.rows;
        self.own.extend_from_slice(&other.own);
        self.machines.extend_from_slice(&other.machines);
        self.storages.extend_from_slice(&other.storages);
        self.peers.extend_from_slice(&other.peers);
        Ok(())
    }

    /// Copy row `r` into a fresh single-row batch.
    pub fn row(&self, r: usize) -> ObsBatch {
        ObsBatch {
            rows: 1,
            counts: self.counts,
            own: self.own_row(r).to_vec(),
            machines: self.machines_row(r).to_vec(),
            storages: self.storages_row(r).to_vec(),
            peers: self.peers_row(r).to_vec(),
        }
    }

    /// Check lengths, finiteness and flags. Inputs that came from outside the process
    /// (the wire, a file) must pass this before they reach a policy.
    pub fn validate(&self) -> Result<(), ObsError> {
        let c = self.counts;
        let expect = [
            ("own", self.own.len(), self.rows * SELF_DIM),
            (
                "machines",
                self.machines.len(),
                self.rows * c.machines * MACHINE_DIM,
            ),
            (
                "storages",
                self.storages.len(),
                self.rows * c.storages * STORAGE_DIM,
            ),
            ("peers", self.peers.len(), self.rows * c.peers * PEER_DIM),
        ];
        for (field, got, expected) in expect {
            if got != expected {
                return Err(ObsError::WrongLength {
                    field,
                    got,
                    expected,
                });
            }
        }
        for (field, v) in [
            ("own", &self.own),
            ("machines", &self.machines),
            ("storages", &self.storages),
            ("peers", &self.peers),
        ] {
            if let Some((index, &value)) = v.iter().enumerate().find(|(_, x)| !x.is_finite()) {
                return Err(ObsError::NonFinite {
                    field,
                    index,
                    value,
                });
            }
        }
        let flags = [
            ("own.has_part", &self.own, SELF_DIM, 2),
            ("machines.part_ready", &self.machines, MACHINE_DIM, 2),
            ("peers.has_part", &self.peers, PEER_DIM, 2),
        ];
        for (field, v, dim, off) in flags {
            for (i, chunk) in v.chunks_exact(dim).enumerate() {
                let f = chunk[off];
                if f != 0.0 && f != 1.0 {
                    return Err(ObsError::BadFlag {
                        field,
                        index: i,
                        value: f,
                    });
                }
            }
        }
        Ok(())
    }
}

/// Builder for one robot's observation from plain entity lists (what `robot_node` has).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ObsBuilder {
    pub own_pos: [f32; 2],
    pub has_part: bool,
    /// absolute machine positions and part_ready
    pub machines: Vec<([f32; 2], bool)>,
    /// absolute storage positions
    pub storages: Vec<[f32; 2]>,
    /// absolute peer positions and has_part
    pub peers: Vec<([f32; 2], bool)>,
}

impl ObsBuilder {
    /// Keep only what `bound` lets the robot observe: the k nearest of each bounded group
    /// by the simulator's rule ([`nearest::Nearest`]), in the order given.
    pub fn bounded(mut self, bound: &Bound) -> Self {
        if !bound.is_bounded() {
            return self;
        }
        let mut pick = nearest::Nearest::default();
        let me = self.own_pos;
        let centres: Vec<[f32; 2]> = self.machines.iter().map(|m| m.0).collect();
        let keep = pick
            .select(me, &centres, bound.nearest_machines, None)
            .to_vec();
        self.machines = keep.iter().map(|&j| self.machines[j]).collect();
        let keep = pick
            .select(me, &self.storages, bound.nearest_storages, None)
            .to_vec();
        self.storages = keep.iter().map(|&j| self.storages[j]).collect();
        let centres: Vec<[f32; 2]> = self.peers.iter().map(|p| p.0).collect();
        let keep = pick
            .select(me, &centres, bound.nearest_peers, None)
            .to_vec();
        self.peers = keep.iter().map(|&j| self.peers[j]).collect();
        self
    }

    /// Build the single-row batch (relative positions computed here, as the simulator does).
    pub fn build(&self) -> Result<ObsBatch, ObsError> {
        let counts = Counts {
            machines: self.machines.len(),
            storages: self.storages.len(),
            peers: self.peers.len(),
        };
        let mut b = ObsBatch::zeros(1, counts);
        let [x, y] = self.own_pos;
        b.own.copy_from_slice(&[x, y, flag(self.has_part)]);
        for (i, (p, ready)) in self.machines.iter().enumerate() {
            b.machines[i * 3..i * 3 + 3].copy_from_slice(&[p[0] - x, p[1] - y, flag(*ready)]);
        }
        for (i, p) in self.storages.iter().enumerate() {
            b.storages[i * 2..i * 2 + 2].copy_from_slice(&[p[0] - x, p[1] - y]);
        }
        for (i, (p, hp)) in self.peers.iter().enumerate() {
            b.peers[i * 3..i * 3 + 3].copy_from_slice(&[p[0] - x, p[1] - y, flag(*hp)]);
        }
        b.validate()?;
        Ok(b)
    }
}

#[inline]
pub fn flag(b: bool) -> f32 {
    if b {
        1.0
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bounded_builder_keeps_the_nearest_in_order() {
        let b = ObsBuilder {
            own_pos: [0.0, 0.0],
            has_part: false,
            machines: vec![([3.0, 0.0], true), ([1.0, 0.0], false), ([2.0, 0.0], true)],
            storages: vec![[0.0, 5.0]],
            peers: vec![
                ([0.0, 0.5], true),
                ([9.0, 9.0], false),
                ([0.0, -1.0], false),
            ],
        };
        let k2 = b.clone().bounded(&Bound::nearest(2));
        assert_eq!(k2.machines, vec![([1.0, 0.0], false), ([2.0, 0.0], true)]);
        assert_eq!(k2.storages, vec![[0.0, 5.0]]);
        assert_eq!(k2.peers, vec![([0.0, 0.5], true), ([0.0, -1.0], false)]);
        assert_eq!(b.clone().bounded(&Bound::EVERYTHING), b);
    }

    #[test]
    fn builder_makes_relative_positions() {
        let b = ObsBuilder {
            own_pos: [0.5, -0.5],
            has_part: true,
            machines: vec![([1.0, 1.0], true)],
            storages: vec![[0.0, 0.0], [-1.0, 0.0]],
            peers: vec![],
        }
        .build()
        .unwrap();
        assert_eq!(b.own, vec![0.5, -0.5, 1.0]);
        assert_eq!(b.machines, vec![0.5, 1.5, 1.0]);
        assert_eq!(b.storages, vec![-0.5, 0.5, -1.5, 0.5]);
        assert_eq!(b.counts.peers, 0);
        assert!(b.peers.is_empty());
    }

    #[test]
    fn validate_rejects_nan_and_bad_lengths() {
        let mut b = ObsBatch::zeros(
            2,
            Counts {
                machines: 1,
                storages: 1,
                peers: 1,
            },
        );
        assert!(b.validate().is_ok());
        b.peers[4] = f32::NAN;
        assert!(matches!(
            b.validate(),
            Err(ObsError::NonFinite {
                field: "peers",
                index: 4,
                ..
            })
        ));
        b.peers[4] = 0.0;
        b.machines[2] = 0.5;
        assert!(matches!(b.validate(), Err(ObsError::BadFlag { .. })));
        b.machines[2] = 1.0;
        b.storages.pop();
        assert!(matches!(
            b.validate(),
            Err(ObsError::WrongLength {
                field: "storages",
                ..
            })
        ));
    }

    #[test]
    fn extend_requires_same_counts() {
        let mut a = ObsBatch::zeros(
            1,
            Counts {
                machines: 2,
                storages: 1,
                peers: 0,
            },
        );
        let b = ObsBatch::zeros(
            3,
            Counts {
                machines: 2,
                storages: 1,
                peers: 0,
            },
        );
        a.extend_from(&b).unwrap();
        assert_eq!(a.rows, 4);
        assert_eq!(a.row(3), b.row(0));
        let c = ObsBatch::zeros(
            1,
            Counts {
                machines: 1,
                storages: 1,
                peers: 0,
            },
        );
        assert!(a.extend_from(&c).is_err());
    }
}
