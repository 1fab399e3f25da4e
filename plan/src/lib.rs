//! The scripted planner of `tending`: what a robot does with its observation.
//!
//! Everything here reads one robot's observation row (`obs::ObsBatch`'s layout) plus what
//! the robot knows about its fleet as parameters ([`FleetParams`]), so the simulator
//! (offline episodes, training rollouts) and `robot_node` (on the robot) run one and the
//! same code and agree step for step:
//!
//! - [`greedy`]: the greedy baseline (task allocation, axis moves);
//! - [`orca`]: greedy-ORCA (greedy allocation, ORCA avoidance, continuous velocities) and
//!   ORCA as a safety filter on a learned policy's command;
//! - [`targets`]: the target menu a target-action policy picks from, with the matching
//!   behind its "matched" entry ([`matching`]), the storage queues ([`storage_queue`]) and
//!   the machine clocks ([`machine_clock`]) it plans with, and the detour round a box
//!   ([`detour`]);
//! - [`shield`]: the one-step action shield over discrete moves ([`action`]);
//! - [`pilot`]: actor output -> menu target -> planner -> ORCA filter or shield, the one
//!   path a learned policy (or matching-ORCA) drives through, with the rule for when the
//!   filter is on ([`Safety`]);
//! - [`margins`]: the filter's and greedy-ORCA's margins as a named TOML file;
//! - [`controller`]: the one controller trait of a robot (observation in, velocity out),
//!   with the scripted controllers (the learned one is `policy::controller`).

pub mod controller;
pub mod detour;
pub mod fleet;
pub mod geom;
pub mod greedy;
pub mod machine_clock;
pub mod margins;
pub mod matching;
pub mod method;
pub mod orca;
pub mod pilot;
pub mod shield;
pub mod storage_queue;
pub mod targets;

pub use controller::Controller;
pub use fleet::FleetParams;
pub use margins::{Margins, ScriptMargins};
pub use method::MethodName;
pub use pilot::{Deployment, FilterMargins, MatchingOrca, Outputs, Pilot, Row, Safety};
