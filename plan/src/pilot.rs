//! The pilot: the one path from a policy's chosen action to a velocity command, used by
//! `tending eval`, the trainer's rollouts and robot_node alike.
//!
//! actor output -> (shield: unsafe moves masked before the choice) -> action -> menu
//! target and planner (target actions, `crate::targets`) or the move's velocity
//! (`obs::action`) -> ORCA filter (`crate::orca`) -> velocity.
//!
//! Which safety layer a learned policy runs behind is decided once, by [`Safety::choose`]
//! (docs/adr/0011): on the robot the ORCA filter is on unless refused or replaced by the
//! shield; offline a policy runs as it was trained. matching-ORCA (docs/adr/0020) is a
//! pilot too: a target-action "policy" that always asks for the "matched" entry
//! ([`MatchingOrca`]).

use crate::fleet::FleetParams;
use crate::orca::{
    GreedyOrca, OrcaParams, FILTER_CLEARANCE, FILTER_OBSTACLE_HORIZON, FILTER_REST_CLEARANCE,
};
use crate::shield::{self, ShieldParams};
use crate::targets::TargetAction;
use obs::action;
use obs::ObsBatch;

/// One robot's observation row, in `ObsBatch`'s layout.
#[derive(Debug, Clone, Copy)]
pub struct Row<'a> {
    pub own: &'a [f32],
    pub machines: &'a [f32],
    pub storages: &'a [f32],
    pub peers: &'a [f32],
}

impl<'a> Row<'a> {
    /// Row `r` of `obs`.
    pub fn of(obs: &'a ObsBatch, r: usize) -> Self {
        Self {
            own: obs.own_row(r),
            machines: obs.machines_row(r),
            storages: obs.storages_row(r),
            peers: obs.peers_row(r),
        }
    }
}

/// What a policy's outputs mean.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outputs {
    /// Velocity moves of [`action::MOVES`] (the paper's 5, or 9 with the diagonals).
    Moves,
    /// Entries of the target menu ([`TargetAction`]): which box to drive to.
    Targets,
}

/// Margins of the ORCA filter behind a learned policy: peer clearance at full speed and
/// at rest (docs/adr/0017, 0019), horizon for boxes and walls (docs/adr/0030). The
/// `[filter]` table of a margins file ([`crate::margins`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FilterMargins {
    /// Peer clearance at full speed, m.
    pub clearance: f32,
    /// Peer clearance at rest, m; the smaller of this and `clearance` is used.
    pub rest_clearance: f32,
    /// Horizon for boxes and walls, s.
    pub obstacle_horizon: f32,
}

impl FilterMargins {
    /// The margins robot_node deploys by default and `tending eval` runs unless told.
    pub const DEPLOYED: Self = Self {
        clearance: FILTER_CLEARANCE,
        rest_clearance: FILTER_REST_CLEARANCE,
        obstacle_horizon: FILTER_OBSTACLE_HORIZON,
    };

    /// The planner's and filter's parameters behind a learned policy, from greedy-ORCA's
    /// (`base`, [`FleetParams::orca_params`]): [`OrcaParams::for_policy_filter`] with
    /// these margins.
    pub fn orca_params(&self, base: OrcaParams) -> OrcaParams {
        base.for_policy_filter(self.clearance, self.rest_clearance)
            .with_obstacle_horizon(self.obstacle_horizon)
    }

    /// Whether the full-speed and rest clearances are the deployed ones (as used: the rest
    /// clearance is cut to the full-speed one).
    pub fn deployed_clearances(&self) -> bool {
        self.clearance == FILTER_CLEARANCE
            && self.rest_clearance.min(self.clearance) == FILTER_REST_CLEARANCE.min(self.clearance)
    }
}

impl Default for FilterMargins {
    fn default() -> Self {
        Self::DEPLOYED
    }
}

/// Where a policy runs, for [`Safety::choose`]'s default.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Deployment {
    /// On a robot (robot_node, and so `tending fleet`): a factory deploys any controller
    /// behind a safety layer.
    Robot,
    /// Offline (`tending eval`, `tending sim`), which measures the policy: as it was trained.
    Offline { trained_with_filter: bool },
}

