//! The default scenario's bodies and timing at scale 1: one source for the simulator's
//! config defaults (`sim::ScenarioConfig`) and the planner's (`plan::GreedyParams`), which
//! robot_node's parameters take in turn. They live here because `obs` is the one crate
//! both `sim` and `plan` stand on; neither may depend on the other (docs/adr/0036).

/// Robot disc radius, m.
pub const ROBOT_RADIUS: f32 = 0.08;
/// Machine box half extents, m.
pub const MACHINE_HALF: [f32; 2] = [0.12, 0.12];
/// Storage box half extents, m.
pub const STORAGE_HALF: [f32; 2] = [0.15, 0.08];
/// Pick/place reach beyond the robot's surface, m.
pub const REACH: f32 = 0.08;
/// Speed limit, m/s.
pub const K_SPEED: f32 = 0.5;
/// Control and simulation step, s.
pub const DT: f32 = 0.1;
/// Steps a machine takes to make a part after one is picked.
pub const PREP_STEPS: u32 = 20;
