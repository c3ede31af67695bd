//! The three convex 2D shapes a prism can have, and their world-frame queries.
//!
//! Each shape implements its queries in its own local frame (`cuboid.rs`, `cylinder.rs`,
//! `polygon.rs`); this module dispatches and transforms.

pub(crate) mod cuboid;
mod cylinder;
mod polygon;

pub use cuboid::Cuboid;
pub use cylinder::Cylinder;
pub use polygon::{ConvexPolygon, MAX_POLYGON_VERTICES};

use crate::aabb::Aabb;
use crate::math::Vec2;

/// Why a shape could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ShapeError {
    /// A coordinate or size is NaN or infinite.
    #[error("{0} must be finite")]
    NotFinite(&'static str),
    /// A size or radius is zero or negative.
    #[error("{what} must be positive, got {value}")]
    NotPositive {
        /// Which quantity.
        what: &'static str,
        /// The offending value.
        value: f32,
    },
    /// A polygon with too few or too many vertices.
    #[error("a polygon needs 3 to {max} points, got {got}", max = MAX_POLYGON_VERTICES)]
    VertexCount {
        /// Points given.
        got: usize,
    },
    /// A polygon that is not convex, or has repeated or collinear-degenerate points.
    #[error("polygon is not convex (or has zero area / repeated points) at point {index}")]
    NotConvex {
        /// Index of the first vertex where convexity fails.
        index: usize,
    },
}

/// A convex 2D shape in the world frame.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// A rotated rectangle.
    Cuboid(Cuboid),
    /// A circle.
    Cylinder(Cylinder),
    /// A convex polygon.
    Polygon(ConvexPolygon),
}

impl Shape {
    /// The bounding rectangle.
    pub fn aabb(&self) -> Aabb {
        match self {
            Shape::Cuboid(s) => s.aabb(),
            Shape::Cylinder(s) => s.aabb(),
            Shape::Polygon(s) => s.aabb(),
        }
    }

    /// Euclidean distance from `p` to the shape; 0 when `p` is inside or on the border.
    pub fn distance_to_point(&self, p: Vec2) -> f32 {
        match self {
            Shape::Cuboid(s) => s.distance_to_point(p),
            Shape::Cylinder(s) => s.distance_to_point(p),
            Shape::Polygon(s) => s.distance_to_point(p),
        }
    }

    /// True if `p` is inside or on the border.
    pub fn contains(&self, p: Vec2) -> bool {
        self.distance_to_point(p) <= 0.0
    }

    /// True if a disc of radius `r` centred at `c` overlaps the shape's interior.
    pub fn overlaps_disc(&self, c: Vec2, r: f32) -> bool {
        self.distance_to_point(c) < r
    }

    /// Casts the ray `origin + t·dir` (`dir` a unit vector) in the world frame.
    /// Returns the entry and exit parameters `(t_in, t_out)` with `t_out >= 0`; `t_in` is
    /// negative when the origin is inside. `None` when the ray misses.
    pub fn cast_ray(&self, origin: Vec2, dir: Vec2) -> Option<(f32, f32)> {
        let (t_in, t_out) = match self {
            Shape::Cuboid(s) => s.cast_ray(origin, dir),
            Shape::Cylinder(s) => s.cast_ray(origin, dir),
            Shape::Polygon(s) => s.cast_ray(origin, dir),
        };
        (t_in <= t_out && t_out >= 0.0).then_some((t_in, t_out))
    }

    /// The outline as a closed polygon (a cylinder is approximated by `segments` points),
    /// for drawing.
    pub fn outline(&self, segments: usize) -> Vec<Vec2> {
        match self {
            Shape::Cuboid(s) => s.corners().to_vec(),
            Shape::Cylinder(s) => (0..segments.max(3))
                .map(|i| {
                    let a = i as f32 / segments.max(3) as f32 * std::f32::consts::TAU;
                    s.center + Vec2::from_angle(a) * s.radius
                })
                .collect(),
            Shape::Polygon(s) => s.points().to_vec(),
        }
    }

    /// The shape moved to a new centre (cylinders: their centre; boxes: their centre;
    /// polygons: translated by the difference of centroids). Used for moving obstacles.
    pub fn translated(&self, by: Vec2) -> Shape {
        match self {
            Shape::Cuboid(s) => Shape::Cuboid(Cuboid::from_parts(s.center + by, s.half, s.yaw)),
            Shape::Cylinder(s) => {
                Shape::Cylinder(Cylinder { center: s.center + by, radius: s.radius })
            }
            Shape::Polygon(s) => Shape::Polygon(s.translated(by)),
        }
    }
}
