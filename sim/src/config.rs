//! Every constant of the scenario in one config struct (rapier style), loadable from TOML.
//!
//! Defaults and why (the paper's supplementary values are not available to us, so where
//! the paper is silent the choice is ours and stated here):
//! - world: the paper's 2.3 m room, dt 0.1 s, 200-step episodes, 20-step machine preparation.
//! - physics: VMAS world defaults (drag 0.25, contact force 100, contact margin 1e-3,
//!   mass 1, one substep).
//! - actuation: the native input is a holonomic velocity command. A velocity tracker turns
//!   it into the force that would reach the commanded velocity after this step's drag,
//!   capped at `max_force`: the simulated base follows a Twist like a real holonomic base
//!   does, while contacts still act as VMAS forces on top.
//! - k_speed 0.5 m/s: a typical indoor mobile-base speed; at dt 0.1 s a step moves 5 cm,
//!   less than the smallest robot radius, so nothing tunnels.
//! - reach 0.08 m: pick/place happens when the robot centre is within its radius + reach of
//!   the machine or storage surface (the manipulator reaches out; the paper assumes
//!   pick-and-place without stopping). Collisions count at surface distance <= 0.005 m, as
//!   VMAS's navigation scenario does, so a robot can pick without touching the machine.
//! - rewards: pick +3, place +5, collision -0.3 per body touched per step, progress 2 per
//!   metre, utilization -0.02 x uncollected/M, time -0.01. One delivery (+8) outweighs the
//!   progress shaping of a room crossing (2 x 2.3 m). The penalties were tuned by measurement
//!   (docs/bench/train.md): with collision -1 and utilization -0.1, PPO from scratch learned
//!   to stand still (random-level parts after 576 episodes of 6.4_2); with -0.3 / -0.02 it
//!   delivers ~24 parts after 480 episodes, and -0.1 left ~1.5x more collisions.

use crate::SimError;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ScenarioConfig {
    pub world: WorldConfig,
    pub physics: PhysicsConfig,
    pub task: TaskConfig,
    pub sizes: SizeConfig,
    pub rewards: RewardConfig,
    /// What each robot observes: everything (the paper's) or the k nearest of each group.
    pub observation: obs::Bound,
}

