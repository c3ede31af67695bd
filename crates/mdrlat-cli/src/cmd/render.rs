//! `mdrlat render`: a world from above, optionally with the robot and its sensors.

use super::{ensure_parent, load_world, make_env, parse_pose, px_per_m, snapshot};
use crate::config::Config;
use anyhow::Result;
use std::path::PathBuf;

/// Arguments of `mdrlat render`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// World: a built-in name, a .toml world file or a map_server .yaml.
    #[arg(long, default_value = "train")]
    world: String,
    /// Robot pose X,Y,YAW_DEG; without it a seeded random start pose is used.
    #[arg(long, allow_hyphen_values = true)]
    pose: Option<String>,
    /// Draw the world alone: no robot, rays or depth image.
    #[arg(long, conflicts_with = "pose")]
    world_only: bool,
    /// Seed for the start pose, pedestrians and noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output PNG.
    #[arg(long, default_value = "out/render.png")]
    out: PathBuf,
    /// Pixels per metre (default: about 640 pixels on the long side).
    #[arg(long)]
    scale: Option<f32>,
    /// Configuration file (see `mdrlat config default`).
    #[arg(long)]
    config: Option<PathBuf>,
}

/// Runs `mdrlat render`.
pub fn run(a: &Args) -> Result<()> {
    let config = Config::load_or_default(a.config.as_deref())?;
    let world = load_world(&a.world)?;
    let scale = a.scale.unwrap_or_else(|| px_per_m(&world, 640.0));
    ensure_parent(&a.out)?;
    let picture = if a.world_only {
        mdrlat_render::world_picture(&world, scale)
    } else {
        let mut env = make_env(world, &config.sim)?;
        let pose = a.pose.as_deref().map(parse_pose).transpose()?;
        env.reset_with(Some(a.seed), pose)?;
        let p = env.pose();
        let caption = format!(
            "{}  pose {:.2},{:.2},{:.0}deg  seed {}",
            env.world().name,
            p.x,
            p.y,
            p.yaw.to_degrees(),
            a.seed
        );
        snapshot(&env, &[], &caption, false, scale)
    };
    picture.save_png(&a.out)?;
    out!("wrote {} ({}x{})", a.out.display(), picture.width, picture.height);
    Ok(())
}
