//! Import of ROS `map_server` maps (being written).

use crate::{World, WorldError};
use std::path::Path;

/// Options of the map import.
#[derive(Debug, Clone, Default)]
pub struct ImportOptions {}

/// Imports a map_server YAML + image as a world.
///
/// # Errors
/// Always, for now.
pub fn import(path: &Path, _opts: &ImportOptions) -> Result<World, WorldError> {
    Err(WorldError::Parse {
        source_name: path.display().to_string(),
        message: "map import is being written".into(),
    })
}
