//! Worlds: the data the simulator runs in.
//!
//! A world is a versioned TOML file (see `worlds/example.toml` for the fully commented
//! format): bounds, obstacles (vertical prisms with a height interval), spawn regions,
//! pedestrians and, for navigation, goal regions. [`World::from_toml`] parses and validates
//! one with errors that name the file, the field and the problem; [`builtin`] holds the
//! worlds shipped with mdrlat; [`map_server`] imports a ROS `map_server` floor plan.

pub mod builtin;
mod error;
mod format;
pub mod generate;
pub mod map_server;
mod world;

pub use error::WorldError;
pub use format::FORMAT_VERSION;
pub use generate::{Family, family_toml, generate, generate_family, generate_toml};
pub use world::{Obstacle, PedestrianSpec, World, load, load_set};
