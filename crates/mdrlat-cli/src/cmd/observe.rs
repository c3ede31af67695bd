//! `mdrlat observe`: both sensors at a chosen pose, as NumPy arrays and a picture.

use super::{ensure_dir, load_world, make_env, parse_pose, px_per_m, snapshot};
use crate::config::Config;
use anyhow::{Context, Result};
use mdrlat_core::{DEPTH_COLS, DEPTH_ROWS, LASER_BEAMS, npy};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// Arguments of `mdrlat observe`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// World: a built-in name (see `mdrlat worlds`), a .toml world file or a map_server .yaml.
    #[arg(long, default_value = "train")]
    world: String,
    /// Robot pose as X,Y,YAW_DEG (metres, metres, degrees counter-clockwise from +x).
    #[arg(long, allow_hyphen_values = true)]
    pose: String,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/observe")]
    out: PathBuf,
    /// Seed for pedestrian positions and sensor noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Configuration file (see `mdrlat config default`).
    #[arg(long)]
    config: Option<PathBuf>,
}

fn write_npy(path: &Path, shape: &[usize], data: &[f32]) -> Result<()> {
    let f = File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    npy::write_f32(BufWriter::new(f), shape, data)
        .with_context(|| format!("writing {}", path.display()))
}

/// Runs `mdrlat observe`.
pub fn run(a: &Args) -> Result<()> {
    let config = Config::load_or_default(a.config.as_deref())?;
    let pose = parse_pose(&a.pose)?;
    let world = load_world(&a.world)?;
    let mut env = make_env(world, &config.sim)?;
    env.reset_with(Some(a.seed), Some(pose))?;
    if !env.world().is_free(pose.position(), config.sim.robot.radius_m) {
        eprintln!("note: the robot at this pose overlaps an obstacle (it would be in collision)");
    }
    ensure_dir(&a.out)?;
    let obs = env.observation();
    write_npy(&a.out.join("laser.npy"), &[LASER_BEAMS], obs.laser.latest())?;
    write_npy(&a.out.join("depth.npy"), &[DEPTH_ROWS, DEPTH_COLS], obs.depth.latest())?;
    // The collision rule reads the laser's own scan; with the camera's memory on, the
    // scan written and drawn can be nearer.
    let scan_min = obs.laser.latest().iter().copied().fold(f32::INFINITY, f32::min);
    let d_min = env.laser_d_min();
    let memory = if scan_min < d_min {
        format!(" (scan with the camera's memory {scan_min:.2} m)")
    } else {
        String::new()
    };
    let caption = format!(
        "{}  pose {:.2},{:.2},{:.0}deg  d_min {d_min:.2} m{memory}",
        env.world().name,
        pose.x,
        pose.y,
        pose.yaw.to_degrees(),
    );
    let picture = snapshot(&env, &[], &caption, false, px_per_m(env.world(), 640.0));
    picture.save_png(&a.out.join("view.png"))?;
    out!(
        "wrote {0}/laser.npy (512 f32, metres), {0}/depth.npy (128x160 f32, metres, 0 = no reading), {0}/view.png",
        a.out.display()
    );
    out!("load in Python: numpy.load('{}/depth.npy')", a.out.display());
    Ok(())
}
