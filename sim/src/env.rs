//! One tending environment: bodies, the step, pick/place, rewards and metrics.
//!
//! Where things are: the bodies, construction, reset and accessors here; [`live`] (adding
//! and removing robots, machines and storages during an episode), [`step`] (physics,
//! collisions, pick/place, rewards and P_max), [`observe`] (observations).

mod live;
mod observe;
mod step;

use crate::entities::{MachineId, RobotId, Sizes, StaticBox, StorageId};
use crate::grid::Grid;
use crate::layout::{self, generate, sizes_for};
use crate::metrics::Metrics;
use crate::{ScenarioConfig, Setup, SimError};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// What happened to one robot in the last step.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RobotEvents {
    pub picked: Option<MachineId>,
    pub placed: Option<StorageId>,
    /// Bodies this robot touched at the end of the step.
    pub collisions: u32,
    /// This robot touches something now and touched nothing at the end of the last step:
    /// one collision event (onset), the paper's "collisions" read as events rather than
    /// contact steps.
    pub contact_onset: bool,
}

/// Read-only view of a robot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotView {
    pub id: RobotId,
    pub pos: [f32; 2],
    pub vel: [f32; 2],
    pub has_part: bool,
}

/// Read-only view of a machine.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MachineView {
    pub id: MachineId,
    pub centre: [f32; 2],
    pub half: [f32; 2],
    pub part_ready: bool,
    /// Steps until the next part is ready (0 when ready).
    pub timer: u32,
}

/// Read-only view of a storage area.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StorageView {
    pub id: StorageId,
    pub centre: [f32; 2],
    pub half: [f32; 2],
}

#[derive(Debug, Clone)]
pub struct Env {
    cfg: ScenarioConfig,
    setup: Setup,
    sizes: Sizes,
    rng: ChaCha8Rng,
    steps: u32,
    next_id: [u32; 3],

    r_id: Vec<RobotId>,
    r_pos: Vec<[f32; 2]>,
    r_vel: Vec<[f32; 2]>,
    r_prev: Vec<[f32; 2]>,
    r_force: Vec<[f32; 2]>,
    r_part: Vec<bool>,
    r_reward: Vec<f32>,
    r_events: Vec<RobotEvents>,

    m_id: Vec<MachineId>,
    m_box: Vec<StaticBox>,
    m_ready: Vec<bool>,
    m_timer: Vec<u32>,
    m_alive: Vec<u32>,

    s_id: Vec<StorageId>,
    s_box: Vec<StaticBox>,

    grid: Grid,
    ready_scratch: Vec<[f32; 2]>,
    metrics: Metrics,
    /// P_max contribution of machines removed during the episode.
    p_max_removed: u32,
}

impl Env {
    /// A new environment of `setup`, laid out from `seed`.
    pub fn new(cfg: ScenarioConfig, setup: Setup, seed: u64) -> Result<Self, SimError> {
        cfg.validate()?;
        if setup.machines == 0 || setup.storages == 0 || setup.robots == 0 {
            return Err(SimError::BadSetup {
                setup: setup.to_string(),
                reason: "a setup needs at least one robot, one machine and one storage".into(),
            });
        }
        // A grown floor becomes the paper's floor with the setup's room (`resolved_for`).
        let cfg = cfg.resolved_for(setup);
        let sizes = sizes_for(setup, &cfg);
        let interaction = 2.0 * sizes.robot_radius + cfg.task.collision_distance.max(0.0);
        let grid = Grid::new(cfg.world.room_size, interaction);
        let mut env = Env {
            cfg,
            setup,
            sizes,
            rng: ChaCha8Rng::seed_from_u64(seed),
            steps: 0,
            next_id: [0; 3],
            r_id: Vec::new(),
            r_pos: Vec::new(),
            r_vel: Vec::new(),
            r_prev: Vec::new(),
            r_force: Vec::new(),
            r_part: Vec::new(),
            r_reward: Vec::new(),
            r_events: Vec::new(),
            m_id: Vec::new(),
            m_box: Vec::new(),
            m_ready: Vec::new(),
            m_timer: Vec::new(),
            m_alive: Vec::new(),
            s_id: Vec::new(),
            s_box: Vec::new(),
            grid,
            ready_scratch: Vec::new(),
            metrics: Metrics::default(),
            p_max_removed: 0,
        };
        env.reset(seed)?;
        Ok(env)
    }

    /// An environment with bodies at given positions (tests, replays, hand-made floors).
    /// Sizes follow `setup` as usual; positions must be finite.
    pub fn with_layout(
        cfg: ScenarioConfig,
        setup: Setup,
        layout: layout::Layout,
        seed: u64,
    ) -> Result<Self, SimError> {
        let mut env = Self::new(cfg, setup, seed)?;
        let all = layout
            .robots
            .iter()
            .chain(&layout.machines)
            .chain(&layout.storages);
        if let Some(p) = all
            .clone()
            .find(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            return Err(SimError::BadPosition {
                kind: "layout body",
                x: p[0],
                y: p[1],
            });
        }
        env.clear_bodies();
        for c in layout.storages {
            env.push_storage(c);
        }
        for c in layout.machines {
            env.push_machine(c);
        }
        for p in layout.robots {
            env.push_robot(p);
        }
        env.grid.rebuild(&env.r_pos);
        env.update_p_max();
        Ok(env)
    }

