//! Axis-aligned bounding rectangles.

use crate::math::Vec2;
use serde::{Deserialize, Serialize};

/// An axis-aligned rectangle `[min, max]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Aabb {
    /// Lower-left corner.
    pub min: Vec2,
    /// Upper-right corner.
    pub max: Vec2,
}

impl Aabb {
    /// The rectangle spanned by two corners.
    pub fn new(min: Vec2, max: Vec2) -> Self {
        Self { min, max }
    }
    /// The square of half-width `r` around `c`.
    pub fn around(c: Vec2, r: f32) -> Self {
        Self::new(Vec2::new(c.x - r, c.y - r), Vec2::new(c.x + r, c.y + r))
    }
    /// The smallest rectangle holding all `points` (None when empty).
    pub fn from_points(points: impl IntoIterator<Item = Vec2>) -> Option<Self> {
        let mut it = points.into_iter();
        let first = it.next()?;
        Some(it.fold(Self::new(first, first), |b, p| Self::new(b.min.min(p), b.max.max(p))))
    }
    /// Width and height.
    pub fn size(&self) -> Vec2 {
        self.max - self.min
    }
    /// Area in square metres.
    pub fn area(&self) -> f32 {
        let s = self.size();
        s.x.max(0.0) * s.y.max(0.0)
    }
    /// True if `p` lies inside or on the border.
    pub fn contains(&self, p: Vec2) -> bool {
        p.x >= self.min.x && p.x <= self.max.x && p.y >= self.min.y && p.y <= self.max.y
    }
    /// True if the rectangles share any point.
    pub fn intersects(&self, o: &Aabb) -> bool {
        self.min.x <= o.max.x
            && o.min.x <= self.max.x
            && self.min.y <= o.max.y
            && o.min.y <= self.max.y
    }
    /// The smallest rectangle holding both.
    pub fn union(&self, o: &Aabb) -> Aabb {
        Aabb::new(self.min.min(o.min), self.max.max(o.max))
    }
    /// The rectangle grown by `m` on every side.
    pub fn inflate(&self, m: f32) -> Aabb {
        Aabb::new(self.min - Vec2::new(m, m), self.max + Vec2::new(m, m))
    }
}
