//! serde mirrors of the ROS 2 (Jazzy) `common_interfaces` message types used by `tending`.
//!
//! CDR is positional: every struct lists its fields in exactly the order of its `.msg`
//! file. Do not reorder fields.

use serde::{Deserialize, Serialize};

// ---------------------------------------------------------------- builtin_interfaces

/// builtin_interfaces/msg/Time
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    /// From seconds (f64); negative and non-finite inputs clamp to zero.
    pub fn from_secs_f64(t: f64) -> Self {
        if !t.is_finite() || t <= 0.0 {
            return Self::default();
        }
        let sec = t.floor();
        let mut nanosec = ((t - sec) * 1e9).round() as u32;
        let mut sec = sec.min(i32::MAX as f64) as i32;
        if nanosec >= 1_000_000_000 {
            nanosec -= 1_000_000_000;
            sec = sec.saturating_add(1);
        }
        Self { sec, nanosec }
    }
    pub fn as_secs_f64(&self) -> f64 {
        self.sec as f64 + self.nanosec as f64 * 1e-9
    }
    /// Current wall-clock time (UNIX epoch).
    pub fn now() -> Self {
        let d = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap_or_default();
        Self {
            sec: d.as_secs().min(i32::MAX as u64) as i32,
            nanosec: d.subsec_nanos(),
        }
    }
}

/// builtin_interfaces/msg/Duration
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Duration {
    pub sec: i32,
    pub nanosec: u32,
}

// ---------------------------------------------------------------- std_msgs

/// std_msgs/msg/Header
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

/// std_msgs/msg/Bool
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Bool {
    pub data: bool,
}

/// std_msgs/msg/String
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct StdString {
    pub data: String,
}

/// std_msgs/msg/ColorRGBA
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct ColorRGBA {
    pub r: f32,
    pub g: f32,
    pub b: f32,
    pub a: f32,
}

// ---------------------------------------------------------------- geometry_msgs

