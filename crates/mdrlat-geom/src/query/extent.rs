//! The angular interval a shape covers as seen from a viewpoint.
//!
//! A sensor only casts the rays of its fan that fall inside this interval, so the cost of a
//! scan grows with what the sensor sees, not with the number of obstacles in the world.

use crate::math::Vec2;
use crate::shape::Shape;

/// Angles (world frame, radians) under which a shape is seen from a viewpoint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Extent {
    /// The viewpoint is inside the footprint: every direction hits it.
    Full,
    /// Directions in `[lo, hi]`, with `lo <= hi < lo + π`; `lo` and `hi` may lie outside
    /// (−π, π] (they are not wrapped).
    Arc {
        /// Most clockwise direction.
        lo: f32,
        /// Most counter-clockwise direction.
        hi: f32,
    },
}

impl Shape {
    /// The directions from `from` that hit the shape.
    pub fn angular_extent(&self, from: Vec2) -> Extent {
        match self {
            Shape::Cylinder(c) => {
                let d = c.center - from;
                let dist = d.length();
                if dist <= c.radius {
                    return Extent::Full;
                }
                let half = (c.radius / dist).asin();
                let mid = d.angle();
                Extent::Arc { lo: mid - half, hi: mid + half }
            }
            Shape::Cuboid(b) => vertex_extent(&b.corners(), from, self),
            Shape::Polygon(p) => vertex_extent(p.points(), from, self),
        }
    }
}

fn vertex_extent(points: &[Vec2], from: Vec2, shape: &Shape) -> Extent {
    if shape.contains(from) {
        return Extent::Full;
    }
    // All vertices lie within less than π of each other as seen from outside a convex shape,
    // so the cross product orders them by angle; only the two extremes need an atan2.
    let mut lo = points[0] - from;
    let mut hi = lo;
    for &p in &points[1..] {
        let r = p - from;
        if lo.cross(r) < 0.0 {
            lo = r;
        }
        if hi.cross(r) > 0.0 {
            hi = r;
        }
    }
    let lo_a = lo.angle();
    let mut hi_a = hi.angle();
    if hi_a < lo_a {
        hi_a += std::f32::consts::TAU;
    }
    Extent::Arc { lo: lo_a, hi: hi_a }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape::{Cuboid, Cylinder};
    use std::f32::consts::{FRAC_PI_4, PI};

    #[test]
    fn box_straight_ahead_and_behind() {
        let b =
            Shape::Cuboid(Cuboid::new(Vec2::new(2.0, 0.0), Vec2::new(2.0, 2.0), 0.0).expect("box"));
        match b.angular_extent(Vec2::ZERO) {
            Extent::Arc { lo, hi } => {
                assert!((lo + FRAC_PI_4).abs() < 1e-6 && (hi - FRAC_PI_4).abs() < 1e-6, "{lo} {hi}")
            }
            Extent::Full => panic!("not inside"),
        }
        // Behind the viewpoint the interval straddles ±π and is returned unwrapped.
        let b = Shape::Cuboid(
            Cuboid::new(Vec2::new(-2.0, 0.0), Vec2::new(2.0, 2.0), 0.0).expect("box"),
        );
        match b.angular_extent(Vec2::ZERO) {
            Extent::Arc { lo, hi } => {
                assert!((hi - lo - PI / 2.0).abs() < 1e-5, "{lo} {hi}");
                assert!((lo.sin() - (0.75 * PI).sin()).abs() < 1e-5);
            }
            Extent::Full => panic!("not inside"),
        }
        assert_eq!(b.angular_extent(Vec2::new(-2.0, 0.5)), Extent::Full);
    }

    #[test]
    fn cylinder_tangents() {
        let c = Shape::Cylinder(Cylinder::new(Vec2::new(0.0, 2.0), 1.0).expect("cyl"));
        match c.angular_extent(Vec2::ZERO) {
            Extent::Arc { lo, hi } => {
                assert!((lo - (PI / 2.0 - PI / 6.0)).abs() < 1e-5);
                assert!((hi - (PI / 2.0 + PI / 6.0)).abs() < 1e-5);
            }
            Extent::Full => panic!(),
        }
    }
}