    fn clear_bodies(&mut self) {
        self.steps = 0;
        self.next_id = [0; 3];
        self.metrics = Metrics::default();
        self.p_max_removed = 0;
        for v in [
            &mut self.r_pos,
            &mut self.r_vel,
            &mut self.r_prev,
            &mut self.r_force,
        ] {
            v.clear();
        }
        self.r_id.clear();
        self.r_part.clear();
        self.r_reward.clear();
        self.r_events.clear();
        self.m_id.clear();
        self.m_box.clear();
        self.m_ready.clear();
        self.m_timer.clear();
        self.m_alive.clear();
        self.s_id.clear();
        self.s_box.clear();
    }

    /// Start a new episode with the initial setup, laid out from `seed`.
    pub fn reset(&mut self, seed: u64) -> Result<(), SimError> {
        self.rng = ChaCha8Rng::seed_from_u64(seed);
        let l = generate(self.setup, &self.cfg, &self.sizes, &mut self.rng)?;
        self.clear_bodies();
        for c in l.storages {
            self.push_storage(c);
        }
        for c in l.machines {
            self.push_machine(c);
        }
        for p in l.robots {
            self.push_robot(p);
        }
        self.grid.rebuild(&self.r_pos);
        self.update_p_max();
        Ok(())
    }

    fn push_robot(&mut self, p: [f32; 2]) -> RobotId {
        let id = RobotId(self.next_id[0]);
        self.next_id[0] += 1;
        self.r_id.push(id);
        self.r_pos.push(p);
        self.r_vel.push([0.0; 2]);
        self.r_prev.push(p);
        self.r_force.push([0.0; 2]);
        self.r_part.push(false);
        self.r_reward.push(0.0);
        self.r_events.push(RobotEvents::default());
        id
    }

    fn push_machine(&mut self, c: [f32; 2]) -> MachineId {
        let id = MachineId(self.next_id[1]);
        self.next_id[1] += 1;
        self.m_id.push(id);
        self.m_box.push(StaticBox {
            centre: c,
            half: self.sizes.machine_half,
        });
        // A machine starts with a part ready (it has been producing before the shift).
        self.m_ready.push(true);
        self.m_timer.push(0);
        self.m_alive.push(0);
        id
    }

    fn push_storage(&mut self, c: [f32; 2]) -> StorageId {
        let id = StorageId(self.next_id[2]);
        self.next_id[2] += 1;
        self.s_id.push(id);
        self.s_box.push(StaticBox {
            centre: c,
            half: self.sizes.storage_half,
        });
        id
    }

    fn all_boxes(&self) -> Vec<StaticBox> {
        self.m_box
            .iter()
            .chain(self.s_box.iter())
            .copied()
            .collect()
    }

    pub fn config(&self) -> &ScenarioConfig {
        &self.cfg
    }
    pub fn setup(&self) -> Setup {
        self.setup
    }
    /// The current counts (they differ from `setup()` after live changes).
    pub fn counts(&self) -> Setup {
        Setup::new(self.r_id.len(), self.m_id.len(), self.s_id.len())
    }
    pub fn sizes(&self) -> &Sizes {
        &self.sizes
    }
    pub fn steps(&self) -> u32 {
        self.steps
    }
    pub fn is_done(&self) -> bool {
        self.steps >= self.cfg.world.episode_steps
    }
    pub fn metrics(&self) -> &Metrics {
        &self.metrics
    }
    pub fn n_robots(&self) -> usize {
        self.r_id.len()
    }
    pub fn robot_ids(&self) -> &[RobotId] {
        &self.r_id
    }
    pub fn robot_index(&self, id: RobotId) -> Option<usize> {
        self.r_id.iter().position(|&r| r == id)
    }
    /// Per-robot rewards of the last step, in robot order.
    pub fn rewards(&self) -> &[f32] {
        &self.r_reward
    }
    /// Per-robot events of the last step, in robot order.
    pub fn events(&self) -> &[RobotEvents] {
        &self.r_events
    }
    pub fn robots(&self) -> impl ExactSizeIterator<Item = RobotView> + '_ {
        (0..self.r_id.len()).map(|i| RobotView {
            id: self.r_id[i],
            pos: self.r_pos[i],
            vel: self.r_vel[i],
            has_part: self.r_part[i],
        })
    }
    pub fn machines(&self) -> impl ExactSizeIterator<Item = MachineView> + '_ {
        (0..self.m_id.len()).map(|j| MachineView {
            id: self.m_id[j],
            centre: self.m_box[j].centre,
            half: self.m_box[j].half,
            part_ready: self.m_ready[j],
            timer: self.m_timer[j],
        })
    }
    pub fn storages(&self) -> impl ExactSizeIterator<Item = StorageView> + '_ {
        (0..self.s_id.len()).map(|k| StorageView {
            id: self.s_id[k],
            centre: self.s_box[k].centre,
            half: self.s_box[k].half,
        })
    }

    /// Test and tooling hook: put robot `id` at `pos` with velocity `vel`.
    pub fn set_robot_state(
        &mut self,
        id: RobotId,
        pos: [f32; 2],
        vel: [f32; 2],
    ) -> Result<(), SimError> {
        let i = self.robot_index(id).ok_or(SimError::UnknownId {
            kind: "robot",
            id: id.0,
        })?;
        self.r_pos[i] = pos;
        self.r_vel[i] = vel;
        self.r_prev[i] = pos;
        self.grid.rebuild(&self.r_pos);
        Ok(())
    }
}