/// geometry_msgs/msg/Point
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Point {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// geometry_msgs/msg/Quaternion (default is the identity, w = 1, as in the .msg)
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Self {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

/// geometry_msgs/msg/Pose
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose {
    pub position: Point,
    pub orientation: Quaternion,
}

/// geometry_msgs/msg/PoseStamped
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PoseStamped {
    pub header: Header,
    pub pose: Pose,
}

impl PoseStamped {
    /// A planar pose at (x, y) in `frame_id` with identity orientation.
    pub fn planar(stamp: Time, frame_id: &str, x: f64, y: f64) -> Self {
        Self {
            header: Header {
                stamp,
                frame_id: frame_id.to_string(),
            },
            pose: Pose {
                position: Point { x, y, z: 0.0 },
                orientation: Quaternion::default(),
            },
        }
    }
}

/// nav_msgs/msg/Path: here also one cell's state (docs/adr/0038-cell-topics.md): one pose
/// per entity, named by its header's frame_id.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Path {
    pub header: Header,
    pub poses: Vec<PoseStamped>,
}

/// geometry_msgs/msg/Vector3
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// geometry_msgs/msg/Twist
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Twist {
    pub linear: Vector3,
    pub angular: Vector3,
}

impl Twist {
    /// A planar holonomic velocity command (linear.x, linear.y), everything else zero.
    pub fn planar(vx: f64, vy: f64) -> Self {
        Self {
            linear: Vector3 {
                x: vx,
                y: vy,
                z: 0.0,
            },
            angular: Vector3::default(),
        }
    }
    pub fn zero() -> Self {
        Self::default()
    }
}

// ---------------------------------------------------------------- rosgraph_msgs

/// rosgraph_msgs/msg/Clock
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Clock {
    pub clock: Time,
}

// ---------------------------------------------------------------- sensor_msgs

/// sensor_msgs/msg/CompressedImage (only as a field of Marker)
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct CompressedImage {
    pub header: Header,
    pub format: String,
    pub data: Vec<u8>,
}

// ---------------------------------------------------------------- visualization_msgs

/// visualization_msgs/msg/UVCoordinate
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct UVCoordinate {
    pub u: f32,
    pub v: f32,
}

/// visualization_msgs/msg/MeshFile
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct MeshFile {
    pub filename: String,
    pub data: Vec<u8>,
}

/// visualization_msgs/msg/Marker (Jazzy layout, with texture and mesh_file fields)
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Marker {
    pub header: Header,
    pub ns: String,
    pub id: i32,
    #[serde(rename = "type")]
    pub type_: i32,
    pub action: i32,
    pub pose: Pose,
    pub scale: Vector3,
    pub color: ColorRGBA,
    pub lifetime: Duration,
    pub frame_locked: bool,
    pub points: Vec<Point>,
    pub colors: Vec<ColorRGBA>,
    pub texture_resource: String,
    pub texture: CompressedImage,
    pub uv_coordinates: Vec<UVCoordinate>,
    pub text: String,
    pub mesh_resource: String,
    pub mesh_file: MeshFile,
    pub mesh_use_embedded_materials: bool,
}

impl Marker {
    pub const ARROW: i32 = 0;
    pub const CUBE: i32 = 1;
    pub const SPHERE: i32 = 2;
    pub const CYLINDER: i32 = 3;
    pub const LINE_STRIP: i32 = 4;
    pub const LINE_LIST: i32 = 5;
    pub const CUBE_LIST: i32 = 6;
    pub const SPHERE_LIST: i32 = 7;
    pub const POINTS: i32 = 8;
    pub const TEXT_VIEW_FACING: i32 = 9;
    pub const MESH_RESOURCE: i32 = 10;
    pub const TRIANGLE_LIST: i32 = 11;
    pub const ARROW_STRIP: i32 = 12;
    pub const ADD: i32 = 0;
    pub const MODIFY: i32 = 0;
    pub const DELETE: i32 = 2;
    pub const DELETEALL: i32 = 3;
}

/// visualization_msgs/msg/MarkerArray
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct MarkerArray {
    pub markers: Vec<Marker>,
}

// ---------------------------------------------------------------- diagnostic_msgs

/// diagnostic_msgs/msg/KeyValue
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct KeyValue {
    pub key: String,
    pub value: String,
}

/// diagnostic_msgs/msg/DiagnosticStatus
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    /// `byte` in the .msg (one octet on the wire)
    pub level: u8,
    pub name: String,
    pub message: String,
    pub hardware_id: String,
    pub values: Vec<KeyValue>,
}

impl DiagnosticStatus {
    pub const OK: u8 = 0;
    pub const WARN: u8 = 1;
    pub const ERROR: u8 = 2;
    pub const STALE: u8 = 3;
}

/// diagnostic_msgs/msg/DiagnosticArray
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct DiagnosticArray {
    pub header: Header,
    pub status: Vec<DiagnosticStatus>,
}

impl DiagnosticArray {
    /// The first value named `key` in any status, as a number: `/tending/metrics` carries
    /// the bridge's figures as key-value strings. None when absent or not a number.
    pub fn number(&self, key: &str) -> Option<f64> {
        self.status
            .iter()
            .flat_map(|s| s.values.iter())
            .find(|kv| kv.key == key)
            .and_then(|kv| kv.value.parse().ok())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn diagnostic_numbers_are_found_in_any_status_and_bad_ones_are_none() {
        let kv = |k: &str, v: &str| KeyValue {
            key: k.into(),
            value: v.into(),
        };
        let d = DiagnosticArray {
            header: Header::default(),
            status: vec![
                DiagnosticStatus {
                    values: vec![kv("step", "12")],
                    ..Default::default()
                },
                DiagnosticStatus {
                    values: vec![kv("mu", "0.75"), kv("setup", "6.4_2")],
                    ..Default::default()
                },
            ],
        };
        assert_eq!(d.number("step"), Some(12.0));
        assert_eq!(d.number("mu"), Some(0.75));
        assert_eq!(d.number("setup"), None, "not a number");
        assert_eq!(d.number("absent"), None);
    }
}
