//! A circle (a cylinder prism's footprint: posts, stools, pedestrians).

use super::ShapeError;
use crate::aabb::Aabb;
use crate::math::Vec2;

/// A circle of `radius` centred at `center`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cylinder {
    /// Centre, world frame.
    pub center: Vec2,
    /// Radius, metres.
    pub radius: f32,
}

impl Cylinder {
    /// A circle; errors on non-finite values or a non-positive radius.
    ///
    /// # Errors
    /// Non-finite centre or radius, radius ≤ 0.
    pub fn new(center: Vec2, radius: f32) -> Result<Self, ShapeError> {
        if !center.is_finite() {
            return Err(ShapeError::NotFinite("center"));
        }
        if !radius.is_finite() {
            return Err(ShapeError::NotFinite("radius"));
        }
        if radius <= 0.0 {
            return Err(ShapeError::NotPositive { what: "radius", value: radius });
        }
        Ok(Self { center, radius })
    }

    /// Bounding rectangle.
    pub fn aabb(&self) -> Aabb {
        Aabb::around(self.center, self.radius)
    }

    /// Distance from a point (0 inside).
    pub fn distance_to_point(&self, p: Vec2) -> f32 {
        ((p - self.center).length() - self.radius).max(0.0)
    }

    /// Ray–circle intersection; returns raw `(t_in, t_out)` (a miss has `t_in > t_out`).
    pub fn cast_ray(&self, origin: Vec2, dir: Vec2) -> (f32, f32) {
        circle(origin - self.center, dir, self.radius * self.radius)
    }
}

/// Intersection of the ray `oc + t·d` (`d` unit, `oc` = origin − centre) with a circle of
/// squared radius `r2` at the origin.
#[inline(always)]
pub(crate) fn circle(oc: Vec2, d: Vec2, r2: f32) -> (f32, f32) {
    let b = oc.dot(d);
    let disc = b * b - (oc.dot(oc) - r2);
    if disc < 0.0 {
        return (f32::INFINITY, f32::NEG_INFINITY);
    }
    let s = disc.sqrt();
    (-b - s, -b + s)
}
