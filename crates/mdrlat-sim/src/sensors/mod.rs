//! The robot's two sensors, both at the robot's centre: a 2D laser and a depth camera.
//!
//! Both are fans of 2D rays cast per obstacle over the obstacle's angular extent (see
//! `mdrlat_geom::query`), so the cost of a frame grows with what is visible. The depth
//! camera turns each column's ground-plane hit interval into per-row hits with a short,
//! vectorised loop over the 128 rows (SPEC §2: 160 casts, not 20,480).

mod depth;
mod laser;

pub use depth::{DepthCamera, DepthGeometry};
pub use laser::Laser;
// The scan with the camera's memory is drawn by the robot's node too: it lives in core.
pub use mdrlat_core::{LASER_SEEN_SLACK_M, MAX_MEMORY_FRAMES, ScanMemory};
