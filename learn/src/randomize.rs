//! Randomized setups (beyond the paper): train one policy on robot, machine and storage
//! counts drawn from inclusive ranges, to evaluate it zero-shot on every paper setup.
//!
//! A [`SetupRange`] is written like a setup name with a range in place of any count:
//! `2..12.2..8_1..4` = 2 to 12 robots, 2 to 8 machines, 1 to 4 storage areas, all bounds
//! inclusive (`2-12.2-8_1-4` is the same range; `6.2..8_2` keeps 6 robots and 2 storages).
//!
//! The draw is **per update**: all `n_envs` environments of one rollout share the drawn
//! counts, because the rollout buffers, the observation batch and the critic's robot
//! grouping have one shape per update (a per-env draw would need padded batches). Each
//! count is uniform over its range, independently, from a generator seeded by (training
//! seed, update index) only, so the sequence is a pure function of the seed and a resumed
//! run draws exactly what an uninterrupted one would.

use super::TrainConfig;
use crate::error::TrainError;
use policy::config::ModelKind;
use rand::Rng;
use sim::{ScenarioConfig, Setup};
use std::fmt;
use std::str::FromStr;

/// Inclusive ranges of robots, machines and storage areas: every count of `lo` is <= the
/// same count of `hi`, and every count of `lo` is >= 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SetupRange {
    pub lo: Setup,
    pub hi: Setup,
}

impl SetupRange {
    /// `lo..=hi` per count; refused when a lower bound exceeds its upper bound or is 0.
    pub fn new(lo: Setup, hi: Setup) -> Result<Self, String> {
        let dims = [
            ("robots", lo.robots, hi.robots),
            ("machines", lo.machines, hi.machines),
            ("storages", lo.storages, hi.storages),
        ];
        for (name, a, b) in dims {
            if a == 0 {
                return Err(format!("{name} must be >= 1 (a setup needs at least one)"));
            }
            if a > b {
                return Err(format!(
                    "{name} range {a}..{b} is empty (lower bound > upper)"
                ));
            }
        }
        Ok(Self { lo, hi })
    }

    /// Every setup of the range: robots x machines x storages.
    pub fn len(&self) -> usize {
        (self.hi.robots - self.lo.robots + 1)
            * (self.hi.machines - self.lo.machines + 1)
            * (self.hi.storages - self.lo.storages + 1)
    }

    /// Never true (a range holds at least one setup); here for clippy's `len` rule.
    pub fn is_empty(&self) -> bool {
        false
    }

    pub fn contains(&self, s: Setup) -> bool {
        (self.lo.robots..=self.hi.robots).contains(&s.robots)
            && (self.lo.machines..=self.hi.machines).contains(&s.machines)
            && (self.lo.storages..=self.hi.storages).contains(&s.storages)
    }

    /// One setup, each count uniform over its range (3 draws from `rng`).
    pub fn draw<R: Rng>(&self, rng: &mut R) -> Setup {
        Setup::new(
            rng.gen_range(self.lo.robots..=self.hi.robots),
            rng.gen_range(self.lo.machines..=self.hi.machines),
            rng.gen_range(self.lo.storages..=self.hi.storages),
        )
    }

    /// The corners of the box (deduplicated), largest last.
    fn corners(&self) -> Vec<Setup> {
        let mut v = vec![];
        for r in [self.lo.robots, self.hi.robots] {
            for m in [self.lo.machines, self.hi.machines] {
                for k in [self.lo.storages, self.hi.storages] {
                    let s = Setup::new(r, m, k);
                    if !v.contains(&s) {
                        v.push(s);
                    }
                }
            }
        }
        v
    }

