//! `mdrlat rollout`: episodes with a scripted policy, as CSV (and optionally a GIF).

use super::{ensure_parent, load_world, make_env, parse_pose, px_per_m, snapshot};
use crate::config::Config;
use crate::progress;
use anyhow::{Context, Result};
use mdrlat_core::Action;
use mdrlat_geom::{Pose2, Vec2};
use mdrlat_render::{GifWriter, Image};
use mdrlat_sim::rollout::{CSV_HEADER, TrajectoryRow, run_episode};
use mdrlat_sim::{ConstantPolicy, Env, Policy, RandomPolicy, WanderPolicy};
use std::io::Write;
use std::path::{Path, PathBuf};

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

/// Writes episodes as CSV rows and, optionally, GIF frames: shared by `rollout` and `demo`.
pub struct Recorder {
    csv: std::io::BufWriter<std::fs::File>,
    gif: Option<(PathBuf, Option<GifWriter<std::io::BufWriter<std::fs::File>>>)>,
    scale: f32,
    /// The last frame drawn (with a GIF).
    pub last_frame: Option<Image>,
}

impl Recorder {
    /// Creates the CSV (with its header) and remembers where a GIF goes, if anywhere.
    pub fn create(csv: &Path, gif: Option<&Path>, scale: f32) -> Result<Self> {
        ensure_parent(csv)?;
        let file = std::fs::File::create(csv)
            .with_context(|| format!("cannot create {}", csv.display()))?;
        let mut csv = std::io::BufWriter::new(file);
        writeln!(csv, "{CSV_HEADER}")?;
        if let Some(g) = gif {
            ensure_parent(g)?;
        }
        Ok(Self { csv, gif: gif.map(|g| (g.to_path_buf(), None)), scale, last_frame: None })
    }

    /// Adds a frame of the environment's current state to the GIF (if any).
    pub fn frame(
        &mut self,
        env: &Env,
        trail: &[Vec2],
        caption: &str,
        collided: bool,
    ) -> Result<()> {
        let Some((path, writer)) = self.gif.as_mut() else { return Ok(()) };
        let frame = snapshot(env, trail, caption, collided, self.scale);
        if writer.is_none() {
            *writer = Some(GifWriter::create(path, frame.width, frame.height, 20)?);
        }
        if let Some(w) = writer.as_mut() {
            w.add_frame(&frame)?;
        }
        self.last_frame = Some(frame);
        Ok(())
    }

    /// Runs one episode of `policy`, recording every step; `tick` is called once per step.
    pub fn episode(
        &mut self,
        env: &mut Env,
        policy: &mut dyn Policy,
        (seed, pose): (Option<u64>, Option<Pose2>),
        steps: u32,
        label: &str,
        mut tick: impl FnMut(),
    ) -> Result<Vec<TrajectoryRow>> {
        let mut trail: Vec<Vec2> = Vec::new();
        let mut sum = 0.0f32;
        run_episode(env, policy, seed, pose, steps, |env, row| -> Result<()> {
            writeln!(self.csv, "{}", row.to_csv())?;
            sum += row.reward;
            trail.push(row.info.pose.position());
            let i = &row.info;
            let caption = format!(
                "{}  {label}step {}  v {:.2} w {:+.2}  r {:+.2}  sum {:+.1}",
                env.world().name,
                i.step,
                i.velocity.v,
                i.velocity.w,
                row.reward,
                sum
            );
            self.frame(env, &trail, &caption, row.terminated)?;
            tick();
            Ok(())
        })
    }

    /// Flushes the CSV and closes the GIF.
    pub fn finish(mut self) -> Result<()> {
        self.csv.flush()?;
        if let Some((_, Some(w))) = self.gif.take() {
            w.finish()?;
        }
        Ok(())
    }
}

/// Runs `mdrlat rollout`.
pub fn run(a: &Args) -> Result<()> {
    let config = Config::load_or_default(a.config.as_deref())?;
    let world = load_world(&a.world)?;
    let mut env = make_env(world, &config.sim)?;
    let mut policy = make_policy(a.policy, &env, a.seed);
    let scale = px_per_m(env.world(), 480.0);
    let mut rec = Recorder::create(&a.out, a.gif.as_deref(), scale)?;
    let pb = progress::bar(u64::from(a.steps) * u64::from(a.episodes), "rollout");
    let (mut total_steps, mut collisions, mut total_reward) = (0usize, 0u32, 0.0f64);
    for episode in 0..a.episodes {
        let start = if episode == 0 {
            (Some(a.seed), a.pose.as_deref().map(parse_pose).transpose()?)
        } else {
            (None, None)
        };
        let rows = rec.episode(
            &mut env,
            policy.as_mut(),
            start,
            a.steps,
            &format!("ep {episode}  "),
            || pb.inc(1),
        )?;
        total_steps += rows.len();
        collisions += u32::from(rows.last().is_some_and(|r| r.terminated));
        total_reward += rows.iter().map(|r| f64::from(r.reward)).sum::<f64>();
    }
    pb.finish_and_clear();
    rec.finish()?;
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
