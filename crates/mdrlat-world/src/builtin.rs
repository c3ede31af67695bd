//! The worlds shipped with mdrlat (`worlds/*.toml` in the repository, embedded at build time).

use crate::{World, WorldError};

/// Built-in world names, in the order `mdrlat worlds` lists them.
pub const NAMES: [&str; 7] =
    ["train", "office", "furnished", "crowd", "nav-train", "nav-test", "example"];

/// The TOML text of a built-in world.
pub fn text(name: &str) -> Option<&'static str> {
    Some(match name {
        "train" => include_str!("../../../worlds/train.toml"),
        "office" => include_str!("../../../worlds/office.toml"),
        "furnished" => include_str!("../../../worlds/furnished.toml"),
        "crowd" => include_str!("../../../worlds/crowd.toml"),
        "nav-train" => include_str!("../../../worlds/nav-train.toml"),
        "nav-test" => include_str!("../../../worlds/nav-test.toml"),
        "example" => include_str!("../../../worlds/example.toml"),
        _ => return None,
    })
}

/// Parses a built-in world; `None` if `name` is not built in.
pub fn get(name: &str) -> Option<Result<World, WorldError>> {
    text(name).map(|t| World::from_toml(&format!("built-in world '{name}'"), t))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_builtin_world_loads() {
        for name in NAMES {
            let w = get(name).expect("listed").unwrap_or_else(|e| panic!("{e}"));
            assert!(!w.obstacles.is_empty(), "{name} has no obstacles");
        }
    }
}
