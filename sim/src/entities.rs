//! Typed, stable handles and sizes of the bodies in a world.
//!
//! Ids are never reused within an `Env`'s lifetime (until `reset`), so a ROS topic
//! `/robot_3` keeps meaning the same body while others come and go.

use serde::{Deserialize, Serialize};

macro_rules! id_type {
    ($name:ident) => {
        #[derive(
            Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize,
        )]
        pub struct $name(pub u32);
    };
}
id_type!(RobotId);
id_type!(MachineId);
id_type!(StorageId);

/// Body sizes of one environment, fixed at reset from its setup (they never change while
/// bodies come and go, as physical robots would not).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Sizes {
    /// The factor applied to the configured base sizes.
    pub scale: f32,
    pub robot_radius: f32,
    /// Half extents of a machine box.
    pub machine_half: [f32; 2],
    /// Half extents of a storage box.
    pub storage_half: [f32; 2],
    /// Pick/place reach beyond the robot radius.
    pub reach: f32,
}

/// A static axis-aligned box (machine or storage).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct StaticBox {
    pub centre: [f32; 2],
    pub half: [f32; 2],
}

impl StaticBox {
    /// Signed distance from a point to the box surface (negative inside) and the unit
    /// direction pointing from the box towards the point, via parry2d's point projection
    /// (it handles points inside the box, where the closest-point direction flips).
    #[inline]
    pub fn signed_distance(&self, p: [f32; 2]) -> (f32, [f32; 2]) {
        use parry2d::math::{Point, Vector};
        use parry2d::query::PointQuery;
        use parry2d::shape::Cuboid;
        let local = Point::new(p[0] - self.centre[0], p[1] - self.centre[1]);
        let cuboid = Cuboid::new(Vector::new(self.half[0], self.half[1]));
        let proj = cuboid.project_local_point(&local, false);
        let d = local - proj.point;
        let n = d.norm();
        if n <= f32::EPSILON {
            // Exactly on the surface: push along the axis of least penetration.
            let ex = self.half[0] - local.x.abs();
            let ey = self.half[1] - local.y.abs();
            let dir = if ex < ey {
                [local.x.signum(), 0.0]
            } else {
                [0.0, local.y.signum()]
            };
            return (0.0, dir);
        }
        if proj.is_inside {
            (-n, [-d.x / n, -d.y / n])
        } else {
            (n, [d.x / n, d.y / n])
        }
    }

    /// Quick reject: is `p` farther than `margin` from the box's bounding rectangle?
    #[inline]
    pub fn far(&self, p: [f32; 2], margin: f32) -> bool {
        (p[0] - self.centre[0]).abs() > self.half[0] + margin
            || (p[1] - self.centre[1]).abs() > self.half[1] + margin
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signed_distance_outside_inside_and_direction() {
        let b = StaticBox {
            centre: [1.0, 0.0],
            half: [0.5, 0.25],
        };
        let (d, n) = b.signed_distance([2.0, 0.0]);
        assert!((d - 0.5).abs() < 1e-6 && (n[0] - 1.0).abs() < 1e-6);
        let (d, n) = b.signed_distance([1.0, 0.2]);
        assert!((d + 0.05).abs() < 1e-6, "{d}");
        assert!((n[1] - 1.0).abs() < 1e-6, "{n:?}");
        let (d, _) = b.signed_distance([2.0, 1.25]);
        assert!((d - (0.5f32 * 0.5 + 1.0).sqrt()).abs() < 1e-5);
    }
}
