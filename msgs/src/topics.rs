//! Topic names of the `tending` contract and parsing of discovered topic names.
//!
//! | topic | type | profile |
//! |---|---|---|
//! | `/clock` | rosgraph_msgs/Clock | [`Profile::Clock`] |
//! | `/<robot>/pose` | geometry_msgs/PoseStamped | [`Profile::RobotStream`] |
//! | `/<robot>/has_part` | std_msgs/Bool | [`Profile::RobotStream`] |
//! | `/<robot>/cmd_vel` | geometry_msgs/Twist | [`Profile::RobotStream`] |
//! | `/machine_<j>/pose` | geometry_msgs/PoseStamped | [`Profile::LatchedPose`] |
//! | `/machine_<j>/part_ready` | std_msgs/Bool | [`Profile::PartReady`] |
//! | `/storage_<k>/pose` | geometry_msgs/PoseStamped | [`Profile::LatchedPose`] |
//! | `/tending/markers` | visualization_msgs/MarkerArray | [`Profile::Visualization`] |
//! | `/tending/metrics` | diagnostic_msgs/DiagnosticArray | [`Profile::Visualization`] |
//! | `/tending/cells/c<i>_<j>` | nav_msgs/Path (one cell's entities, [`crate::cells`]) | [`Profile::Cell`] |

use crate::qos::Profile;
use crate::schema::{self, MsgDef};

pub const CLOCK: &str = "/clock";
pub const MARKERS: &str = "/tending/markers";
pub const METRICS: &str = "/tending/metrics";
/// sim_bridge's run-time commands (std_msgs/String): `add_machine [x y]`,
/// `remove_machine <id>`, `add_storage [x y]`, `remove_storage <id>`,
/// `add_robot <name> [x y]`, `remove_robot <name>`.
pub const COMMAND: &str = "/tending/command";
/// The frame every pose is expressed in.
pub const FRAME_ID: &str = "map";

/// The last segment of each per-entity topic.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Leaf {
    Pose,
    HasPart,
    CmdVel,
    PartReady,
}

impl Leaf {
    pub const fn as_str(self) -> &'static str {
        match self {
            Leaf::Pose => "pose",
            Leaf::HasPart => "has_part",
            Leaf::CmdVel => "cmd_vel",
            Leaf::PartReady => "part_ready",
        }
    }
    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "pose" => Leaf::Pose,
            "has_part" => Leaf::HasPart,
            "cmd_vel" => Leaf::CmdVel,
            "part_ready" => Leaf::PartReady,
            _ => return None,
        })
    }
}

/// Who a topic belongs to.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Entity {
    /// A robot, by namespace without the leading slash (`robot_3`, or `fleet/robot_3`).
    Robot(String),
    Machine(u32),
    Storage(u32),
}

impl Entity {
    /// The namespace, with leading slash (`/robot_3`, `/machine_2`).
    pub fn namespace(&self) -> String {
        match self {
            Entity::Robot(ns) => format!("/{ns}"),
            Entity::Machine(j) => format!("/machine_{j}"),
            Entity::Storage(k) => format!("/storage_{k}"),
        }
    }
}

/// One topic of the contract.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct EntityTopic {
    pub entity: Entity,
    pub leaf: Leaf,
}

impl EntityTopic {
    pub fn new(entity: Entity, leaf: Leaf) -> Self {
        Self { entity, leaf }
    }
    /// Fully qualified ROS name, e.g. `/robot_3/pose`.
    pub fn ros_name(&self) -> String {
        format!("{}/{}", self.entity.namespace(), self.leaf.as_str())
    }
    /// DDS topic name, e.g. `rt/robot_3/pose`.
    pub fn dds_name(&self) -> String {
        format!("rt{}", self.ros_name())
    }
    /// The message type of this topic, or `None` for a combination outside the contract.
    pub fn msg_def(&self) -> Option<&'static MsgDef> {
        match (&self.entity, self.leaf) {
            (_, Leaf::Pose) => Some(&schema::POSE_STAMPED),
            (Entity::Robot(_), Leaf::HasPart) => Some(&schema::BOOL),
            (Entity::Robot(_), Leaf::CmdVel) => Some(&schema::TWIST),
            (Entity::Machine(_), Leaf::PartReady) => Some(&schema::BOOL),
            _ => None,
        }
    }
    /// The QoS profile of this topic, or `None` for a combination outside the contract.
    pub fn profile(&self) -> Option<Profile> {
        match (&self.entity, self.leaf) {
            (Entity::Robot(_), Leaf::Pose | Leaf::HasPart | Leaf::CmdVel) => {
                Some(Profile::RobotStream)
            }
            (Entity::Machine(_) | Entity::Storage(_), Leaf::Pose) => Some(Profile::LatchedPose),
            (Entity::Machine(_), Leaf::PartReady) => Some(Profile::PartReady),
            _ => None,
        }
    }
}

