//! Target actions: the policy chooses *where* to go, the robot drives there straight.
//!
//! The paper's actions are 5 axis moves, and a learned policy behind the ORCA filter loses
//! to greedy-ORCA mostly on motion: axis moves cover 1.27x the straight distance, and a
//! policy that learned its task allocation by shoving cannot shove behind the filter
//! (docs/RESULTS.md section 7.2). With target actions the policy keeps what it can be
//! better at than a script (which machine to serve, when to wait where, which storage
//! to use) and leaves motion to the part that is already good at it: a straight line at
//! up to K_speed to a point just inside reach, through ORCA (`crate::orca`).
//!
//! The menu has a fixed size whatever the entity counts, so one trained head works on every
//! setup (zero-shot). Ranks are by distance from the robot, ties by observation order.
//! A target that does not exist on this step (no second ready machine, one storage) means
//! "stay": the policy sees the flags and counts, and learns not to ask for it.

use crate::greedy::{claimed_by_a_nearer_peer, greedy_target, GreedyParams, Target};
use crate::{MACHINE_DIM, PEER_DIM, STORAGE_DIM};

/// Number of target actions.
pub const N_TARGET_ACTIONS: usize = 7;

/// The menu, by action index.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum TargetAction {
    /// Zero velocity.
    Stay = 0,
    /// The greedy script's choice ([`greedy_target`]): nearest unclaimed ready machine, or
    /// the nearest storage with a part. A policy that always picks it is greedy-ORCA.
    Greedy = 1,
    /// Nearest machine with a ready part that no nearer part-less peer claims (greedy's
    /// claim rule). Claim-aware since ADR 0017: contesting a claimed machine cost up to a
    /// quarter of the parts on machine-rich, storage-bound setups (80.40_4, 40.40_2).
    NearestReady = 2,
    /// Second-nearest machine with a ready part.
    SecondReady = 3,
    /// Nearest machine without a ready part that no nearer part-less peer claims (greedy's
    /// claim rule): wait there for the next one. Claim-aware since ADR 0015: without the
    /// claim, half of an idle fleet queued at the same few busy machines.
    NearestBusy = 4,
    /// Nearest storage area.
    NearestStorage = 5,
    /// Second-nearest storage area (a less crowded one).
    SecondStorage = 6,
}

impl TargetAction {
    pub fn from_index(a: u8) -> Option<Self> {
        use TargetAction::*;
        Some(match a {
            0 => Stay,
            1 => Greedy,
            2 => NearestReady,
            3 => SecondReady,
            4 => NearestBusy,
            5 => NearestStorage,
            6 => SecondStorage,
            _ => return None,
        })
    }

    /// Short name for tables and logs.
    pub fn name(self) -> &'static str {
        use TargetAction::*;
        match self {
            Stay => "stay",
            Greedy => "greedy",
            NearestReady => "nearest-ready",
            SecondReady => "second-ready",
            NearestBusy => "nearest-busy",
            NearestStorage => "nearest-storage",
            SecondStorage => "second-storage",
        }
    }
}

/// The box target action `a` heads for on this observation row (layout of `ObsBatch`), or
/// None for "stay" (asked for, or the ranked box does not exist). An index outside the
/// menu is None too: callers check the policy's action count once, at load.
pub fn target(
    a: u8,
    own: &[f32],
    machines: &[f32],
    storages: &[f32],
    peers: &[f32],
    p: &GreedyParams,
) -> Option<Target> {
    use TargetAction::*;
    // The `rank`-th nearest machine that `keep` accepts.
    let machine = |rank: usize, keep: &dyn Fn(&[f32]) -> bool| {
        nth_nearest(machines, MACHINE_DIM, rank, keep).map(|rel| Target {
            rel,
            half: p.machine_half,
        })
    };
    let ready = |m: &[f32]| m[2] > 0.5;
    let storage = |rank: usize| {
        nth_nearest(storages, STORAGE_DIM, rank, |_| true).map(|rel| Target {
            rel,
            half: p.storage_half,
        })
    };
    match TargetAction::from_index(a)? {
        Stay => None,
        Greedy => {
            debug_assert_eq!(peers.len() % PEER_DIM, 0);
            greedy_target(own, machines, storages, peers, p)
        }
        NearestReady => machine(0, &|m| ready(m) && !claimed_by_a_nearer_peer(m, peers)),
        SecondReady => machine(1, &ready),
        NearestBusy => machine(0, &|m| !ready(m) && !claimed_by_a_nearer_peer(m, peers)),
        NearestStorage => storage(0),
        SecondStorage => storage(1),
    }
}

