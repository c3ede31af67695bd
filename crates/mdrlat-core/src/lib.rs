//! Shared vocabulary of mdrlat.
//!
//! Everything here is used by both the simulator and the real robot, so it is the single
//! source of truth for sim-to-real: the action table (paper Table 1), the observation
//! layout, the normalisation of SPEC §2, and the seeded random number generator.
//! No heavy dependencies: this crate builds quickly.

pub mod action;
pub mod npy;
pub mod obs;
pub mod policy;
pub mod rng;
pub mod scan_memory;
pub mod variant;

pub use action::{Action, TABLE_1, Velocity};
pub use obs::{
    DEPTH_COLS, DEPTH_HEIGHT_M, DEPTH_HFOV_DEG, DEPTH_LEN, DEPTH_MIN_RANGE_M, DEPTH_ROWS,
    DEPTH_VFOV_DEG, FRAME_STACK, FrameStack, GOAL_DIM, GOAL_NORM_M, LASER_BEAMS, LASER_FOV_DEG,
    LASER_MAX_RANGE_M, ODOM_HISTORY, Observation, goal_in_robot_frame, laser_beam_angle,
    normalize_depth, normalize_goal, normalize_laser,
};
pub use policy::{
    Decision, Policy, PolicyError, Sensors, catch_panic, check_batch, decide_each, decide_one,
    greedy_actions,
};
pub use rng::Rng;
pub use scan_memory::{DepthGeometry, LASER_SEEN_SLACK_M, MAX_MEMORY_FRAMES, ScanMemory};
pub use variant::{Variant, VariantParseError};

/// Robot constants shared by the simulator and the world checks (turtlebot2 / Kobuki).
pub mod robot {
    /// Footprint radius, metres.
    pub const RADIUS_M: f32 = 0.177;
    /// Body height, metres: obstacles whose height interval overlaps `[0, BODY_HEIGHT_M]`
    /// can hit the bumper.
    pub const BODY_HEIGHT_M: f32 = 0.45;
    /// Default extra clearance between the footprint and any obstacle at a reset pose,
    /// metres. World validation checks every spawn region has room for
    /// `RADIUS_M + SPAWN_CLEARANCE_M`, the same test `reset` applies.
    pub const SPAWN_CLEARANCE_M: f32 = 0.1;
}
