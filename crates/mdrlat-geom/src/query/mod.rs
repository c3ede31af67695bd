//! Queries: angular extents seen from a viewpoint, and ray fans cast against one shape.

pub mod extent;
pub mod fan;
