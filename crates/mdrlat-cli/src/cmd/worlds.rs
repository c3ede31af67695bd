//! `mdrlat worlds` and `mdrlat world check`.

use anyhow::{Context, Result};
use mdrlat_geom::Prism;
use mdrlat_world::World;
use std::path::Path;

fn summary(w: &World) -> String {
    let laser_z = mdrlat_sim::SimConfig::default().laser.height_m;
    let body_z = mdrlat_core::robot::BODY_HEIGHT_M;
    let prisms: Vec<&Prism> = w.obstacles.iter().map(|o| &o.prism).collect();
    let depth_only = prisms
        .iter()
        .filter(|p| p.overlaps_heights(0.0, body_z) && !p.spans_height(laser_z))
        .count();
    let s = w.bounds.size();
    format!(
        "{:>5.1} x {:<5.1} m  {:>4} obstacles ({:>2} depth-only)  {:>2} pedestrians  {:>2} goals",
        s.x,
        s.y,
        w.obstacles.len(),
        depth_only,
        w.pedestrians.len(),
        w.goals.len()
    )
}

/// `mdrlat worlds`.
pub fn list() -> Result<()> {
    for name in mdrlat_world::builtin::NAMES {
        let w = mdrlat_world::builtin::get(name)
            .with_context(|| format!("built-in world {name} is missing"))??;
        out!("{name:<10} {}", summary(&w));
        if !w.description.is_empty() {
            out!("{:<10} {}", "", w.description);
        }
    }
    out!(
        "\nAny command taking --world also accepts gen-N or home-N (a generated world, `mdrlat \
         world generate`), a .toml world file or a ROS map_server .yaml."
    );
    Ok(())
}

/// `mdrlat world check FILE`.
pub fn check(file: &Path) -> Result<()> {
    let spec = file.to_str().with_context(|| format!("{}: path is not UTF-8", file.display()))?;
    if !file.is_file() {
        anyhow::bail!("{}: no such file", file.display());
    }
    let w = mdrlat_world::load(spec)?;
    out!("{}: ok: '{}'  {}", file.display(), w.name, summary(&w));
    Ok(())
}

/// `mdrlat world generate [--family F] --seed N [--out FILE]`.
pub fn generate(family: mdrlat_world::Family, seed: u64, out: Option<&Path>) -> Result<()> {
    let text = mdrlat_world::family_toml(family, seed);
    let w = World::from_toml(&format!("{}{seed}", family.prefix()), &text)?;
    match out {
        Some(path) => {
            super::ensure_parent(path)?;
            std::fs::write(path, &text)
                .with_context(|| format!("cannot write {}", path.display()))?;
            out!("{}: '{}'  {}", path.display(), w.name, summary(&w));
        }
        None => out!("{}", text.trim_end()),
    }
    Ok(())
}
