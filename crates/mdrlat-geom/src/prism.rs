//! A vertical prism: a convex footprint extruded over a height interval.

use crate::shape::Shape;

/// An obstacle: `shape` extruded from `z_min` to `z_max` metres above the floor.
///
/// Walls are tall boxes, a table top is a thin box at 0.7 m, a low box lies below the laser
/// plane, a pedestrian is a 1.7 m cylinder.
#[derive(Debug, Clone, PartialEq)]
pub struct Prism {
    /// Footprint.
    pub shape: Shape,
    /// Bottom face height, metres.
    pub z_min: f32,
    /// Top face height, metres.
    pub z_max: f32,
}

impl Prism {
    /// A prism; callers validate `z_min < z_max` (the world loader does, with file context).
    pub fn new(shape: Shape, z_min: f32, z_max: f32) -> Self {
        Self { shape, z_min, z_max }
    }

    /// True if the prism's height interval contains the plane at height `z`.
    pub fn spans_height(&self, z: f32) -> bool {
        self.z_min <= z && z <= self.z_max
    }

    /// True if the open height intervals `(z_min, z_max)` and `(lo, hi)` overlap.
    pub fn overlaps_heights(&self, lo: f32, hi: f32) -> bool {
        self.z_min < hi && lo < self.z_max
    }
}
