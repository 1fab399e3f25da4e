//! What the bridge publishes: one step's state as a frame, the writers per entity
//! (created and dropped as entities come and go) and the fixed publishers, and the
//! recorder of `-p record:=DIR`.
#![allow(clippy::map_entry)] // writers are created fallibly before insertion

use std::collections::{BTreeMap, HashMap};

use ros2_client::dds::{Context, Node, Publisher};
use tracing::warn;

use msgs::cells::{self, Cell, CellEntry, CellGrid};
use msgs::topics::{self, machine, robot, storage, Entity, Leaf};
use msgs::{Bool, Clock, DiagnosticArray, MarkerArray, Path, PoseStamped, Profile, RosMessage};
use ros::{publisher, StampedWriter};

use crate::core::Core;
use crate::watchdog::Watchdog;

pub(crate) struct EntityWriters {
    pose: StampedWriter<PoseStamped>,
    flag: Option<StampedWriter<Bool>>,
}

/// One step's outgoing state, built right after the step; published at once or, with
/// `-p test_state_delay_ms`, when it is due.
pub(crate) struct StateFrame {
    /// The step's stamp (sim time, ns): the source timestamp of every sample.
    ns: i64,
    robots: Vec<(String, PoseStamped, bool)>,
    machines: Vec<(u32, PoseStamped, bool)>,
    storages: Vec<(u32, PoseStamped)>,
    /// Every cell's state (empty cells too: a robot waits for each cell around it), when
    /// the bridge publishes cell topics.
    cells: Vec<(Cell, Path)>,
    markers: MarkerArray,
    diag: DiagnosticArray,
    clock: Clock,
}

pub(crate) fn wall_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

/// `-p record:=DIR`: every message the bridge publishes and every cmd_vel and command it
/// receives, into a rosbag2 MCAP bag (log time = wall clock, like `tending record`).
pub(crate) struct Recorder {
    pub(crate) w: bag::BagWriter,
    pub(crate) errors: u64,
}

impl Recorder {
    pub(crate) fn put<M: RosMessage>(&mut self, topic: &str, msg: &M) {
        if let Err(e) = self.w.write_contract(topic, wall_ns(), msg) {
            self.errors += 1;
            if self.errors <= 5 || self.errors.is_power_of_two() {
                warn!("recording {topic} failed ({} errors): {e:#}", self.errors);
            }
        }
    }
}

/// The bridge's outgoing endpoints: the fixed publishers and one writer (or two) per
/// entity, created and dropped as entities come and go.
pub(crate) struct Outputs {
    clock: Publisher<Clock>,
    markers: Publisher<MarkerArray>,
    metrics: Publisher<DiagnosticArray>,
    robots: BTreeMap<String, EntityWriters>,
    machines: HashMap<u32, EntityWriters>,
    storages: HashMap<u32, EntityWriters>,
    /// One writer per cell (`cell_size` > 0), created once: the floor does not change.
    cells: BTreeMap<Cell, StampedWriter<Path>>,
    pub(crate) grid: Option<CellGrid>,
}

/// A writer on an entity's topic.
fn entity_writer<M: RosMessage>(
    ctx: &Context,
    node: &Node,
    topic: topics::EntityTopic,
    profile: Profile,
) -> anyhow::Result<StampedWriter<M>> {
    StampedWriter::new(ctx, node, &topic.ros_name(), profile)
}

impl Outputs {
    pub(crate) fn new(node: &mut Node, grid: Option<CellGrid>) -> anyhow::Result<Self> {
        Ok(Self {
            cells: BTreeMap::new(),
            grid,
            clock: publisher(node, topics::CLOCK, Profile::Clock)?,
            markers: publisher(node, topics::MARKERS, Profile::Visualization)?,
            metrics: publisher(node, topics::METRICS, Profile::Visualization)?,
            robots: BTreeMap::new(),
            machines: HashMap::new(),
            storages: HashMap::new(),
        })
    }

    /// Create the writers of entities that appeared, drop those of entities that left.
    pub(crate) fn sync(
        &mut self,
        ctx: &Context,
        node: &Node,
        core: &Core,
        wd: &Watchdog,
    ) -> anyhow::Result<()> {
        if let Some(g) = self.grid.filter(|_| self.cells.is_empty()) {
            for c in g.all() {
                wd.beat();
                let w = StampedWriter::new(ctx, node, &c.ros_name(), Profile::Cell)?;
                self.cells.insert(c, w);
            }
        }
        let states = core.robot_states();
        self.robots.retain(|n, _| states.iter().any(|s| &s.0 == n));
        for (name, _, _) in &states {
            if !self.robots.contains_key(name) {
                wd.beat(); // progress while creating many writers (100 robots at start-up)
                let w = EntityWriters {
                    pose: entity_writer(ctx, node, robot(name, Leaf::Pose), Profile::RobotStream)?,
                    flag: Some(entity_writer(
                        ctx,
                        node,
                        robot(name, Leaf::HasPart),
                        Profile::RobotStream,
                    )?),
                };
                self.robots.insert(name.clone(), w);
            }
        }
        let ms: Vec<u32> = core.env.machines().map(|m| m.id.0).collect();
        self.machines.retain(|j, _| ms.contains(j));
        for &j in &ms {
            if !self.machines.contains_key(&j) {
                wd.beat();
                let w = EntityWriters {
                    pose: entity_writer(ctx, node, machine(j, Leaf::Pose), Profile::LatchedPose)?,
                    flag: Some(entity_writer(
                        ctx,
                        node,
                        machine(j, Leaf::PartReady),
                        Profile::PartReady,
                    )?),
                };
                self.machines.insert(j, w);
            }
        }
        let ss: Vec<u32> = core.env.storages().map(|s| s.id.0).collect();
        self.storages.retain(|k, _| ss.contains(k));
        for &k in &ss {
            if !self.storages.contains_key(&k) {
                wd.beat();
                let w = EntityWriters {
                    pose: entity_writer(ctx, node, storage(k, Leaf::Pose), Profile::LatchedPose)?,
                    flag: None,
                };
                self.storages.insert(k, w);
            }
        }
        Ok(())
    }