pub fn robot(ns: &str, leaf: Leaf) -> EntityTopic {
    EntityTopic::new(Entity::Robot(ns.trim_matches('/').to_string()), leaf)
}
pub fn machine(j: u32, leaf: Leaf) -> EntityTopic {
    EntityTopic::new(Entity::Machine(j), leaf)
}
pub fn storage(k: u32, leaf: Leaf) -> EntityTopic {
    EntityTopic::new(Entity::Storage(k), leaf)
}

/// The topic of a static entity namespace segment (`machine_2` -> Machine(2)).
fn parse_indexed(seg: &str, prefix: &str) -> Option<u32> {
    let digits = seg.strip_prefix(prefix)?;
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    if digits.len() > 1 && digits.starts_with('0') {
        return None;
    }
    digits.parse().ok()
}

fn valid_token(seg: &str) -> bool {
    !seg.is_empty()
        && !seg.as_bytes()[0].is_ascii_digit()
        && seg.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_')
        && !seg.contains("__")
}

/// Parse a discovered topic name (DDS form `rt/robot_3/pose`, or ROS form `/robot_3/pose`)
/// into the contract topic it is, or `None` if it is not one of ours.
///
/// `machine_<j>` and `storage_<k>` namespaces are machines and storages (decimal index,
/// no leading zeros); any other namespace (one or more valid name tokens, not `tending`)
/// with a contract leaf is a robot. Machines and storages have no robot leaves and
/// robots no `part_ready`.
pub fn parse_topic(name: &str) -> Option<EntityTopic> {
    let rest = match name.strip_prefix("rt/") {
        Some(r) => r,
        None => name.strip_prefix('/')?,
    };
    let (ns, leaf) = rest.rsplit_once('/')?;
    let leaf = Leaf::parse(leaf)?;
    let segs: Vec<&str> = ns.split('/').collect();
    if !segs.iter().all(|s| valid_token(s)) {
        return None;
    }
    let entity = if segs.len() == 1 {
        if let Some(j) = parse_indexed(segs[0], "machine_") {
            Entity::Machine(j)
        } else if let Some(k) = parse_indexed(segs[0], "storage_") {
            Entity::Storage(k)
        } else if segs[0] == "tending"
            || segs[0].starts_with("machine_")
            || segs[0].starts_with("storage_")
        {
            return None;
        } else {
            Entity::Robot(segs[0].to_string())
        }
    } else {
        Entity::Robot(ns.to_string())
    };
    let t = EntityTopic { entity, leaf };
    t.profile().map(|_| t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names() {
        assert_eq!(
            robot("/robot_3", Leaf::CmdVel).ros_name(),
            "/robot_3/cmd_vel"
        );
        assert_eq!(
            machine(2, Leaf::PartReady).dds_name(),
            "rt/machine_2/part_ready"
        );
        assert_eq!(storage(0, Leaf::Pose).ros_name(), "/storage_0/pose");
    }

    #[test]
    fn parse_discovered() {
        assert_eq!(
            parse_topic("rt/robot_3/pose"),
            Some(robot("robot_3", Leaf::Pose))
        );
        assert_eq!(
            parse_topic("rt/machine_2/part_ready"),
            Some(machine(2, Leaf::PartReady))
        );
        assert_eq!(
            parse_topic("/storage_11/pose"),
            Some(storage(11, Leaf::Pose))
        );
        assert_eq!(
            parse_topic("rt/fleet/robot_1/has_part"),
            Some(robot("fleet/robot_1", Leaf::HasPart))
        );
        assert_eq!(
            parse_topic("rt/alpha/cmd_vel"),
            Some(robot("alpha", Leaf::CmdVel))
        );
        for bad in [
            "rt/clock",
            "rt/tending/markers",
            "rt/tending/pose",
            "rt/machine_2/has_part",
            "rt/storage_1/part_ready",
            "rt/robot_1/part_ready",
            "rt/machine_/pose",
            "rt/machine_x/pose",
            "rt/machine_01/pose",
            "rt/robot_3/pose/extra",
            "rq/robot_3/poseRequest",
            "robot_3/pose",
            "rt//pose",
            "rt/3robot/pose",
            "rt/ros_discovery_info",
            "",
        ] {
            assert_eq!(parse_topic(bad), None, "{bad}");
        }
    }

    #[test]
    fn contract_types() {
        assert_eq!(
            robot("r", Leaf::CmdVel).msg_def().unwrap().full_name(),
            "geometry_msgs/msg/Twist"
        );
        assert_eq!(
            machine(0, Leaf::PartReady).msg_def().unwrap().full_name(),
            "std_msgs/msg/Bool"
        );
        assert_eq!(machine(0, Leaf::Pose).profile(), Some(Profile::LatchedPose));
        assert_eq!(
            machine(0, Leaf::PartReady).profile(),
            Some(Profile::PartReady)
        );
        assert_eq!(robot("r", Leaf::Pose).profile(), Some(Profile::RobotStream));
    }
}
