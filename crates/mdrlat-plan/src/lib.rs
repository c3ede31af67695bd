//! The classical navigation baseline: what ROS's `move_base` does in the paper's Figure 9,
//! rebuilt on the simulator's worlds.
//!
//! - [`OccupancyGrid`]: a world rasterised at a few centimetres a cell — by default what a
//!   2D-laser SLAM map of it would hold (the obstacles that cross the laser plane), or
//!   everything the robot's body can hit ([`MapKind`]).
//! - [`CostMap`]: the grid inflated by the robot's radius (the exact Euclidean
//!   distance transform the map import uses), with navfn-style costs that fall off away from obstacles.
//! - [`astar`]: the global plan, A* over the cost map, 8-connected, no corner cutting;
//!   optimal on the grid (tested against Dijkstra) and deterministic.
//! - [`Dwa`]: the local planner in the style of move_base's DWA: sample the velocities
//!   reachable within the acceleration limits, roll each out over a short horizon, drop
//!   those that would hit a point of the current laser scan, score the rest on following
//!   the plan, heading to it, clearance and speed.
//!
//! - [`PlannerPolicy`]: both as a [`mdrlat_core::Policy`] (`--policy planner`): the global
//!   plan at the start of each episode (and when the robot strays from it), the local planner
//!   every step, continuous velocity commands.
//!
//! Nothing here is random: the same inputs give the same plan and the same commands.

mod astar;
mod dwa;
mod grid;
mod policy;

pub use astar::{Path, PlanError, astar};
pub use dwa::{Dwa, DwaConfig, Limits};
pub use grid::{Cell, CostMap, MapKind, OccupancyGrid};
pub use policy::{MapSource, PlannerOptions, PlannerPolicy};
