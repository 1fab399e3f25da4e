//! Input validation: a message from the wire must pass before it reaches a controller.

use crate::types::{PoseStamped, Twist};

/// Half the side of the 2.3 m x 2.3 m room, centred at the origin.
pub const ROOM_HALF_EXTENT: f64 = 1.15;
/// Default tolerance beyond the walls (localization noise, entity radius).
pub const DEFAULT_MARGIN: f64 = 0.25;

/// The accepted area: |x| and |y| at most `half_extent + margin`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RoomBounds {
    pub half_extent: f64,
    pub margin: f64,
}

impl Default for RoomBounds {
    fn default() -> Self {
        Self {
            half_extent: ROOM_HALF_EXTENT,
            margin: DEFAULT_MARGIN,
        }
    }
}

impl RoomBounds {
    pub fn limit(&self) -> f64 {
        self.half_extent + self.margin
    }
    pub fn contains(&self, x: f64, y: f64) -> bool {
        let l = self.limit();
        x.abs() <= l && y.abs() <= l
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InvalidMsg {
    #[error("field `{field}` is not finite ({value})")]
    NonFinite { field: &'static str, value: f64 },
    #[error("position ({x}, {y}) is outside the room (|x|,|y| <= {limit})")]
    OutOfRoom { x: f64, y: f64, limit: f64 },
}

fn finite(field: &'static str, value: f64) -> Result<(), InvalidMsg> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(InvalidMsg::NonFinite { field, value })
    }
}

/// Accept a pose only if every number is finite and the position is inside the room;
/// returns the planar position (x, y).
pub fn pose_stamped(p: &PoseStamped, room: &RoomBounds) -> Result<[f64; 2], InvalidMsg> {
    let pos = &p.pose.position;
    let q = &p.pose.orientation;
    finite("pose.position.x", pos.x)?;
    finite("pose.position.y", pos.y)?;
    finite("pose.position.z", pos.z)?;
    finite("pose.orientation.x", q.x)?;
    finite("pose.orientation.y", q.y)?;
    finite("pose.orientation.z", q.z)?;
    finite("pose.orientation.w", q.w)?;
    if !room.contains(pos.x, pos.y) {
        return Err(InvalidMsg::OutOfRoom {
            x: pos.x,
            y: pos.y,
            limit: room.limit(),
        });
    }
    Ok([pos.x, pos.y])
}

/// Accept a twist only if all six numbers are finite.
pub fn twist(t: &Twist) -> Result<(), InvalidMsg> {
    finite("linear.x", t.linear.x)?;
    finite("linear.y", t.linear.y)?;
    finite("linear.z", t.linear.z)?;
    finite("angular.x", t.angular.x)?;
    finite("angular.y", t.angular.y)?;
    finite("angular.z", t.angular.z)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::*;

    #[test]
    fn pose_checks() {
        let room = RoomBounds::default();
        let ok = PoseStamped::planar(Time::default(), "map", 1.15, -1.15);
        assert_eq!(pose_stamped(&ok, &room), Ok([1.15, -1.15]));
        let edge = PoseStamped::planar(Time::default(), "map", 1.39, 0.0);
        assert!(pose_stamped(&edge, &room).is_ok());
        let out = PoseStamped::planar(Time::default(), "map", 1.41, 0.0);
        assert!(matches!(
            pose_stamped(&out, &room),
            Err(InvalidMsg::OutOfRoom { .. })
        ));
        let tight = RoomBounds {
            margin: 0.0,
            ..room
        };
        assert!(pose_stamped(&edge, &tight).is_err());
        let mut nan = ok.clone();
        nan.pose.position.y = f64::NAN;
        assert!(matches!(
            pose_stamped(&nan, &room),
            Err(InvalidMsg::NonFinite {
                field: "pose.position.y",
                ..
            })
        ));
        let mut q = ok.clone();
        q.pose.orientation.w = f64::INFINITY;
        assert!(pose_stamped(&q, &room).is_err());
        let mut z = ok;
        z.pose.position.z = f64::NEG_INFINITY;
        assert!(pose_stamped(&z, &room).is_err());
    }

    #[test]
    fn twist_checks() {
        assert!(twist(&Twist::planar(0.5, 0.0)).is_ok());
        let mut t = Twist::zero();
        t.angular.z = f64::NAN;
        assert!(twist(&t).is_err());
    }
}
