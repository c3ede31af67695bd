//! The configuration tree: one TOML file with a section per room, defaults for every key.

use anyhow::{Context, Result};
use mdrlat_sim::SimConfig;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The commented default configuration, embedded from `configs/default.toml`.
pub const DEFAULT_TOML: &str = include_str!("../../../configs/default.toml");

/// Every setting of mdrlat.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    /// The simulator.
    pub sim: SimConfig,
}

impl Config {
    /// Reads a config file (missing keys keep their defaults) and validates it.
    pub fn load(path: &Path) -> Result<Config> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read config {}", path.display()))?;
        let config: Config = toml::from_str(&text)
            .map_err(|e| anyhow::anyhow!("{}: {}", path.display(), e.to_string().trim_end()))?;
        config.sim.validate().with_context(|| path.display().to_string())?;
        Ok(config)
    }

    /// The default config, or the one in `path` when given.
    pub fn load_or_default(path: Option<&Path>) -> Result<Config> {
        path.map_or_else(|| Ok(Config::default()), Config::load)
    }
}

/// `mdrlat config check FILE`.
pub fn check(path: &Path) -> Result<()> {
    let config = Config::load(path)?;
    out!("{}", toml::to_string(&config).context("serialising the config")?.trim_end());
    eprintln!("{}: ok", path.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_commented_default_file_is_the_default() {
        let parsed: Config = toml::from_str(DEFAULT_TOML).expect("default.toml parses");
        assert_eq!(parsed, Config::default(), "configs/default.toml drifted from the code");
    }

    #[test]
    fn unknown_keys_and_bad_values_are_errors() {
        assert!(toml::from_str::<Config>("[sim]\nbogus = 1\n").is_err());
        assert!(toml::from_str::<Config>("[sim.laser]\nmax_range = 3.0\n").is_err());
        let c: Config = toml::from_str("[sim.laser]\nmax_range_m = -1.0\n").expect("parses");
        let e = c.sim.validate().expect_err("negative range").to_string();
        assert!(e.contains("laser.max_range_m") && e.contains("-1"), "{e}");
    }
}
