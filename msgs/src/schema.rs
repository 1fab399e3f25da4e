//! ROS type names and `ros2msg` schema text (rosbag2 MCAP form) of every wire type.
//!
//! The definitions are the Jazzy `.msg` field lists (comments dropped, constants and
//! default values kept). [`schema_text`] renders a type's definition followed by each of
//! its transitive dependencies as a line of 80 `=`, `MSG: pkg/Type` and its definition,
//! which is what rosbag2 writes into MCAP schema records.

use serde::{de::DeserializeOwned, Serialize};

use crate::types::*;

/// One message definition and its direct dependencies.
#[derive(Debug)]
pub struct MsgDef {
    /// ROS 2 package, e.g. `geometry_msgs`.
    pub package: &'static str,
    /// Type name, e.g. `Twist`.
    pub name: &'static str,
    /// The `.msg` text.
    pub text: &'static str,
    /// Direct dependencies (types of fields), in order of first use.
    pub deps: &'static [&'static MsgDef],
}

impl MsgDef {
    /// `pkg/msg/Type`, the form of MCAP schema names and `ros2 topic` output.
    pub fn full_name(&self) -> String {
        format!("{}/msg/{}", self.package, self.name)
    }
    /// `pkg/Type`, the form used after `MSG:` in concatenated definitions.
    pub fn short_name(&self) -> String {
        format!("{}/{}", self.package, self.name)
    }
    /// DDS type name, e.g. `geometry_msgs::msg::dds_::Twist_`.
    pub fn dds_name(&self) -> String {
        format!("{}::msg::dds_::{}_", self.package, self.name)
    }
    /// The ros2-client type name.
    pub fn type_name(&self) -> ros2_client::MessageTypeName {
        ros2_client::MessageTypeName::new(self.package, self.name)
    }
}

/// A wire type with its definition.
pub trait RosMessage: Serialize + DeserializeOwned + 'static {
    const DEF: &'static MsgDef;

    fn full_name() -> String {
        Self::DEF.full_name()
    }
    fn type_name() -> ros2_client::MessageTypeName {
        Self::DEF.type_name()
    }
    fn schema_text() -> String {
        schema_text(Self::DEF)
    }
}

/// The rosbag2 `ros2msg` schema text: own definition, then every transitive dependency
/// (depth-first, first appearance, each once).
pub fn schema_text(def: &MsgDef) -> String {
    fn collect(def: &'static MsgDef, out: &mut Vec<&'static MsgDef>) {
        for d in def.deps {
            if !out.iter().any(|o| std::ptr::eq(*o, *d)) {
                out.push(d);
                collect(d, out);
            }
        }
    }
    let mut deps: Vec<&'static MsgDef> = Vec::new();
    for d in def.deps {
        if !deps.iter().any(|o| std::ptr::eq(*o, *d)) {
            deps.push(d);
            collect(d, &mut deps);
        }
    }
    let mut s = String::from(def.text.trim_end());
    s.push('\n');
    for d in deps {
        s.push_str(&"=".repeat(80));
        s.push('\n');
        s.push_str("MSG: ");
        s.push_str(&d.short_name());
        s.push('\n');
        s.push_str(d.text.trim_end());
        s.push('\n');
    }
    s
}

macro_rules! def {
    ($id:ident, $pkg:literal, $name:literal, [$($dep:ident),*], $text:expr) => {
        pub static $id: MsgDef = MsgDef {
            package: $pkg,
            name: $name,
            text: $text,
            deps: &[$(&$dep),*],
        };
    };
}

