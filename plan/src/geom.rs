//! Small planar geometry on what a robot observes: axis-aligned boxes (machines, storages)
//! given by centre and half extents, points in the robot's frame.

/// The point of the box (`centre`, `half`) nearest to `p` (p itself when inside).
#[inline]
pub fn nearest_on_box(centre: [f32; 2], half: [f32; 2], p: [f32; 2]) -> [f32; 2] {
    [
        centre[0] + (p[0] - centre[0]).clamp(-half[0], half[0]),
        centre[1] + (p[1] - centre[1]).clamp(-half[1], half[1]),
    ]
}

/// Signed distance from `p` to the box surface: Euclidean outside, minus the depth inside
/// (the simulator's contact test uses the same measure).
#[inline]
pub fn box_distance(centre: [f32; 2], half: [f32; 2], p: [f32; 2]) -> f32 {
    let dx = (p[0] - centre[0]).abs() - half[0];
    let dy = (p[1] - centre[1]).abs() - half[1];
    if dx > 0.0 || dy > 0.0 {
        (dx.max(0.0).powi(2) + dy.max(0.0).powi(2)).sqrt()
    } else {
        dx.max(dy)
    }
}

#[inline]
pub fn norm(v: [f32; 2]) -> f32 {
    (v[0] * v[0] + v[1] * v[1]).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances_outside_inside_and_at_corners() {
        let (c, h) = ([1.0, 0.0], [0.5, 0.25]);
        assert!((box_distance(c, h, [0.0, 0.0]) - 0.5).abs() < 1e-6);
        assert!((box_distance(c, h, [1.0, 0.0]) + 0.25).abs() < 1e-6);
        // Corner: (0.5, 0.25) from (0.2, 0.65) is (0.3, 0.4) away.
        assert!((box_distance(c, h, [0.2, 0.65]) - 0.5).abs() < 1e-6);
        assert_eq!(nearest_on_box(c, h, [0.2, 0.65]), [0.5, 0.25]);
        assert_eq!(nearest_on_box(c, h, [1.1, 0.1]), [1.1, 0.1]);
    }
}
