//! Pictures of mdrlat worlds and sensors, for people to look at before they trust the
//! simulator.
//!
//! This crate draws plain data and never depends on the simulator: a [`Scene`] borrows a
//! [`World`](mdrlat_world::World) plus whatever the caller wants marked (robot pose, laser
//! ranges, pedestrians, trail, goal, a caption). [`top_view`] draws it from above with
//! obstacles shaded by their height interval and a legend; [`depth_view`] false-colours a
//! depth image with a metre colour bar; [`side_by_side`] composes pictures; an [`Image`]
//! saves as PNG and a [`GifWriter`] turns frames into an animation.
//!
//! Everything is deterministic: the same input gives the same pixels and the same file
//! bytes (shapes are anti-aliased by tiny-skia, text comes from the built-in bitmap
//! [`font`], GIF colours from a fixed palette).

mod animation;
mod chart;
mod depth;
mod error;
pub mod font;
mod image;
mod style;
mod top;

pub use animation::{GifWriter, PALETTE_LEN};
pub use chart::{Chart, Series, line_chart, series_colour};
pub use depth::{depth_colour, depth_view};
pub use error::RenderError;
pub use image::{Image, side_by_side, stacked, titled};
pub use style::{HeightClass, LASER_PLANE_M};
pub use top::{LaserRays, MapFrame, RobotMark, Scene, map_frame, top_view, world_picture};
