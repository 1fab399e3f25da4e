//! What the bridge shows of its core besides the entity topics: `/tending/metrics` as a
//! DiagnosticArray, `/tending/markers` for RViz and Foxglove.

use msgs::{
    ColorRGBA, DiagnosticArray, DiagnosticStatus, Header, KeyValue, Marker, MarkerArray, Pose,
    Vector3,
};

use super::Core;

impl Core {
    pub fn diagnostics(&self) -> DiagnosticArray {
        let m = self.metrics();
        let kv = |k: &str, v: String| KeyValue {
            key: k.into(),
            value: v,
        };
        DiagnosticArray {
            header: Header {
                stamp: self.stamp(),
                frame_id: String::new(),
            },
            status: vec![DiagnosticStatus {
                level: DiagnosticStatus::OK,
                name: "tending/metrics".into(),
                message: format!(
                    "{} delivered, MU {:.3}, {} collisions",
                    m.parts_delivered, m.mu, m.collisions
                ),
                hardware_id: "sim_bridge".into(),
                values: vec![
                    kv("parts_delivered", m.parts_delivered.to_string()),
                    kv("parts_collected", m.parts_collected.to_string()),
                    kv("collisions", m.collisions.to_string()),
                    kv(
                        "collisions_robot_robot",
                        m.collisions_robot_robot.to_string(),
                    ),
                    kv(
                        "collisions_robot_machine",
                        m.collisions_robot_machine.to_string(),
                    ),
                    kv(
                        "collisions_robot_storage",
                        m.collisions_robot_storage.to_string(),
                    ),
                    kv("collisions_robot_wall", m.collisions_robot_wall.to_string()),
                    kv("collision_events", m.collision_events.to_string()),
                    kv("machine_utilization", format!("{:.4}", m.mu)),
                    kv("p_max", m.p_max.to_string()),
                    kv("robots", m.robots.to_string()),
                    kv("step", m.step.to_string()),
                    kv(
                        "lockstep_timeouts",
                        m.counters.lockstep_timeouts.to_string(),
                    ),
                    kv(
                        "cmds_dropped",
                        (m.counters.cmds_dropped_non_finite + m.counters.cmds_dropped_decode)
                            .to_string(),
                    ),
                    kv(
                        "cmds_foreign_writer",
                        m.counters.cmds_foreign_writer.to_string(),
                    ),
                ],
            }],
        }
    }

    /// Robots red cylinders, machines green cubes (dimmer when no part is ready), storages
    /// blue cubes, as in the paper's figures. DELETEALL first so removed bodies vanish.
    pub fn markers(&self) -> MarkerArray {
        let header = Header {
            stamp: self.stamp(),
            frame_id: msgs::topics::FRAME_ID.into(),
        };
        let mut markers = vec![Marker {
            header: header.clone(),
            action: Marker::DELETEALL,
            ..Default::default()
        }];
        let mk = |ns: &str, id: u32, ty: i32, c: [f32; 2], scale: [f64; 3], color: ColorRGBA| {
            let mut pose = Pose::default();
            pose.position.x = c[0] as f64;
            pose.position.y = c[1] as f64;
            pose.position.z = scale[2] / 2.0;
            Marker {
                header: header.clone(),
                ns: ns.into(),
                id: id as i32,
                type_: ty,
                action: Marker::ADD,
                pose,
                scale: Vector3 {
                    x: scale[0],
                    y: scale[1],
                    z: scale[2],
                },
                color,
                ..Default::default()
            }
        };
        let rgba = |r, g, b, a| ColorRGBA { r, g, b, a };
        let d = 2.0 * self.env.sizes().robot_radius as f64;
        for r in self.env.robots() {
            let c = if r.has_part {
                rgba(1.0, 0.5, 0.5, 1.0)
            } else {
                rgba(0.9, 0.1, 0.1, 1.0)
            };
            markers.push(mk(
                "robots",
                r.id.0,
                Marker::CYLINDER,
                r.pos,
                [d, d, 0.1],
                c,
            ));
        }
        for m in self.env.machines() {
            let c = if m.part_ready {
                rgba(0.1, 0.8, 0.1, 1.0)
            } else {
                rgba(0.1, 0.5, 0.1, 0.6)
            };
            let s = [2.0 * m.half[0] as f64, 2.0 * m.half[1] as f64, 0.2];
            markers.push(mk("machines", m.id.0, Marker::CUBE, m.centre, s, c));
        }
        for s in self.env.storages() {
            let sc = [2.0 * s.half[0] as f64, 2.0 * s.half[1] as f64, 0.05];
            markers.push(mk(
                "storages",
                s.id.0,
                Marker::CUBE,
                s.centre,
                sc,
                rgba(0.1, 0.2, 0.9, 1.0),
            ));
        }
        MarkerArray { markers }
    }
}