    /// Publish a frame: cells, entity topics, then markers, metrics and /clock last. An entity
    /// removed while its frame was held has no writer any more: skipped.
    pub(crate) fn send(&self, f: StateFrame, rec: &mut Option<Recorder>) {
        let ns = f.ns;
        // cells first: a robot starts waiting for the cells around it when its own pose
        // arrives, and a 1,000-robot frame's entity topics take a while to write
        for (c, path) in f.cells {
            let Some(w) = self.cells.get(&c) else {
                continue;
            };
            if let Some(r) = rec.as_mut() {
                r.put(&c.ros_name(), &path);
            }
            let _ = w.write(path, Some(ns));
        }
        for (name, ps, has_part) in f.robots {
            let Some(w) = self.robots.get(&name) else {
                continue;
            };
            // flag first, then the pose (robot nodes key everything on the stamp anyway)
            if let Some(fl) = &w.flag {
                let _ = fl.write(Bool { data: has_part }, Some(ns));
            }
            if let Some(r) = rec.as_mut() {
                r.put(
                    &robot(&name, Leaf::HasPart).ros_name(),
                    &Bool { data: has_part },
                );
                r.put(&robot(&name, Leaf::Pose).ros_name(), &ps);
            }
            let _ = w.pose.write(ps, Some(ns));
        }
        for (j, ps, ready) in f.machines {
            let Some(w) = self.machines.get(&j) else {
                continue;
            };
            if let Some(fl) = &w.flag {
                let _ = fl.write(Bool { data: ready }, Some(ns));
            }
            if let Some(r) = rec.as_mut() {
                r.put(
                    &machine(j, Leaf::PartReady).ros_name(),
                    &Bool { data: ready },
                );
                r.put(&machine(j, Leaf::Pose).ros_name(), &ps);
            }
            let _ = w.pose.write(ps, Some(ns));
        }
        for (k, ps) in f.storages {
            let Some(w) = self.storages.get(&k) else {
                continue;
            };
            if let Some(r) = rec.as_mut() {
                r.put(&storage(k, Leaf::Pose).ros_name(), &ps);
            }
            let _ = w.pose.write(ps, Some(ns));
        }
        if let Some(r) = rec.as_mut() {
            r.put(topics::MARKERS, &f.markers);
            r.put(topics::METRICS, &f.diag);
            r.put(topics::CLOCK, &f.clock);
        }
        let _ = self.markers.publish(f.markers);
        let _ = self.metrics.publish(f.diag);
        let _ = self.clock.publish(f.clock);
    }
}

impl StateFrame {
    /// The current state of every entity, stamped with the core's sim time, and with
    /// `grid` every cell's.
    pub(crate) fn of(core: &Core, grid: Option<&CellGrid>) -> Self {
        let stamp = core.stamp();
        let ns = stamp.sec as i64 * 1_000_000_000 + stamp.nanosec as i64;
        let pose =
            |c: [f32; 2]| PoseStamped::planar(stamp, topics::FRAME_ID, c[0] as f64, c[1] as f64);
        StateFrame {
            ns,
            cells: grid.map(|g| cell_states(core, g)).unwrap_or_default(),
            robots: core
                .robot_states()
                .into_iter()
                .map(|(n, pos, has)| (n, pose(pos), has))
                .collect(),
            machines: core
                .env
                .machines()
                .map(|m| (m.id.0, pose(m.centre), m.part_ready))
                .collect(),
            storages: core
                .env
                .storages()
                .map(|s| (s.id.0, pose(s.centre)))
                .collect(),
            markers: core.markers(),
            diag: core.diagnostics(),
            clock: Clock { clock: stamp },
        }
    }
}

/// Every cell's state: robots in name order, then machines and storages by id (the order a
/// robot sorts them into anyway).
fn cell_states(core: &Core, g: &CellGrid) -> Vec<(Cell, Path)> {
    let mut by_cell: BTreeMap<Cell, Vec<CellEntry>> = g.all().map(|c| (c, Vec::new())).collect();
    let f = |c: [f32; 2]| [c[0] as f64, c[1] as f64];
    let mut put = |entity: Entity, xy: [f64; 2], flag: bool| {
        if let Some(v) = by_cell.get_mut(&g.cell_of(xy)) {
            v.push(CellEntry { entity, xy, flag });
        }
    };
    for (name, pos, has) in core.robot_states() {
        put(Entity::Robot(name), f(pos), has);
    }
    for m in core.env.machines() {
        put(Entity::Machine(m.id.0), f(m.centre), m.part_ready);
    }
    for s in core.env.storages() {
        put(Entity::Storage(s.id.0), f(s.centre), false);
    }
    let stamp = core.stamp();
    by_cell
        .into_iter()
        .map(|(c, e)| (c, cells::encode(stamp, &e)))
        .collect()
}