/// Which floor a setup is laid out on (docs/adr/0037).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Floor {
    /// The paper's: one room of `world.room_size` for every setup; bodies shrink when the
    /// setup would cover more than `sizes.occupancy` of it (section IV-D).
    #[default]
    Paper,
    /// The floor grows with the fleet: the room's side is chosen so that the setup's bodies,
    /// at their unscaled size, cover the same fraction of the floor as 6.4_2's do in the
    /// paper's room of `world.room_size`. Bodies never shrink; 6.4_2 gets the paper's room.
    Grown,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WorldConfig {
    /// Side of the square room, metres; origin at its centre. On a grown floor
    /// ([`Floor::Grown`]) the paper's room the growth is measured from.
    pub room_size: f32,
    /// The paper's fixed room, or a floor that grows with the fleet.
    pub floor: Floor,
    /// Control period, seconds.
    pub dt: f32,
    /// Physics substeps per control step (VMAS `substeps`).
    pub substeps: u32,
    /// Steps per episode.
    pub episode_steps: u32,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PhysicsConfig {
    /// Fraction of velocity removed once per step (VMAS `drag`).
    pub drag: f32,
    /// Contact stiffness (VMAS `collision_force`).
    pub collision_force: f32,
    /// Soft-plus width of the contact penetration (VMAS `contact_margin`).
    pub contact_margin: f32,
    /// Robot mass, kg.
    pub mass: f32,
    /// Largest force the velocity tracker may apply, N.
    pub max_force: f32,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TaskConfig {
    /// Steps a machine needs to make the next part after a pick.
    pub prep_steps: u32,
    /// Speed of the 5 discrete actions, m/s.
    pub k_speed: f32,
    /// Pick/place reach beyond the robot's radius, metres (scaled with entity size).
    pub reach: f32,
    /// Surface distance at or below which two bodies count as colliding, metres.
    pub collision_distance: f32,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SizeConfig {
    /// Robot radius before scaling, metres.
    pub robot_radius: f32,
    /// Machine footprint (width, height) before scaling, metres.
    pub machine_size: [f32; 2],
    /// Storage footprint (width, height) before scaling, metres.
    pub storage_size: [f32; 2],
    /// Largest fraction of the room floor the bodies (boxes counted with their gap halo)
    /// may cover. When the unscaled bodies would cover more, every size is multiplied by sqrt(occupancy * room / footprint),
    /// which keeps the density of the room constant as counts grow (the paper keeps "the
    /// scale of the number of entities to the environment size roughly the same").
    pub occupancy: f32,
    /// Free gap kept between static boxes and between boxes and walls at layout time, in
    /// robot diameters, so robots can pass between any two of them.
    pub box_gap_diameters: f32,
    /// Smallest robot radius the size rule may shrink to, metres: below it a setup is
    /// refused as not fitting (a body that small is no longer a mobile manipulator).
    pub min_robot_radius: f32,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RewardConfig {
    /// R_pi: a robot without a part picks at a machine with a ready part.
    pub pick: f32,
    /// R_pl: a robot with a part places it at a storage area.
    pub place: f32,
    /// R_c: per collision (pair) the robot takes part in, per step.
    pub collision: f32,
    /// s_pr: progress towards the closest ready machine / storage, per metre.
    pub progress: f32,
    /// s_u: utilization penalty scale, times uncollected parts / M (paper eq. 4).
    pub utilization: f32,
    /// tp: time penalty when R_pi, R_pl and R_u are all zero (paper eq. 5).
    pub time: f32,
}

impl Default for WorldConfig {
    fn default() -> Self {
        Self {
            room_size: 2.3,
            floor: Floor::Paper,
            dt: obs::defaults::DT,
            substeps: 1,
            episode_steps: 200,
        }
    }
}
impl Default for PhysicsConfig {
    fn default() -> Self {
        Self {
            drag: 0.25,
            collision_force: 100.0,
            contact_margin: 1e-3,
            mass: 1.0,
            max_force: 3.0,
        }
    }
}
impl Default for TaskConfig {
    fn default() -> Self {
        Self {
            prep_steps: obs::defaults::PREP_STEPS,
            k_speed: obs::defaults::K_SPEED,
            reach: obs::defaults::REACH,
            collision_distance: 0.005,
        }
    }
}
impl Default for SizeConfig {
    fn default() -> Self {
        Self {
            robot_radius: obs::defaults::ROBOT_RADIUS,
            // full sizes: twice the half extents
            machine_size: obs::defaults::MACHINE_HALF.map(|h| 2.0 * h),
            storage_size: obs::defaults::STORAGE_HALF.map(|h| 2.0 * h),
            occupancy: 0.35,
            box_gap_diameters: 1.25,
            min_robot_radius: 0.02,
        }
    }
}
impl Default for RewardConfig {
    fn default() -> Self {
        Self {
            pick: 3.0,
            place: 5.0,
            collision: -0.3,
            progress: 2.0,
            utilization: -0.02,
            time: -0.01,
        }
    }
}

impl ScenarioConfig {
    /// Parse TOML; `source_name` names the input in errors.
    pub fn from_toml(text: &str, source_name: &str) -> Result<Self, SimError> {
        let cfg: ScenarioConfig = toml::from_str(text).map_err(|e| SimError::ConfigParse {
            source_name: source_name.to_string(),
            message: e.to_string(),
        })?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// The scenario file at `path`; errors name it and say whether it is missing,
    /// unreadable or malformed (crate `inputs`).
    pub fn load(path: &std::path::Path) -> Result<Self, SimError> {
        let text = inputs::read_text("scenario file", path)?;
        let cfg: ScenarioConfig = toml::from_str(&text)
            .map_err(|e| inputs::InputError::malformed("scenario file", path, e))?;
        cfg.validate()
            .map_err(|e| inputs::InputError::malformed("scenario file", path, e))?;
        Ok(cfg)
    }

    /// TOML text with floats written as their shortest f32 form (2.3, not 2.299999952...).
    pub fn to_toml(&self) -> String {
        fn tidy(v: &mut toml::Value) {
            match v {
                toml::Value::Float(f) => {
                    *f = format!("{}", *f as f32).parse().unwrap_or(*f);
                }
                toml::Value::Table(t) => t.iter_mut().for_each(|(_, x)| tidy(x)),
                toml::Value::Array(a) => a.iter_mut().for_each(tidy),
                _ => {}
            }
        }
        let mut v = toml::Value::try_from(self).expect("config serializes");
        tidy(&mut v);
        toml::to_string_pretty(&v).expect("config serializes")
    }

    /// This config as `setup` runs it: on a grown floor, the paper's floor with the room
    /// [`crate::layout::room_for`] gives the setup (so everything that reads
    /// `world.room_size` from an environment's config reads the room it runs in).
    pub fn resolved_for(&self, setup: crate::Setup) -> Self {
        let mut c = self.clone();
        c.world.room_size = crate::layout::room_for(setup, self);
        c.world.floor = Floor::Paper;
        c
    }

    /// Refuse values that would make the physics meaningless or blow up.
    pub fn validate(&self) -> Result<(), SimError> {
        fn pos(field: &str, v: f32) -> Result<(), SimError> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(SimError::BadConfig {
                    field: field.into(),
                    reason: format!("must be a finite number > 0, got {v}"),
                })
            }
        }
        fn finite(field: &str, v: f32) -> Result<(), SimError> {
            if v.is_finite() {
                Ok(())
            } else {
                Err(SimError::BadConfig {
                    field: field.into(),
                    reason: format!("must be finite, got {v}"),
                })
            }
        }
        let w = &self.world;
        pos("world.room_size", w.room_size)?;
        let o = &self.observation;
        for (field, k) in [
            ("observation.nearest_machines", o.nearest_machines),
            ("observation.nearest_storages", o.nearest_storages),
        ] {
            if k == Some(0) {
                return Err(SimError::BadConfig {
                    field: field.into(),
                    reason: "must be >= 1 (a robot must see a machine and a storage)".into(),
                });
            }
        }
        pos("world.dt", w.dt)?;
        if w.substeps == 0 {
            return Err(SimError::BadConfig {
                field: "world.substeps".into(),
                reason: "must be >= 1".into(),
            });
        }
        if w.episode_steps == 0 {
            return Err(SimError::BadConfig {
                field: "world.episode_steps".into(),
                reason: "must be >= 1".into(),
            });
        }
        let p = &self.physics;
        finite("physics.drag", p.drag)?;
        if !(0.0..1.0).contains(&p.drag) {
            return Err(SimError::BadConfig {
                field: "physics.drag".into(),
                reason: format!("must be in [0, 1), got {}", p.drag),
            });
        }
        pos("physics.collision_force", p.collision_force)?;
        pos("physics.contact_margin", p.contact_margin)?;
        pos("physics.mass", p.mass)?;
        pos("physics.max_force", p.max_force)?;
        let t = &self.task;
        if t.prep_steps == 0 {
            return Err(SimError::BadConfig {
                field: "task.prep_steps".into(),
                reason: "must be >= 1".into(),
            });
        }
        pos("task.k_speed", t.k_speed)?;
        pos("task.reach", t.reach)?;
        finite("task.collision_distance", t.collision_distance)?;
        let s = &self.sizes;
        pos("sizes.robot_radius", s.robot_radius)?;
        pos("sizes.machine_size[0]", s.machine_size[0])?;
        pos("sizes.machine_size[1]", s.machine_size[1])?;
        pos("sizes.storage_size[0]", s.storage_size[0])?;
        pos("sizes.storage_size[1]", s.storage_size[1])?;
        pos("sizes.occupancy", s.occupancy)?;
        if s.occupancy > 0.6 {
            return Err(SimError::BadConfig {
                field: "sizes.occupancy".into(),
                reason: format!("{} leaves too little free floor (max 0.6)", s.occupancy),
            });
        }
        finite("sizes.box_gap_diameters", s.box_gap_diameters)?;
        pos("sizes.min_robot_radius", s.min_robot_radius)?;
        let r = &self.rewards;
        for (f, v) in [
            ("rewards.pick", r.pick),
            ("rewards.place", r.place),
            ("rewards.collision", r.collision),
            ("rewards.progress", r.progress),
            ("rewards.utilization", r.utilization),
            ("rewards.time", r.time),
        ] {
            finite(f, v)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_roundtrips_through_toml() {
        let c = ScenarioConfig::default();
        let back = ScenarioConfig::from_toml(&c.to_toml(), "test").unwrap();
        assert_eq!(c, back);
    }

    #[test]
    fn partial_toml_keeps_defaults() {
        let c = ScenarioConfig::from_toml("[task]\nk_speed = 0.3\n", "t").unwrap();
        assert_eq!(c.task.k_speed, 0.3);
        assert_eq!(c.world.episode_steps, 200);
    }

    #[test]
    fn malformed_and_bad_values_are_named() {
        let e = ScenarioConfig::from_toml("[task\nk_speed = 0.3", "cfg.toml").unwrap_err();
        assert!(e.to_string().contains("cfg.toml"), "{e}");
        let e = ScenarioConfig::from_toml("[task]\nk_sped = 0.3", "cfg.toml").unwrap_err();
        assert!(e.to_string().contains("k_sped"), "{e}");
        let e = ScenarioConfig::from_toml("[physics]\ndrag = 1.5", "c").unwrap_err();
        assert!(e.to_string().contains("physics.drag"), "{e}");
        let e = ScenarioConfig::from_toml("[world]\ndt = -0.1", "c").unwrap_err();
        assert!(e.to_string().contains("world.dt"), "{e}");
        let e = ScenarioConfig::from_toml("[rewards]\npick = nan", "c").unwrap_err();
        assert!(e.to_string().contains("rewards.pick"), "{e}");
    }
}