/// What a learned policy's command passes through on its way to the base.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Safety {
    /// The one-step action shield on the moves' logits (`crate::shield`).
    pub shield: bool,
    /// ORCA as a safety filter on the velocity, with these margins.
    pub filter: Option<FilterMargins>,
}

impl Safety {
    /// Neither: the policy's command as it is.
    pub const RAW: Self = Self {
        shield: false,
        filter: None,
    };

    /// The ORCA filter with `margins`, no shield.
    pub fn filtered(margins: FilterMargins) -> Self {
        Self {
            shield: false,
            filter: Some(margins),
        }
    }

    /// The rule, written once (docs/adr/0011): the shield when asked for; the ORCA filter
    /// when asked for (`orca_filter` `Some(true)`), not when refused (`Some(false)`), and
    /// when nobody says, unless the shield is on: always on a robot, offline only for a
    /// policy trained behind it.
    pub fn choose(
        shield: bool,
        orca_filter: Option<bool>,
        deployment: Deployment,
        margins: FilterMargins,
    ) -> Self {
        let default_on = match deployment {
            Deployment::Robot => true,
            Deployment::Offline {
                trained_with_filter,
            } => trained_with_filter,
        };
        let on = orca_filter.unwrap_or(default_on && !shield);
        Self {
            shield,
            filter: on.then_some(margins),
        }
    }
}

/// One robot's pilot: shield, target planner and ORCA filter as its policy needs them.
/// Stateful (the planner's memories, the filter's velocity estimates): one per robot,
/// [`Self::reset`] when its inputs jump.
#[derive(Debug, Clone)]
pub struct Pilot {
    outputs: Outputs,
    k_speed: f32,
    shield: Option<ShieldParams>,
    /// The target planner and/or the ORCA filter: one [`GreedyOrca`], whose planning and
    /// filtering states are apart.
    orca: Option<GreedyOrca>,
    filter: bool,
}

impl Pilot {
    /// A pilot for a policy whose outputs mean `outputs` in the fleet `fleet` (its k_speed
    /// is the moves' speed), behind `safety`. Refused: the shield for target actions (it
    /// masks moves), and ORCA parameters ORCA cannot work with.
    pub fn new(fleet: &FleetParams, outputs: Outputs, safety: Safety) -> Result<Self, String> {
        if safety.shield && outputs == Outputs::Targets {
            return Err(
                "the action shield acts on velocity moves; this policy has target \
                        actions (use the ORCA filter instead)"
                    .into(),
            );
        }
        let base = fleet.orca_params();
        let orca = match (safety.filter, outputs) {
            (Some(m), _) => Some(m.orca_params(base)),
            // Without the filter a target policy still plans with the policy's parameters.
            (None, Outputs::Targets) => Some(base.for_policy(None)),
            (None, Outputs::Moves) => None,
        };
        Ok(Self {
            outputs,
            k_speed: fleet.k_speed,
            shield: safety.shield.then(|| fleet.shield_params()),
            orca: orca.map(GreedyOrca::new).transpose()?,
            filter: safety.filter.is_some(),
        })
    }

    pub fn outputs(&self) -> Outputs {
        self.outputs
    }

    /// Whether the shield masks this pilot's moves.
    pub fn shielded(&self) -> bool {
        self.shield.is_some()
    }

    /// Whether the command passes through the ORCA filter.
    pub fn filtered(&self) -> bool {
        self.filter
    }

    /// Forget the planner's memories and the filter's last observation.
    pub fn reset(&mut self) {
        if let Some(o) = &mut self.orca {
            o.reset();
        }
    }

    /// Control period of the planner, s (None: no planner or filter).
    pub fn dt(&self) -> Option<f32> {
        self.orca.as_ref().map(|o| o.params().greedy.dt)
    }

    /// `n` control steps passed without a call (a real-time robot that missed states):
    /// the planner's machine clock counts them ([`GreedyOrca::skip_steps`]).
    pub fn skip_steps(&mut self, n: u32) {
        if let Some(o) = &mut self.orca {
            o.skip_steps(n);
        }
    }

    /// The shield's verdict on every move for this row; None without the shield.
    pub fn safe_moves(&self, row: Row) -> Option<[bool; action::N_ACTIONS_WITH_DIAGONALS]> {
        let p = self.shield.as_ref()?;
        Some(shield::safe_actions(
            row.own,
            row.machines,
            row.storages,
            row.peers,
            p,
        ))
    }

