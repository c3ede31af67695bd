//! 2.5D geometry for the mdrlat simulator.
//!
//! Every obstacle is a vertical [`Prism`]: a convex 2D [`Shape`] (rotated box, cylinder or
//! convex polygon) extruded over a height interval `[z_min, z_max]`. Because every pixel of a
//! depth-image column shares one ground-plane ray, both sensors reduce to 2D ray casts:
//! a *fan* of rays from one origin against one shape at a time ([`query::fan`]), restricted
//! to the rays inside the shape's angular extent ([`query::extent`]). The fan kernels are
//! written as straight loops over structure-of-arrays so the compiler vectorises them.
//!
//! Layout follows parry: one file per shape, one folder per query. Each shape implements
//! its queries in its own local frame; world-frame versions transform the ray.

pub mod aabb;
pub mod distance;
pub mod grid;
pub mod math;
pub mod prism;
pub mod query;
pub mod shape;

pub use aabb::Aabb;
pub use distance::distance_sq;
pub use grid::{Grid, GridScratch};
pub use math::{Pose2, Vec2};
pub use prism::Prism;
pub use query::extent::Extent;
pub use query::fan::{Fan, FanHits, PreparedShape};
pub use shape::{ConvexPolygon, Cuboid, Cylinder, Shape, ShapeError};
