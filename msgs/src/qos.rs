//! The QoS profiles of the `tending` ROS 2 contract (DESIGN.md), built field by field so
//! nothing depends on ros2-client defaults (its default subscription QoS is best-effort,
//! depth 1), plus the rosbag2 `offered_qos_profiles` YAML of each.

use std::time::Duration;

use ros2_client::qos::{Durability, History, Liveliness, Reliability, WhenFull};
pub use ros2_client::QosProfile;

/// How long a reliable `publish` may wait for send-window space before failing.
pub const PUBLISH_MAX_BLOCK: Duration = Duration::from_millis(100);

const fn base(durability: Durability, depth: usize) -> QosProfile {
    QosProfile {
        reliability: Reliability::Reliable {
            when_full: WhenFull::Wait(PUBLISH_MAX_BLOCK),
        },
        durability,
        history: History::KeepLast { depth },
        deadline: None,
        lifespan: None,
        liveliness: Liveliness::Automatic,
        liveliness_lease: None,
    }
}

/// `/clock`: reliable, volatile, keep last 1.
pub const fn clock() -> QosProfile {
    base(Durability::Volatile, 1)
}

/// `/<robot>/pose`, `/<robot>/has_part`, `/<robot>/cmd_vel`: reliable, volatile, depth 10.
pub const fn robot_stream() -> QosProfile {
    base(Durability::Volatile, 10)
}

/// `/machine_<j>/pose`, `/storage_<k>/pose`: reliable, transient local, keep last 1
/// (latched: a late joiner gets the last pose).
pub const fn latched_pose() -> QosProfile {
    base(Durability::TransientLocal, 1)
}

/// `/machine_<j>/part_ready`: reliable, transient local, depth 1.
pub const fn part_ready() -> QosProfile {
    base(Durability::TransientLocal, 1)
}

/// `/tending/markers`, `/tending/metrics`: reliable, volatile, depth 10.
pub const fn visualization() -> QosProfile {
    base(Durability::Volatile, 10)
}

/// `/tending/cells/c<i>_<j>`: reliable, transient local, keep last 1: a robot that enters
/// a cell gets the cell's latest state at once (docs/adr/0038-cell-topics.md).
pub const fn cell() -> QosProfile {
    base(Durability::TransientLocal, 1)
}

/// Which profile a topic uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Profile {
    Clock,
    RobotStream,
    LatchedPose,
    PartReady,
    Visualization,
    Cell,
}

impl Profile {
    pub const fn qos(self) -> QosProfile {
        match self {
            Profile::Clock => clock(),
            Profile::RobotStream => robot_stream(),
            Profile::LatchedPose => latched_pose(),
            Profile::PartReady => part_ready(),
            Profile::Visualization => visualization(),
            Profile::Cell => cell(),
        }
    }

    /// The rosbag2 (metadata version 9, Jazzy) `offered_qos_profiles` YAML for one
    /// publisher with this profile.
    pub fn offered_qos_yaml(self) -> String {
        offered_qos_yaml(&self.qos())
    }
}

/// rosbag2 `offered_qos_profiles` YAML (metadata version 9 string form) of one profile,
/// as a one-element sequence. Infinite durations are written as RMW_DURATION_INFINITE
/// (sec 9223372036, nsec 854775807), as rosbag2 does.
pub fn offered_qos_yaml(q: &QosProfile) -> String {
    let (history, depth) = match q.history {
        History::KeepLast { depth } => ("keep_last", depth),
        History::KeepAll => ("keep_all", 0),
    };
    let reliability = match q.reliability {
        Reliability::BestEffort => "best_effort",
        Reliability::Reliable { .. } => "reliable",
    };
    let durability = match q.durability {
        Durability::Volatile => "volatile",
        Durability::TransientLocal => "transient_local",
    };
    let liveliness = match q.liveliness {
        Liveliness::Automatic => "automatic",
        Liveliness::ManualByTopic => "manual_by_topic",
    };
    fn dur(name: &str, d: Option<Duration>) -> String {
        let (sec, nsec) = match d {
            None => (9_223_372_036u64, 854_775_807u64),
            Some(d) => (d.as_secs(), d.subsec_nanos() as u64),
        };
        format!("  {name}:\n    sec: {sec}\n    nsec: {nsec}\n")
    }
    let mut s = format!(
        "- history: {history}\n  depth: {depth}\n  reliability: {reliability}\n  durability: {durability}\n"
    );
    s.push_str(&dur("deadline", q.deadline));
    s.push_str(&dur("lifespan", q.lifespan));
    s.push_str(&format!("  liveliness: {liveliness}\n"));
    s.push_str(&dur("liveliness_lease_duration", q.liveliness_lease));
    s.push_str("  avoid_ros_namespace_conventions: false");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profiles_match_design_table() {
        let c = clock();
        assert!(matches!(c.reliability, Reliability::Reliable { .. }));
        assert_eq!(c.history, History::KeepLast { depth: 1 });
        let r = robot_stream();
        assert!(matches!(r.reliability, Reliability::Reliable { .. }));
        assert_eq!(r.durability, Durability::Volatile);
        assert_eq!(r.history, History::KeepLast { depth: 10 });
        for p in [latched_pose(), part_ready()] {
            assert!(matches!(p.reliability, Reliability::Reliable { .. }));
            assert_eq!(p.durability, Durability::TransientLocal);
            assert_eq!(p.history, History::KeepLast { depth: 1 });
        }
        // never the ros2-client subscription default
        for p in [
            Profile::Clock,
            Profile::RobotStream,
            Profile::LatchedPose,
            Profile::PartReady,
            Profile::Visualization,
            Profile::Cell,
        ] {
            assert_ne!(p.qos(), QosProfile::subscription_default());
        }
    }

    #[test]
    fn yaml_form() {
        let y = Profile::PartReady.offered_qos_yaml();
        assert_eq!(
            y,
            "- history: keep_last\n  depth: 1\n  reliability: reliable\n  durability: transient_local\n  deadline:\n    sec: 9223372036\n    nsec: 854775807\n  lifespan:\n    sec: 9223372036\n    nsec: 854775807\n  liveliness: automatic\n  liveliness_lease_duration:\n    sec: 9223372036\n    nsec: 854775807\n  avoid_ros_namespace_conventions: false"
        );
        assert!(Profile::RobotStream
            .offered_qos_yaml()
            .contains("depth: 10\n  reliability: reliable\n  durability: volatile\n"));
    }
}
