//! Points, vectors and planar poses.

use serde::{Deserialize, Serialize};
use std::ops::{Add, Mul, Neg, Sub};

/// A 2D point or vector, metres.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Vec2 {
    /// x coordinate.
    pub x: f32,
    /// y coordinate.
    pub y: f32,
}

impl Vec2 {
    /// The vector (x, y).
    pub const fn new(x: f32, y: f32) -> Self {
        Self { x, y }
    }
    /// The zero vector.
    pub const ZERO: Vec2 = Vec2::new(0.0, 0.0);
    /// Unit vector at angle `a` (radians, counter-clockwise from +x).
    pub fn from_angle(a: f32) -> Self {
        let (s, c) = a.sin_cos();
        Self::new(c, s)
    }
    /// Dot product.
    pub fn dot(self, o: Vec2) -> f32 {
        self.x * o.x + self.y * o.y
    }
    /// z component of the 3D cross product.
    pub fn cross(self, o: Vec2) -> f32 {
        self.x * o.y - self.y * o.x
    }
    /// Euclidean length.
    pub fn length(self) -> f32 {
        self.x.hypot(self.y)
    }
    /// Squared length.
    pub fn length_sq(self) -> f32 {
        self.dot(self)
    }
    /// Angle of the vector, radians in (−π, π].
    pub fn angle(self) -> f32 {
        self.y.atan2(self.x)
    }
    /// This vector rotated by `(cos, sin)` of an angle.
    pub fn rotate(self, cos: f32, sin: f32) -> Vec2 {
        Vec2::new(cos * self.x - sin * self.y, sin * self.x + cos * self.y)
    }
    /// True if both coordinates are finite.
    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite()
    }
    /// Component-wise minimum.
    pub fn min(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x.min(o.x), self.y.min(o.y))
    }
    /// Component-wise maximum.
    pub fn max(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x.max(o.x), self.y.max(o.y))
    }
}

impl Add for Vec2 {
    type Output = Vec2;
    fn add(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x + o.x, self.y + o.y)
    }
}
impl Sub for Vec2 {
    type Output = Vec2;
    fn sub(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x - o.x, self.y - o.y)
    }
}
impl Mul<f32> for Vec2 {
    type Output = Vec2;
    fn mul(self, k: f32) -> Vec2 {
        Vec2::new(self.x * k, self.y * k)
    }
}
impl Neg for Vec2 {
    type Output = Vec2;
    fn neg(self) -> Vec2 {
        Vec2::new(-self.x, -self.y)
    }
}
impl From<[f32; 2]> for Vec2 {
    fn from(a: [f32; 2]) -> Self {
        Vec2::new(a[0], a[1])
    }
}

/// A planar pose: position in metres and heading `yaw` in radians (counter-clockwise from +x).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose2 {
    /// x position, metres.
    pub x: f32,
    /// y position, metres.
    pub y: f32,
    /// Heading, radians.
    pub yaw: f32,
}

impl Pose2 {
    /// The pose (x, y, yaw).
    pub const fn new(x: f32, y: f32, yaw: f32) -> Self {
        Self { x, y, yaw }
    }
    /// Position as a vector.
    pub fn position(&self) -> Vec2 {
        Vec2::new(self.x, self.y)
    }
    /// Maps a point from this pose's frame into the world frame.
    pub fn to_world(&self, p_local: Vec2) -> Vec2 {
        let (s, c) = self.yaw.sin_cos();
        p_local.rotate(c, s) + self.position()
    }
    /// Maps a world point into this pose's frame.
    pub fn to_local(&self, p_world: Vec2) -> Vec2 {
        let (s, c) = self.yaw.sin_cos();
        (p_world - self.position()).rotate(c, -s)
    }
}

/// Wraps an angle into (−π, π].
pub fn wrap_angle(a: f32) -> f32 {
    use std::f32::consts::{PI, TAU};
    let mut r = a % TAU;
    if r > PI {
        r -= TAU;
    } else if r <= -PI {
        r += TAU;
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pose_round_trip() {
        let p = Pose2::new(1.0, 2.0, 0.7);
        let q = Vec2::new(-0.3, 4.0);
        let back = p.to_world(p.to_local(q));
        assert!((back - q).length() < 1e-5);
        let ahead = p.to_world(Vec2::new(1.0, 0.0));
        assert!((ahead - Vec2::new(1.0 + 0.7f32.cos(), 2.0 + 0.7f32.sin())).length() < 1e-6);
    }

    #[test]
    fn wrap() {
        use std::f32::consts::PI;
        assert!((wrap_angle(3.0 * PI) - PI).abs() < 1e-5);
        assert!((wrap_angle(-0.5) + 0.5).abs() < 1e-6);
        assert!((wrap_angle(2.0 * PI + 0.1) - 0.1).abs() < 1e-5);
    }
}
