//! One module per subcommand, plus the glue they share.

pub mod bench;
pub mod bench_ros;
pub mod bench_train;
pub mod demo;
pub mod diagnose;
pub mod eval;
pub mod export;
pub mod observe;
pub mod plot;
pub mod render;
pub mod reproduce;
pub mod rollout;
pub mod ros;
pub mod ros2;
pub mod train;
pub mod worlds;

use anyhow::{Context, Result, bail};
pub use mdrlat_eval::figures::{px_per_m, snapshot};
use mdrlat_geom::Pose2;
use mdrlat_plan::{MapSource, PlannerOptions, PlannerPolicy};
use mdrlat_sim::Scripted;
use mdrlat_sim::config::Task;
use mdrlat_sim::{Env, SimConfig};
use mdrlat_world::World;
use std::path::Path;

/// Loads a world by built-in name, `.toml` path or map_server `.yaml` path.
pub fn load_world(spec: &str) -> Result<World> {
    Ok(mdrlat_world::load(spec)?)
}

/// An environment over `world` with `config`.
pub fn make_env(world: World, config: &SimConfig) -> Result<Env> {
    Ok(Env::from_world(world, config.clone())?)
}

/// Parses `n` comma-separated finite numbers given to `flag` (`expected` names them).
pub fn parse_numbers(flag: &str, s: &str, n: usize, expected: &str) -> Result<Vec<f32>> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != n {
        bail!("{flag} '{s}': expected {expected} ({n} comma-separated numbers)");
    }
    parts
        .iter()
        .map(|p| {
            p.parse::<f32>()
                .ok()
                .filter(|x| x.is_finite())
                .with_context(|| format!("{flag} '{s}': '{p}' is not a finite number"))
        })
        .collect()
}

/// Parses `X,Y,YAW_DEG` (metres, metres, degrees).
pub fn parse_pose(s: &str) -> Result<Pose2> {
    let v = parse_numbers("--pose", s, 3, "X,Y,YAW_DEG")?;
    Ok(Pose2::new(v[0], v[1], v[2].to_radians()))
}

/// `--policy`: a scripted baseline or the classical planner.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PolicyArg {
    /// A scripted policy of the simulator.
    Scripted(Scripted),
    /// The classical planner (A* + DWA) with this map.
    Planner(MapSource),
}

pub fn parse_policy(s: &str) -> Result<PolicyArg, String> {
    if let Some(map) = MapSource::from_policy_name(s) {
        return Ok(PolicyArg::Planner(map));
    }
    s.parse::<Scripted>()
        .map(PolicyArg::Scripted)
        .map_err(|e| format!("{e}; navigation: {}", MapSource::POLICY_NAMES.join(", ")))
}

/// The classical planner for `world`, driving a robot with `sim`'s body and sensors.
///
/// # Errors
/// A map that cannot be built.
pub fn planner(
    world: &World,
    sim: &SimConfig,
    map: MapSource,
) -> Result<Box<dyn mdrlat_core::Policy>> {
    let options = PlannerOptions { map, ..PlannerOptions::default() };
    let p = PlannerPolicy::new(world, sim, &options).map_err(anyhow::Error::msg)?;
    Ok(Box::new(p))
}

/// The task flags of the commands that run episodes.
#[derive(Debug, Clone, clap::Args)]
pub struct TaskArgs {
    /// The task: `avoid` (the paper's obstacle avoidance; the default) or `nav` (reach a
    /// goal in the world's goal regions: the paper's navigation extension).
    #[arg(long, value_parser = parse_task)]
    pub task: Option<Task>,
    /// Navigation: start every episode here instead of a drawn start.
    #[arg(long, value_name = "X,Y,YAW_DEG")]
    pub start: Option<String>,
    /// Navigation: this goal for every episode instead of a drawn one.
    #[arg(long, value_name = "X,Y")]
    pub goal: Option<String>,
}

fn parse_task(s: &str) -> Result<Task, String> {
    s.parse()
}

impl TaskArgs {
    /// Applies the flags to `sim` (a config file's `task` stays unless `--task` is given).
    ///
    /// # Errors
    /// `--start`/`--goal` without the navigation task, or not numbers.
    pub fn apply(&self, sim: &mut SimConfig) -> Result<()> {
        if let Some(t) = self.task {
            sim.task = t;
        }
        if (self.start.is_some() || self.goal.is_some()) && sim.task != Task::Nav {
            bail!("--start and --goal fix a navigation episode: add --task nav");
        }
        if let Some(s) = &self.start {
            let v = parse_numbers("--start", s, 3, "X,Y,YAW_DEG")?;
            sim.nav.start = Some([v[0], v[1], v[2]]);
        }
        if let Some(g) = &self.goal {
            let v = parse_numbers("--goal", g, 2, "X,Y")?;
            sim.nav.goal = Some([v[0], v[1]]);
        }
        Ok(())
    }
}

/// Creates `dir` (and parents) with a clear error.
pub fn ensure_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create directory {}", dir.display()))
}

/// Creates the parent directory of `file`, if any.
pub fn ensure_parent(file: &Path) -> Result<()> {
    match file.parent() {
        Some(p) if !p.as_os_str().is_empty() => ensure_dir(p),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poses_parse_or_explain() {
        let p = parse_pose("1.5, 2, 90").expect("pose");
        assert_eq!((p.x, p.y), (1.5, 2.0));
        assert!((p.yaw - std::f32::consts::FRAC_PI_2).abs() < 1e-6);
        assert!(parse_pose("1,2").is_err());
        assert!(parse_pose("1,2,nan").expect_err("nan").to_string().contains("nan"));
        assert!(parse_pose("a,2,3").is_err());
    }
}
