//! `mdrlat rollout`: episodes with a scripted policy, as CSV (and optionally a GIF).

use super::{ensure_parent, load_world, make_env, parse_pose, px_per_m, snapshot};
use crate::config::Config;
use crate::progress;
use anyhow::{Context, Result};
use mdrlat_core::Action;
use mdrlat_geom::Vec2;
use mdrlat_render::GifWriter;
use mdrlat_sim::rollout::{CSV_HEADER, TrajectoryRow};
use mdrlat_sim::{ConstantPolicy, Env, Policy, RandomPolicy, WanderPolicy};
use std::io::Write;
use std::path::PathBuf;

/// The scripted policies.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum PolicyKind {
    /// Uniformly random actions (seeded).
    Random,
    /// Always straight ahead at 0.5 m/s (action 1).
    Forward,
    /// A reactive wanderer on the laser and the depth camera: heads for the most open way.
    Wander,
    /// The same wanderer with the laser only: blind to low boxes and overhangs.
    WanderLaser,
}

/// Builds a scripted policy for `env`.
pub fn make_policy(kind: PolicyKind, env: &Env, seed: u64) -> Box<dyn Policy> {
    match kind {
        PolicyKind::Random => Box::new(RandomPolicy::new(seed)),
        PolicyKind::Forward => {
            Box::new(ConstantPolicy(Action::new(1).unwrap_or_else(|| unreachable!())))
        }
        PolicyKind::Wander => Box::new(WanderPolicy::with_depth(
            env.laser().angles(),
            env.depth_camera().geometry(),
            env.config().robot.body_height_m,
        )),
        PolicyKind::WanderLaser => Box::new(WanderPolicy::new(env.laser().angles())),
    }
}

/// Arguments of `mdrlat rollout`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// World: a built-in name, a .toml world file or a map_server .yaml.
    #[arg(long, default_value = "train")]
    world: String,
    /// Seed of the episode (start pose, pedestrians, noise, random policy).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Most steps per episode; an episode ends earlier on a collision or at the time limit.
    #[arg(long, default_value_t = 500)]
    steps: u32,
    /// Consecutive episodes (the random streams continue from one to the next).
    #[arg(long, default_value_t = 1)]
    episodes: u32,
    /// Who drives.
    #[arg(long, value_enum, default_value = "random")]
    policy: PolicyKind,
    /// Start pose X,Y,YAW_DEG of the first episode (default: a seeded random free pose).
    #[arg(long, allow_hyphen_values = true)]
    pose: Option<String>,
    /// Trajectory CSV: step,x,y,yaw,v,w,action,reward,terminated,truncated,d_min.
    #[arg(long, default_value = "out/rollout.csv")]
    out: PathBuf,
    /// Also write an animation of the episodes (top view, rays, depth image) here.
    #[arg(long)]
    gif: Option<PathBuf>,
    /// Configuration file (see `mdrlat config default`).
    #[arg(long)]
    config: Option<PathBuf>,
}

/// Runs `mdrlat rollout`.
pub fn run(a: &Args) -> Result<()> {
    let config = Config::load_or_default(a.config.as_deref())?;
    let world = load_world(&a.world)?;
    let mut env = make_env(world, &config.sim)?;
    let mut policy = make_policy(a.policy, &env, a.seed);
    ensure_parent(&a.out)?;
    let mut csv = std::io::BufWriter::new(
        std::fs::File::create(&a.out)
            .with_context(|| format!("cannot create {}", a.out.display()))?,
    );
    writeln!(csv, "{CSV_HEADER}")?;
    let scale = px_per_m(env.world(), 480.0);
    let mut gif: Option<GifWriter<_>> = None;
    let pb = progress::bar(u64::from(a.steps) * u64::from(a.episodes), "rollout");
    let (mut total_steps, mut collisions, mut total_reward) = (0u64, 0u32, 0.0f64);
    for episode in 0..a.episodes {
        let pose = if episode == 0 { a.pose.as_deref().map(parse_pose).transpose()? } else { None };
        env.reset_with(if episode == 0 { Some(a.seed) } else { None }, pose)?;
        let mut trail: Vec<Vec2> = vec![env.pose().position()];
        let mut ep_reward = 0.0f32;
        for _ in 0..a.steps {
            let action = policy.act(env.observation());
            let s = env.step(action)?;
            let row = TrajectoryRow {
                action,
                reward: s.reward,
                terminated: s.terminated,
                truncated: s.truncated,
                info: s.info,
            };
            writeln!(csv, "{}", row.to_csv())?;
            ep_reward += row.reward;
            trail.push(row.info.pose.position());
            if let Some(path) = &a.gif {
                let caption = format!(
                    "{}  ep {}  step {}  v {:.2} w {:+.2}  r {:+.2}  sum {:+.1}",
                    env.world().name,
                    episode,
                    row.info.step,
                    row.info.velocity.v,
                    row.info.velocity.w,
                    row.reward,
                    ep_reward
                );
                let frame = snapshot(&env, &trail, &caption, row.terminated, scale);
                if gif.is_none() {
                    ensure_parent(path)?;
                    gif = Some(GifWriter::create(path, frame.width, frame.height, 20)?);
                }
                if let Some(g) = gif.as_mut() {
                    g.add_frame(&frame)?;
                }
            }
            pb.inc(1);
            total_steps += 1;
            if row.terminated || row.truncated {
                collisions += u32::from(row.terminated);
                break;
            }
        }
        total_reward += f64::from(ep_reward);
    }
    pb.finish_and_clear();
    csv.flush()?;
    if let Some(g) = gif {
        g.finish()?;
    }
    out!(
        "{} episode(s), {} steps, {} collision(s), mean episode reward {:.2}; wrote {}{}",
        a.episodes,
        total_steps,
        collisions,
        total_reward / f64::from(a.episodes.max(1)),
        a.out.display(),
        a.gif.as_ref().map(|g| format!(" and {}", g.display())).unwrap_or_default()
    );
    Ok(())
}
