//! The MAPPO baseline's flat observation: every group zero-padded to a configured maximum.
//!
//! Layout per row: own (3) | machines (max_machines x 3) | storages (max_storages x 2) |
//! peers (max_peers x 3). Padding slots are all zeros, as in the paper's zero-padding
//! strategy (section V-B), so a padded machine looks like "a machine at my position with no
//! part": that ambiguity is the baseline's known weakness, kept on purpose.

use crate::{ObsBatch, ObsError, MACHINE_DIM, PEER_DIM, SELF_DIM, STORAGE_DIM};

/// Value written into padding slots.
pub const FLAT_PAD: f32 = 0.0;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FlatLayout {
    pub max_machines: usize,
    pub max_storages: usize,
    pub max_peers: usize,
}

impl FlatLayout {
    pub fn dim(&self) -> usize {
        SELF_DIM
            + self.max_machines * MACHINE_DIM
            + self.max_storages * STORAGE_DIM
            + self.max_peers * PEER_DIM
    }

    /// Write the flat rows of `obs` into `out` (rows x dim). Fails if a group is larger
    /// than the layout's maximum: dropping entities silently would change the task.
    pub fn write(&self, obs: &ObsBatch, out: &mut Vec<f32>) -> Result<(), ObsError> {
        let c = obs.counts;
        for (field, got, max) in [
            ("machines", c.machines, self.max_machines),
            ("storages", c.storages, self.max_storages),
            ("peers", c.peers, self.max_peers),
        ] {
            if got > max {
                return Err(ObsError::WrongLength {
                    field,
                    got,
                    expected: max,
                });
            }
        }
        let d = self.dim();
        out.clear();
        out.resize(obs.rows * d, FLAT_PAD);
        for r in 0..obs.rows {
            let row = &mut out[r * d..(r + 1) * d];
            let mut o = 0;
            row[o..o + SELF_DIM].copy_from_slice(obs.own_row(r));
            o += SELF_DIM;
            let m = obs.machines_row(r);
            row[o..o + m.len()].copy_from_slice(m);
            o += self.max_machines * MACHINE_DIM;
            let s = obs.storages_row(r);
            row[o..o + s.len()].copy_from_slice(s);
            o += self.max_storages * STORAGE_DIM;
            let p = obs.peers_row(r);
            row[o..o + p.len()].copy_from_slice(p);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ObsBuilder;

    #[test]
    fn pads_with_zeros_and_refuses_overflow() {
        let b = ObsBuilder {
            own_pos: [0.1, 0.2],
            has_part: false,
            machines: vec![([0.3, 0.2], true)],
            storages: vec![[0.1, 0.0]],
            peers: vec![([0.0, 0.0], true)],
        }
        .build()
        .unwrap();
        let l = FlatLayout {
            max_machines: 2,
            max_storages: 1,
            max_peers: 2,
        };
        let mut out = Vec::new();
        l.write(&b, &mut out).unwrap();
        assert_eq!(out.len(), l.dim());
        assert_eq!(&out[0..3], &[0.1, 0.2, 0.0]);
        assert!((out[3] - 0.2).abs() < 1e-6 && out[5] == 1.0);
        assert_eq!(&out[6..9], &[0.0, 0.0, 0.0]); // padded machine
        let small = FlatLayout {
            max_machines: 0,
            max_storages: 1,
            max_peers: 2,
        };
        assert!(small.write(&b, &mut out).is_err());
    }
}