def!(
    TIME,
    "builtin_interfaces",
    "Time",
    [],
    "int32 sec\nuint32 nanosec\n"
);
def!(
    DURATION,
    "builtin_interfaces",
    "Duration",
    [],
    "int32 sec\nuint32 nanosec\n"
);
def!(
    HEADER,
    "std_msgs",
    "Header",
    [TIME],
    "builtin_interfaces/Time stamp\nstring frame_id\n"
);
def!(BOOL, "std_msgs", "Bool", [], "bool data\n");
def!(STRING, "std_msgs", "String", [], "string data\n");
def!(
    COLOR_RGBA,
    "std_msgs",
    "ColorRGBA",
    [],
    "float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n"
);
def!(
    POINT,
    "geometry_msgs",
    "Point",
    [],
    "float64 x\nfloat64 y\nfloat64 z\n"
);
def!(
    QUATERNION,
    "geometry_msgs",
    "Quaternion",
    [],
    "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
);
def!(
    POSE,
    "geometry_msgs",
    "Pose",
    [POINT, QUATERNION],
    "Point position\nQuaternion orientation\n"
);
def!(
    POSE_STAMPED,
    "geometry_msgs",
    "PoseStamped",
    [HEADER, POSE],
    "std_msgs/Header header\nPose pose\n"
);
def!(
    PATH,
    "nav_msgs",
    "Path",
    [HEADER, POSE_STAMPED],
    "std_msgs/Header header\ngeometry_msgs/PoseStamped[] poses\n"
);
def!(
    VECTOR3,
    "geometry_msgs",
    "Vector3",
    [],
    "float64 x\nfloat64 y\nfloat64 z\n"
);
def!(
    TWIST,
    "geometry_msgs",
    "Twist",
    [VECTOR3],
    "Vector3 linear\nVector3 angular\n"
);
def!(
    CLOCK,
    "rosgraph_msgs",
    "Clock",
    [TIME],
    "builtin_interfaces/Time clock\n"
);
def!(
    COMPRESSED_IMAGE,
    "sensor_msgs",
    "CompressedImage",
    [HEADER],
    "std_msgs/Header header\nstring format\nuint8[] data\n"
);
def!(
    UV_COORDINATE,
    "visualization_msgs",
    "UVCoordinate",
    [],
    "float32 u\nfloat32 v\n"
);
def!(
    MESH_FILE,
    "visualization_msgs",
    "MeshFile",
    [],
    "string filename\nuint8[] data\n"
);
def!(
    MARKER,
    "visualization_msgs",
    "Marker",
    [
        HEADER,
        POSE,
        VECTOR3,
        COLOR_RGBA,
        DURATION,
        POINT,
        COMPRESSED_IMAGE,
        UV_COORDINATE,
        MESH_FILE
    ],
    "int32 ARROW=0
int32 CUBE=1
int32 SPHERE=2
int32 CYLINDER=3
int32 LINE_STRIP=4
int32 LINE_LIST=5
int32 CUBE_LIST=6
int32 SPHERE_LIST=7
int32 POINTS=8
int32 TEXT_VIEW_FACING=9
int32 MESH_RESOURCE=10
int32 TRIANGLE_LIST=11
int32 ARROW_STRIP=12

int32 ADD=0
int32 MODIFY=0
int32 DELETE=2
int32 DELETEALL=3

std_msgs/Header header
string ns
int32 id
int32 type
int32 action
geometry_msgs/Pose pose
geometry_msgs/Vector3 scale
std_msgs/ColorRGBA color
builtin_interfaces/Duration lifetime
bool frame_locked
geometry_msgs/Point[] points
std_msgs/ColorRGBA[] colors
string texture_resource
sensor_msgs/CompressedImage texture
UVCoordinate[] uv_coordinates
string text
string mesh_resource
MeshFile mesh_file
bool mesh_use_embedded_materials
"
);
def!(
    MARKER_ARRAY,
    "visualization_msgs",
    "MarkerArray",
    [MARKER],
    "Marker[] markers\n"
);
def!(
    KEY_VALUE,
    "diagnostic_msgs",
    "KeyValue",
    [],
    "string key\nstring value\n"
);
def!(
    DIAGNOSTIC_STATUS,
    "diagnostic_msgs",
    "DiagnosticStatus",
    [KEY_VALUE],
    "byte OK=0
byte WARN=1
byte ERROR=2
byte STALE=3

byte level
string name
string message
string hardware_id
KeyValue[] values
"
);
def!(
    DIAGNOSTIC_ARRAY,
    "diagnostic_msgs",
    "DiagnosticArray",
    [HEADER, DIAGNOSTIC_STATUS],
    "std_msgs/Header header\nDiagnosticStatus[] status\n"
);

