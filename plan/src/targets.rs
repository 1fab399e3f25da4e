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
use crate::matching::{matched_machine, storages_crowded};
use crate::storage_queue::{queued_storage_kept, storage_full, StorageMemory};
use obs::{MACHINE_DIM, PEER_DIM, STORAGE_DIM};

/// Number of target actions.
pub const N_TARGET_ACTIONS: usize = 8;

/// Menu size of checkpoints trained before [`TargetAction::Matched`] existed: their
/// outputs are the first 7 entries, whose meaning has not changed.
pub const N_TARGET_ACTIONS_V1: usize = 7;

/// Whether a policy with `n` outputs can run on this menu (the current one, or a prefix
/// of it that older checkpoints were trained on).
pub fn menu_size_ok(n: usize) -> bool {
    n == N_TARGET_ACTIONS || n == N_TARGET_ACTIONS_V1
}

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
    /// The machine this robot gets in a matching of every part-less robot it observes
    /// (itself included) to the machines ([`matched_machine`]): unlike the claim rule,
    /// which only asks whether a nearer peer exists, no two robots are sent to the same
    /// machine and no machine is left out while a robot is free. While the storages are
    /// crowded ([`crate::matching::MATCH_MAX_CARRIERS_PER_STORAGE`]): greedy's choice.
    /// With a part: the storage with the shortest trip counting its queue, or none (make
    /// room) while the storage is full ([`crate::storage_queue`]; until RESULTS 7.9 the
    /// nearest storage).
    Matched = 7,
}

impl TargetAction {
    /// Every entry, by action index (`ALL[a] as u8 == a`, tested): the one list
    /// [`Self::from_index`] reads.
    pub const ALL: [TargetAction; N_TARGET_ACTIONS] = {
        use TargetAction::*;
        [
            Stay,
            Greedy,
            NearestReady,
            SecondReady,
            NearestBusy,
            NearestStorage,
            SecondStorage,
            Matched,
        ]
    };

    /// The entry with action index `a`; None outside the menu.
    pub fn from_index(a: u8) -> Option<Self> {
        Self::ALL.get(a as usize).copied()
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
            Matched => "matched",
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
    let mut fresh = StorageMemory::default();
    let memory = PlannerMemory {
        storage: &mut fresh,
        ready_in: &[],
    };
    target_kept(a, own, machines, storages, peers, p, memory)
}

/// What a planner remembers between decisions, for [`target_kept`].
pub struct PlannerMemory<'a> {
    /// The storage a carrier chose ([`crate::storage_queue`]).
    pub storage: &'a mut StorageMemory,
    /// Steps until each machine has a part ([`crate::machine_clock`]); empty: none known.
    pub ready_in: &'a [Option<u32>],
}

/// [`target`] for a robot that remembers its storage choice between decisions
/// ([`crate::storage_queue::SWITCH_STEPS`]) and when each machine will be ready
/// ([`crate::machine_clock`]): the planner's path. The storage memory is cleared on every
/// entry but "matched" with a part.
pub fn target_kept(
    a: u8,
    own: &[f32],
    machines: &[f32],
    storages: &[f32],
    peers: &[f32],
    p: &GreedyParams,
    memory: PlannerMemory,
) -> Option<Target> {
    use TargetAction::*;
    let PlannerMemory {
        storage: memory,
        ready_in,
    } = memory;
    let action = TargetAction::from_index(a);
    if !(own[2] > 0.5 && action == Some(Matched)) {
        memory.clear();
    }
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
    match action? {
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
        // With a part: the storage with the shortest queue-counted trip, held back from
        // while it is full (`crate::storage_queue`), so that always asking for this entry
        // is a complete script (matching-ORCA, RESULTS 7.8-7.9).
        Matched if own[2] > 0.5 => {
            let k = queued_storage_kept(own, storages, peers, p, memory)?;
            let rel = [storages[k * STORAGE_DIM], storages[k * STORAGE_DIM + 1]];
            (!storage_full(rel, peers, p)).then_some(Target {
                rel,
                half: p.storage_half,
            })
        }
        // Storages crowded: the script's choice, which sends no one to a busy machine.
        Matched if storages_crowded(storages, peers) => {
            greedy_target(own, machines, storages, peers, p)
        }
        Matched => matched_machine(own, machines, peers, p, ready_in).map(|i| Target {
            rel: [machines[i * MACHINE_DIM], machines[i * MACHINE_DIM + 1]],
            half: p.machine_half,
        }),
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
    fn crowded_storages_turn_the_matching_into_greedy() {
        let p = params();
        let own = [0.0, 0.0, 0.0];
        // A busy machine next to the robot, a ready one far away: matched goes to the busy
        // one (0.05 m + 10 steps beats 1.0 m).
        let machines = [0.05, 0.0, 0.0, 1.0, 0.0, 1.0];
        let one_storage = [0.0, -0.5];
        let carriers =
            |n: usize| -> Vec<f32> { (0..n).flat_map(|i| [-0.5, 0.1 * i as f32, 1.0]).collect() };
        let to = |peers: &[f32]| target(7, &own, &machines, &one_storage, peers, &p).map(|t| t.rel);
        assert_eq!(to(&carriers(4)), Some([0.05, 0.0]));
        // Five carriers for one storage: greedy's choice, the ready machine.
        assert_eq!(to(&carriers(5)), Some([1.0, 0.0]));
        // Two storages take eight.
        let two_storages = [0.0, -0.5, 0.0, 0.5];
        assert_eq!(
            target(7, &own, &machines, &two_storages, &carriers(8), &p).map(|t| t.rel),
            Some([0.05, 0.0])
        );
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
        assert_eq!(TargetAction::from_index(N_TARGET_ACTIONS as u8), None);
    }
}