/// Relative position of the `rank`-th nearest entity (0 = nearest) among those `keep`
/// accepts; entities are `dim` floats starting with (dx, dy). Fixed-size scan, no
/// allocation: ranks are at most 1 here, so two passes beat a sort.
fn nth_nearest(
    entities: &[f32],
    dim: usize,
    rank: usize,
    keep: impl Fn(&[f32]) -> bool,
) -> Option<[f32; 2]> {
    let mut best: [Option<(f32, usize)>; 2] = [None, None];
    for (i, e) in entities.chunks_exact(dim).enumerate() {
        if !keep(e) {
            continue;
        }
        let d = e[0] * e[0] + e[1] * e[1];
        // Strict `<`: ties keep observation order.
        if best[0].is_none_or(|(b, _)| d < b) {
            best[1] = best[0];
            best[0] = Some((d, i));
        } else if best[1].is_none_or(|(b, _)| d < b) {
            best[1] = Some((d, i));
        }
    }
    let (_, i) = (*best.get(rank)?)?;
    Some([entities[i * dim], entities[i * dim + 1]])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> GreedyParams {
        GreedyParams {
            robot_radius: 0.05,
            machine_half: [0.1, 0.1],
            ..GreedyParams::default()
        }
    }

    // Machines: far ready, busy, near ready; storages: far, near.
    const MACHINES: [f32; 9] = [1.0, 0.0, 1.0, 0.3, 0.0, 0.0, 0.0, 0.5, 1.0];
    const STORAGES: [f32; 4] = [-1.0, -1.0, 0.0, -0.4];

    fn rel(a: TargetAction, own: &[f32], peers: &[f32]) -> Option<[f32; 2]> {
        target(a as u8, own, &MACHINES, &STORAGES, peers, &params()).map(|t| t.rel)
    }

    #[test]
    fn menu_ranks_boxes_by_distance() {
        let own = [0.0, 0.0, 0.0];
        assert_eq!(rel(TargetAction::Stay, &own, &[]), None);
        assert_eq!(rel(TargetAction::NearestReady, &own, &[]), Some([0.0, 0.5]));
        assert_eq!(rel(TargetAction::SecondReady, &own, &[]), Some([1.0, 0.0]));
        assert_eq!(rel(TargetAction::NearestBusy, &own, &[]), Some([0.3, 0.0]));
        assert_eq!(
            rel(TargetAction::NearestStorage, &own, &[]),
            Some([0.0, -0.4])
        );
        assert_eq!(
            rel(TargetAction::SecondStorage, &own, &[]),
            Some([-1.0, -1.0])
        );
        let t = target(5, &own, &MACHINES, &STORAGES, &[], &params()).unwrap();
        assert_eq!(t.half, params().storage_half);
    }

    #[test]
    fn greedy_is_the_scripts_choice() {
        let own = [0.0, 0.0, 0.0];
        // A part-less peer right next to the near ready machine claims it.
        let peers = [0.0, 0.45, 0.0];
        assert_eq!(rel(TargetAction::Greedy, &own, &[]), Some([0.0, 0.5]));
        assert_eq!(rel(TargetAction::Greedy, &own, &peers), Some([1.0, 0.0]));
        // With a part, greedy goes to the nearest storage.
        let loaded = [0.0, 0.0, 1.0];
        assert_eq!(rel(TargetAction::Greedy, &loaded, &[]), Some([0.0, -0.4]));
    }

    #[test]
    fn a_busy_machine_a_nearer_peer_claims_is_not_offered() {
        let own = [0.0, 0.0, 0.0];
        assert_eq!(rel(TargetAction::NearestBusy, &own, &[]), Some([0.3, 0.0]));
        // A part-less peer nearer to the busy machine claims it; no other busy machine.
        let empty_peer = [0.35, 0.05, 0.0];
        assert_eq!(rel(TargetAction::NearestBusy, &own, &empty_peer), None);
        // A peer carrying a part claims nothing, and a farther one does not either.
        let loaded_peer = [0.35, 0.05, 1.0];
        assert_eq!(
            rel(TargetAction::NearestBusy, &own, &loaded_peer),
            Some([0.3, 0.0])
        );
        let far_peer = [-0.5, 0.0, 0.0];
        assert_eq!(
            rel(TargetAction::NearestBusy, &own, &far_peer),
            Some([0.3, 0.0])
        );
    }

    #[test]
    fn a_ready_machine_a_nearer_peer_claims_is_not_offered() {
        let own = [0.0, 0.0, 0.0];
        // A part-less peer nearer to the near ready machine claims it (ADR 0017): the
        // entry names the next unclaimed ready machine, as greedy does.
        let empty_peer = [0.0, 0.45, 0.0];
        assert_eq!(
            rel(TargetAction::NearestReady, &own, &empty_peer),
            Some([1.0, 0.0])
        );
        // A peer carrying a part claims nothing.
        let loaded_peer = [0.0, 0.45, 1.0];
        assert_eq!(
            rel(TargetAction::NearestReady, &own, &loaded_peer),
            Some([0.0, 0.5])
        );
        // The second-nearest entry still ranks every ready machine, claimed or not.
        assert_eq!(
            rel(TargetAction::SecondReady, &own, &empty_peer),
            Some([1.0, 0.0])
        );
        // Every ready machine claimed: the entry is missing (stay, ADR 0014).
        let two_peers = [0.0, 0.45, 0.0, 0.95, 0.0, 0.0];
        assert_eq!(rel(TargetAction::NearestReady, &own, &two_peers), None);
    }

    #[test]
    fn missing_ranks_and_unknown_actions_mean_stay() {
        let own = [0.0, 0.0, 0.0];
        let one_storage = [0.2, 0.2];
        let p = params();
        assert!(target(6, &own, &MACHINES, &one_storage, &[], &p).is_none());
        assert!(target(5, &own, &MACHINES, &one_storage, &[], &p).is_some());
        // No busy machine at all.
        let all_ready = [1.0, 0.0, 1.0];
        assert!(target(4, &own, &all_ready, &STORAGES, &[], &p).is_none());
        assert!(target(3, &own, &all_ready, &STORAGES, &[], &p).is_none());
        assert!(target(N_TARGET_ACTIONS as u8, &own, &MACHINES, &STORAGES, &[], &p).is_none());
        for a in 0..N_TARGET_ACTIONS as u8 {
            assert_eq!(TargetAction::from_index(a).map(|t| t as u8), Some(a));
        }
    }
}
