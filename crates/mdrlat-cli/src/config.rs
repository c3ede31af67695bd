//! The configuration tree lives in the library ([`mdrlat_train::settings`]); here is
//! `mdrlat config check`.

use anyhow::{Context, Result};
pub use mdrlat_train::settings::{Config, DEFAULT_TOML};
use std::path::Path;

/// `mdrlat config check FILE`.
pub fn check(path: &Path) -> Result<()> {
    let config = Config::load(path)?;
    out!("{}", toml::to_string(&config).context("serialising the config")?.trim_end());
    eprintln!("{}: ok", path.display());
    Ok(())
}