    /// Mask the logits of unsafe moves in place ([`shield::MASKED_LOGIT`]); nothing
    /// without the shield.
    pub fn shield_logits(&self, row: Row, logits: &mut [f32]) {
        if let Some(safe) = self.safe_moves(row) {
            shield::mask_logits(logits, &safe);
        }
    }

    /// The velocity command (vx, vy), m/s, for `action` on this row: the target's
    /// preferred velocity or the move's, through the ORCA filter when it is on. Call once
    /// per control step (planner and filter keep state). A move outside the table is zero.
    pub fn command(&mut self, action: u8, row: Row) -> [f32; 2] {
        let pref = match self.outputs {
            Outputs::Targets => self
                .orca
                .as_mut()
                .expect("a target-action pilot has its planner")
                .target_preferred(action, row.own, row.machines, row.storages, row.peers),
            Outputs::Moves => action::velocity(action, self.k_speed).unwrap_or([0.0, 0.0]),
        };
        match self.orca.as_mut().filter(|_| self.filter) {
            Some(f) => f.filter(row.own, row.machines, row.storages, row.peers, pref),
            None => pref,
        }
    }
}

/// Commands for every row of `obs` (rows in pilot order) into `out`.
pub fn commands(pilots: &mut [Pilot], obs: &ObsBatch, actions: &[u8], out: &mut Vec<[f32; 2]>) {
    out.clear();
    out.extend(
        pilots
            .iter_mut()
            .zip(actions)
            .enumerate()
            .map(|(r, (p, &a))| p.command(a, Row::of(obs, r))),
    );
}

/// matching-ORCA (docs/adr/0020): the scripted method that always asks the target menu for
/// its "matched" entry, through the pilot a target-action policy runs behind the ORCA
/// filter. The shipped policy is measured against it.
#[derive(Debug, Clone)]
pub struct MatchingOrca {
    pilot: Pilot,
}

impl MatchingOrca {
    /// The menu entry it always asks for.
    pub const ENTRY: TargetAction = TargetAction::Matched;

    /// matching-ORCA in `fleet`, behind the ORCA filter with `margins`.
    pub fn new(fleet: &FleetParams, margins: FilterMargins) -> Result<Self, String> {
        Ok(Self {
            pilot: Pilot::new(fleet, Outputs::Targets, Safety::filtered(margins))?,
        })
    }

    /// The velocity command for this row (once per control step).
    pub fn velocity(&mut self, row: Row) -> [f32; 2] {
        self.pilot.command(Self::ENTRY as u8, row)
    }