macro_rules! impl_msg {
    ($($t:ty => $d:ident),* $(,)?) => {
        $(impl RosMessage for $t { const DEF: &'static MsgDef = &$d; })*
    };
}

impl_msg!(
    Time => TIME,
    Duration => DURATION,
    Header => HEADER,
    Bool => BOOL,
    StdString => STRING,
    ColorRGBA => COLOR_RGBA,
    Point => POINT,
    Quaternion => QUATERNION,
    Pose => POSE,
    PoseStamped => POSE_STAMPED,
    Path => PATH,
    Vector3 => VECTOR3,
    Twist => TWIST,
    Clock => CLOCK,
    CompressedImage => COMPRESSED_IMAGE,
    UVCoordinate => UV_COORDINATE,
    MeshFile => MESH_FILE,
    Marker => MARKER,
    MarkerArray => MARKER_ARRAY,
    KeyValue => KEY_VALUE,
    DiagnosticStatus => DIAGNOSTIC_STATUS,
    DiagnosticArray => DIAGNOSTIC_ARRAY,
);

/// Every definition, for tools that want to list or check them.
pub static ALL: &[&MsgDef] = &[
    &TIME,
    &DURATION,
    &HEADER,
    &BOOL,
    &STRING,
    &COLOR_RGBA,
    &POINT,
    &QUATERNION,
    &POSE,
    &POSE_STAMPED,
    &PATH,
    &VECTOR3,
    &TWIST,
    &CLOCK,
    &COMPRESSED_IMAGE,
    &UV_COORDINATE,
    &MESH_FILE,
    &MARKER,
    &MARKER_ARRAY,
    &KEY_VALUE,
    &DIAGNOSTIC_STATUS,
    &DIAGNOSTIC_ARRAY,
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names() {
        assert_eq!(Twist::full_name(), "geometry_msgs/msg/Twist");
        assert_eq!(TWIST.dds_name(), "geometry_msgs::msg::dds_::Twist_");
        assert_eq!(Twist::type_name().dds_msg_type(), TWIST.dds_name());
        assert_eq!(Clock::full_name(), "rosgraph_msgs/msg/Clock");
    }

    #[test]
    fn pose_stamped_schema_has_all_deps_once() {
        let s = PoseStamped::schema_text();
        let sep = "=".repeat(80);
        let expected = format!(
            "std_msgs/Header header\nPose pose\n\
             {sep}\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n\
             {sep}\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n\
             {sep}\nMSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n\
             {sep}\nMSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n\
             {sep}\nMSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
        );
        assert_eq!(s, expected);
    }

    #[test]
    fn every_referenced_type_is_a_dependency() {
        // Each non-builtin field type in a definition must appear in its schema text.
        let builtin = [
            "bool", "byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64",
            "uint64", "float32", "float64", "string", "wstring",
        ];
        for def in ALL {
            let s = schema_text(def);
            for line in def.text.lines() {
                let line = line.trim();
                if line.is_empty() || line.starts_with('#') {
                    continue;
                }
                let ty = line.split_whitespace().next().unwrap();
                let ty = ty.split('[').next().unwrap();
                if builtin.contains(&ty) {
                    continue;
                }
                let qualified = if ty.contains('/') {
                    ty.to_string()
                } else {
                    format!("{}/{}", def.package, ty)
                };
                assert!(
                    s.contains(&format!("MSG: {qualified}\n")),
                    "{}: dependency {qualified} missing",
                    def.full_name()
                );
            }
            // and no dependency appears twice
            let n = s.matches("MSG: ").count();
            let mut names: Vec<&str> = s.lines().filter(|l| l.starts_with("MSG: ")).collect();
            names.sort();
            names.dedup();
            assert_eq!(n, names.len(), "{}", def.full_name());
        }
    }

    #[test]
    fn marker_array_schema_lists_jazzy_fields() {
        let s = MarkerArray::schema_text();
        for needle in [
            "MSG: visualization_msgs/Marker\n",
            "MSG: sensor_msgs/CompressedImage\n",
            "MSG: visualization_msgs/UVCoordinate\n",
            "MSG: visualization_msgs/MeshFile\n",
            "MSG: builtin_interfaces/Duration\n",
            "UVCoordinate[] uv_coordinates\n",
            "bool mesh_use_embedded_materials\n",
        ] {
            assert!(s.contains(needle), "missing {needle:?}");
        }
    }
}
