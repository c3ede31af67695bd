//! A rotated rectangle (a box prism's footprint).

use super::ShapeError;
use crate::aabb::Aabb;
use crate::math::Vec2;

/// A rectangle of half-extents `half` centred at `center`, rotated by `yaw` radians.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cuboid {
    /// Centre, world frame.
    pub center: Vec2,
    /// Half width (local x) and half depth (local y), metres.
    pub half: Vec2,
    /// Rotation, radians counter-clockwise.
    pub yaw: f32,
    cos: f32,
    sin: f32,
}

impl Cuboid {
    /// A box of full `size` centred at `center`, rotated by `yaw` radians.
    ///
    /// # Errors
    /// Non-finite values or a non-positive size.
    pub fn new(center: Vec2, size: Vec2, yaw: f32) -> Result<Self, ShapeError> {
        if !center.is_finite() {
            return Err(ShapeError::NotFinite("center"));
        }
        if !size.is_finite() {
            return Err(ShapeError::NotFinite("size"));
        }
        if !yaw.is_finite() {
            return Err(ShapeError::NotFinite("yaw"));
        }
        for v in [size.x, size.y] {
            if v <= 0.0 {
                return Err(ShapeError::NotPositive { what: "size", value: v });
            }
        }
        Ok(Self::from_parts(center, size * 0.5, yaw))
    }

    pub(crate) fn from_parts(center: Vec2, half: Vec2, yaw: f32) -> Self {
        let (sin, cos) = yaw.sin_cos();
        Self { center, half, yaw, cos, sin }
    }

    /// `(cos yaw, sin yaw)`.
    pub fn rotation(&self) -> (f32, f32) {
        (self.cos, self.sin)
    }

    /// A world point in the box's local frame.
    pub fn to_local(&self, p: Vec2) -> Vec2 {
        (p - self.center).rotate(self.cos, -self.sin)
    }

    /// The four corners, counter-clockwise.
    pub fn corners(&self) -> [Vec2; 4] {
        let h = self.half;
        [Vec2::new(-h.x, -h.y), Vec2::new(h.x, -h.y), Vec2::new(h.x, h.y), Vec2::new(-h.x, h.y)]
            .map(|p| p.rotate(self.cos, self.sin) + self.center)
    }

    /// Bounding rectangle.
    pub fn aabb(&self) -> Aabb {
        let ex = self.half.x * self.cos.abs() + self.half.y * self.sin.abs();
        let ey = self.half.x * self.sin.abs() + self.half.y * self.cos.abs();
        Aabb::new(self.center - Vec2::new(ex, ey), self.center + Vec2::new(ex, ey))
    }

    /// Distance from a world point (0 inside).
    pub fn distance_to_point(&self, p: Vec2) -> f32 {
        let q = self.to_local(p);
        let dx = (q.x.abs() - self.half.x).max(0.0);
        let dy = (q.y.abs() - self.half.y).max(0.0);
        dx.hypot(dy)
    }

    /// Slab test in the local frame; returns raw `(t_in, t_out)` (a miss has `t_in > t_out`).
    pub fn cast_ray(&self, origin: Vec2, dir: Vec2) -> (f32, f32) {
        let o = self.to_local(origin);
        let d = dir.rotate(self.cos, -self.sin);
        slab_pub(o, d, self.half)
    }
}

/// Slab intersection of the ray `o + t·d` with the box `[-h, h]` (local frame).
#[inline(always)]
pub(crate) fn slab_pub(o: Vec2, d: Vec2, h: Vec2) -> (f32, f32) {
    let (ix, iy) = (1.0 / d.x, 1.0 / d.y);
    let (x1, x2) = ((-h.x - o.x) * ix, (h.x - o.x) * ix);
    let (y1, y2) = ((-h.y - o.y) * iy, (h.y - o.y) * iy);
    let t_in = x1.min(x2).max(y1.min(y2));
    let t_out = x1.max(x2).min(y1.max(y2));
    (t_in, t_out)
}