    /// Its pilot (reset, missed steps).
    pub fn pilot_mut(&mut self) -> &mut Pilot {
        &mut self.pilot
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::greedy::GreedyParams;
    use obs::ObsBuilder;

    fn fleet() -> FleetParams {
        let g = GreedyParams::default();
        FleetParams::from_greedy(&g, 2.3)
    }

    fn batch(peers: &[[f32; 2]]) -> ObsBatch {
        ObsBuilder {
            own_pos: [0.0, 0.0],
            has_part: false,
            machines: vec![([0.8, 0.0], true), ([-0.5, 0.5], false)],
            storages: vec![[-0.8, -0.8]],
            peers: peers.iter().map(|p| (*p, false)).collect(),
        }
        .build()
        .unwrap()
    }

    #[test]
    fn the_filter_is_on_by_default_on_the_robot_and_as_trained_offline() {
        let m = FilterMargins::DEPLOYED;
        let on = Safety::filtered(m);
        let robot = Deployment::Robot;
        assert_eq!(Safety::choose(false, None, robot, m), on);
        assert_eq!(Safety::choose(false, Some(false), robot, m), Safety::RAW);
        // the shield replaces the default filter, not an asked-for one
        let shield = Safety {
            shield: true,
            filter: None,
        };
        assert_eq!(Safety::choose(true, None, robot, m), shield);
        let both = Safety {
            shield: true,
            filter: Some(m),
        };
        assert_eq!(Safety::choose(true, Some(true), robot, m), both);
        for trained_with_filter in [false, true] {
            let offline = Deployment::Offline {
                trained_with_filter,
            };
            let by_default = Safety::choose(false, None, offline, m);
            assert_eq!(by_default.filter.is_some(), trained_with_filter);
            assert_eq!(Safety::choose(false, Some(true), offline, m), on);
            assert_eq!(Safety::choose(false, Some(false), offline, m), Safety::RAW);
            assert_eq!(Safety::choose(true, None, offline, m), shield);
        }
    }

    #[test]
    fn refuses_the_shield_for_target_actions() {
        let s = Safety {
            shield: true,
            filter: None,
        };
        let e = Pilot::new(&fleet(), Outputs::Targets, s).unwrap_err();
        assert!(e.contains("shield"), "{e}");
        assert!(Pilot::new(&fleet(), Outputs::Moves, s).is_ok());
    }

    /// Raw moves are the action table's velocities; behind the filter, the very velocity
    /// the filter alone gives (and a free move passes unchanged).
    #[test]
    fn moves_raw_and_filtered() {
        let f = fleet();
        let obs = batch(&[]);
        let mut raw = Pilot::new(&f, Outputs::Moves, Safety::RAW).unwrap();
        assert_eq!(raw.command(2, Row::of(&obs, 0)), [0.5, 0.0]);
        assert_eq!(raw.command(9, Row::of(&obs, 0)), [0.0, 0.0]);
        let m = FilterMargins::DEPLOYED;
        let mut p = Pilot::new(&f, Outputs::Moves, Safety::filtered(m)).unwrap();
        let mut alone = GreedyOrca::new(m.orca_params(f.orca_params())).unwrap();
        let near = batch(&[[0.2, 0.0]]);
        for obs in [&obs, &near] {
            let row = Row::of(obs, 0);
            let want = alone.filter(row.own, row.machines, row.storages, row.peers, [0.5, 0.0]);
            assert_eq!(p.command(2, row), want);
        }
        assert!(p.filtered() && !p.shielded());
    }

    /// A target-action pilot drives for the box its entry names; matching-ORCA is the
    /// pilot always asking for "matched".
    #[test]
    fn targets_and_matching_orca() {
        let f = fleet();
        let obs = batch(&[]);
        let m = FilterMargins::DEPLOYED;
        let mut p = Pilot::new(&f, Outputs::Targets, Safety::filtered(m)).unwrap();
        let v = p.command(TargetAction::Greedy as u8, Row::of(&obs, 0));
        assert!((v[0] - 0.5).abs() < 1e-3 && v[1].abs() < 1e-3, "{v:?}");
        let mut a = Pilot::new(&f, Outputs::Targets, Safety::filtered(m)).unwrap();
        let mut b = MatchingOrca::new(&f, m).unwrap();
        for _ in 0..3 {
            let want = a.command(TargetAction::Matched as u8, Row::of(&obs, 0));
            assert_eq!(b.velocity(Row::of(&obs, 0)), want);
        }
    }

    #[test]
    fn the_shield_masks_moves_into_a_close_peer() {
        let s = Safety {
            shield: true,
            filter: None,
        };
        let p = Pilot::new(&fleet(), Outputs::Moves, s).unwrap();
        let obs = batch(&[[0.2, 0.0]]);
        let mut logits = [0.0, 0.0, 5.0, 0.0, 0.0];
        p.shield_logits(Row::of(&obs, 0), &mut logits);
        assert_eq!(logits[2], shield::MASKED_LOGIT);
        assert_eq!(logits[0], 0.0);
        let raw = Pilot::new(&fleet(), Outputs::Moves, Safety::RAW).unwrap();
        assert_eq!(raw.safe_moves(Row::of(&obs, 0)), None);
    }

    #[test]
    fn deployed_clearances_compare_as_used() {
        assert!(FilterMargins::DEPLOYED.deployed_clearances());
        let swept = FilterMargins {
            rest_clearance: 0.025,
            ..FilterMargins::DEPLOYED
        };
        assert!(!swept.deployed_clearances());
        // a rest clearance above the full-speed one is cut to it: 40 mm at rest is 40 mm
        let above = FilterMargins {
            rest_clearance: 0.05,
            ..FilterMargins::DEPLOYED
        };
        assert!(!above.deployed_clearances());
        let lower = FilterMargins {
            clearance: FILTER_REST_CLEARANCE,
            ..FilterMargins::DEPLOYED
        };
        assert!(!lower.deployed_clearances());
    }
}