    /// Refuse a range holding a setup the layout generator cannot place, before any
    /// training. The size rule (`sim::layout`) shrinks bodies as the footprint grows, and
    /// the footprint grows with every count, so the largest setup `hi` has the smallest
    /// robots: if its robots stay above `sizes.min_robot_radius`, every setup's do. Each
    /// corner of the range is also laid out once (rejection placement can still fail for a
    /// crowded room), which catches a room too small for the boxes themselves.
    pub fn check_fits(&self, scenario: &ScenarioConfig) -> Result<(), String> {
        let sizes = sim::layout::sizes_for(self.hi, scenario);
        if sizes.robot_radius < scenario.sizes.min_robot_radius {
            return Err(format!(
                "its largest setup {} does not fit the {} m room: robots would shrink to \
                 radius {:.4} m, below sizes.min_robot_radius {} m; lower the upper bounds",
                self.hi,
                scenario.world.room_size,
                sizes.robot_radius,
                scenario.sizes.min_robot_radius
            ));
        }
        for c in self.corners() {
            sim::Env::new(scenario.clone(), c, 0)
                .map_err(|e| format!("its setup {c} cannot be laid out: {e}"))?;
        }
        Ok(())
    }

    /// MAPPO pads its inputs to the training config's `mappo_max_*`: refuse a range whose
    /// upper bounds exceed them (SMAPPO is size-invariant and takes any range).
    pub fn check_padding(&self, kind: ModelKind, cfg: &TrainConfig) -> Result<(), String> {
        if kind != ModelKind::Mappo {
            return Ok(());
        }
        let over = [
            (
                "robots",
                self.hi.robots,
                "mappo_max_robots",
                cfg.mappo_max_robots,
            ),
            (
                "machines",
                self.hi.machines,
                "mappo_max_machines",
                cfg.mappo_max_machines,
            ),
            (
                "storages",
                self.hi.storages,
                "mappo_max_storages",
                cfg.mappo_max_storages,
            ),
        ];
        for (name, v, field, max) in over {
            if v > max {
                return Err(format!(
                    "up to {v} {name} exceeds the MAPPO input padding {field} = {max}: lower \
                     the range or raise {field} in the training config (--config)"
                ));
            }
        }
        Ok(())
    }
}

fn count(a: usize, b: usize, f: &mut fmt::Formatter<'_>) -> fmt::Result {
    if a == b {
        write!(f, "{a}")
    } else {
        write!(f, "{a}..{b}")
    }
}

/// `2..12.2..8_1..4`; a fixed count is written alone (`6.2..8_2`).
impl fmt::Display for SetupRange {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        count(self.lo.robots, self.hi.robots, f)?;
        f.write_str(".")?;
        count(self.lo.machines, self.hi.machines, f)?;
        f.write_str("_")?;
        count(self.lo.storages, self.hi.storages, f)
    }
}

impl FromStr for SetupRange {
    type Err = TrainError;

    /// `N.M_K` with each count `a`, `a..b` or `a-b` (inclusive); `_` may replace the `.`
    /// as in setup names (`2..12_2..8_1..4`).
    fn from_str(s: &str) -> Result<Self, TrainError> {
        let bad = |m: String| {
            TrainError::Config(format!(
                "setup range `{s}`: {m} (expected N.M_K with each count a or a..b, \
                 inclusive, e.g. 2..12.2..8_1..4)"
            ))
        };
        let t = s.trim();
        if t.is_empty() {
            return Err(bad("empty".into()));
        }
        let marked = t.replace("..", "~").replace('-', "~");
        let fields: Vec<&str> = marked.split(['.', '_']).collect();
        if fields.len() != 3 {
            return Err(bad(format!(
                "{} count fields, need 3 (robots.machines_storages)",
                fields.len()
            )));
        }
        let mut lo = [0usize; 3];
        let mut hi = [0usize; 3];
        let names = ["robots", "machines", "storages"];
        for (i, f) in fields.iter().enumerate() {
            let shown = f.replace('~', "..");
            let num = |x: &str| {
                x.trim().parse::<usize>().map_err(|_| {
                    bad(format!(
                        "{} `{shown}` is not a count or a range of counts",
                        names[i]
                    ))
                })
            };
            let (a, b) = match f.split_once('~') {
                Some((a, b)) => (num(a)?, num(b)?),
                None => {
                    let a = num(f)?;
                    (a, a)
                }
            };
            lo[i] = a;
            hi[i] = b;
        }
        Self::new(
            Setup::new(lo[0], lo[1], lo[2]),
            Setup::new(hi[0], hi[1], hi[2]),
        )
        .map_err(bad)
    }
}
