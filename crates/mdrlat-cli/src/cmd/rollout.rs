//! `mdrlat rollout`: episodes with a scripted policy, as CSV (and optionally a GIF), run
//! through the one episode runner.

use super::{ensure_parent, load_world, parse_pose, px_per_m, snapshot};
use crate::config::Config;
use crate::progress;
use anyhow::{Context, Result};
use indicatif::ProgressBar;
use mdrlat_geom::Vec2;
use mdrlat_render::{GifWriter, Image};
use mdrlat_sim::rollout::{CSV_HEADER, TrajectoryRow};
use mdrlat_sim::{
    Env, EpisodeOutcome, EpisodeSpec, Observer, RunOptions, Scripted, SimConfig, StaticScene,
    VecEnv, run_episodes,
};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Parses a scripted policy's name (`--policy`).
pub fn parse_scripted(s: &str) -> Result<Scripted, String> {
    s.parse()
}

/// One environment for episodes run one after another (`rollout`, `demo`).
pub fn single_env(world: mdrlat_world::World, sim: &SimConfig) -> Result<VecEnv> {
    let scene = Arc::new(StaticScene::new(Arc::new(world), sim));
    Ok(VecEnv::new(scene, sim.clone(), 1, 1)?)
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
    /// Who drives: random, forward, wander, wander-laser, spin, circle, avoid, avoid-laser,
    /// avoid-stack or avoid-memory-N; with `--task nav` also planner or planner-body (A* +
    /// DWA, see `mdrlat eval`).
    #[arg(long, default_value = "random", value_parser = super::parse_policy)]
    policy: super::PolicyArg,
    /// The task, and a fixed start and goal for navigation.
    #[command(flatten)]
    task: super::TaskArgs,
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

/// Writes episodes as CSV rows and, optionally, GIF frames, as an episode-runner
/// [`Observer`]: shared by `rollout` and `demo`.
pub struct Recorder {
    csv: std::io::BufWriter<std::fs::File>,
    gif: Option<(PathBuf, Option<GifWriter<std::io::BufWriter<std::fs::File>>>)>,
    scale: f32,
    /// The last frame drawn (with a GIF).
    pub last_frame: Option<Image>,
    trail: Vec<Vec2>,
    sum: f32,
    /// Captions name the episode.
    label_episodes: bool,
    bar: Option<ProgressBar>,
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
        Ok(Self {
            csv,
            gif: gif.map(|g| (g.to_path_buf(), None)),
            scale,
            last_frame: None,
            trail: Vec::new(),
            sum: 0.0,
            label_episodes: false,
            bar: None,
        })
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

    /// Runs `specs` with `policy` in the single environment of `venv`, recording every
    /// step; the bar (if any) advances once per step.
    pub fn run(
        &mut self,
        venv: &mut VecEnv,
        policy: &mut dyn mdrlat_sim::Policy,
        specs: &[EpisodeSpec],
        steps: u32,
        bar: Option<ProgressBar>,
    ) -> Result<Vec<EpisodeOutcome>> {
        self.label_episodes = specs.len() > 1;
        self.bar = bar;
        let options = RunOptions { max_steps: steps, record_rows: true };
        let outcomes = run_episodes(venv, policy, specs, &options, self)?;
        if let Some(bar) = self.bar.take() {
            bar.finish_and_clear();
        }
        Ok(outcomes)
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

impl Observer for Recorder {
    fn wants_steps(&self) -> bool {
        true
    }

    fn on_step(
        &mut self,
        episode: usize,
        env: &Env,
        row: &TrajectoryRow,
    ) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
        writeln!(self.csv, "{}", row.to_csv())?;
        self.sum += row.reward;
        self.trail.push(row.info.pose.position());
        let i = &row.info;
        let label = if self.label_episodes { format!("ep {episode}  ") } else { String::new() };
        let caption = format!(
            "{}  {label}step {}  v {:.2} w {:+.2}  r {:+.2}  sum {:+.1}",
            env.world().name,
            i.step,
            i.velocity.v,
            i.velocity.w,
            row.reward,
            self.sum
        );
        let trail = std::mem::take(&mut self.trail);
        let drawn = self.frame(env, &trail, &caption, row.terminated);
        self.trail = trail;
        drawn?;
        if let Some(bar) = &self.bar {
            bar.inc(1);
        }
        Ok(())
    }

    fn on_episode(&mut self, _episode: usize, _outcome: &EpisodeOutcome) {
        self.trail.clear();
        self.sum = 0.0;
    }
}

/// Runs `mdrlat rollout`.
pub fn run(a: &Args) -> Result<()> {
    let mut config = Config::load_or_default(a.config.as_deref())?;
    a.task.apply(&mut config.sim)?;
    config.sim.validate()?;
    let world = load_world(&a.world)?;
    let scale = px_per_m(&world, 480.0);
    let mut policy = match a.policy {
        super::PolicyArg::Scripted(s) => s.build(&config.sim, a.seed),
        super::PolicyArg::Planner(_) if config.sim.task != mdrlat_sim::config::Task::Nav => {
            anyhow::bail!("--policy planner drives to a goal: add --task nav")
        }
        super::PolicyArg::Planner(map) => super::planner(&world, &config.sim, map)?,
    };
    let mut venv = single_env(world, &config.sim)?;
    let mut rec = Recorder::create(&a.out, a.gif.as_deref(), scale)?;
    let first =
        EpisodeSpec { seed: Some(a.seed), pose: a.pose.as_deref().map(parse_pose).transpose()? };
    let specs: Vec<EpisodeSpec> =
        (0..a.episodes).map(|k| if k == 0 { first } else { EpisodeSpec::default() }).collect();
    let pb = progress::bar(u64::from(a.steps) * u64::from(a.episodes), "rollout");
    let outcomes = rec.run(&mut venv, policy.as_mut(), &specs, a.steps, Some(pb))?;
    rec.finish()?;
    let total_steps: u64 = outcomes.iter().map(|o| u64::from(o.steps)).sum();
    let collisions = outcomes.iter().filter(|o| o.collision.is_some()).count();
    let total_reward: f64 = outcomes.iter().map(|o| f64::from(o.reward)).sum();
    let goals = if outcomes.iter().any(|o| o.goal.is_some()) {
        format!(", {} goal(s) reached", outcomes.iter().filter(|o| o.reached_goal).count())
    } else {
        String::new()
    };
    out!(
        "{} episode(s), {} steps, {} collision(s){goals}, mean episode reward {:.2}; wrote {}{}",
        a.episodes,
        total_steps,
        collisions,
        total_reward / f64::from(a.episodes.max(1)),
        a.out.display(),
        a.gif.as_ref().map(|g| format!(" and {}", g.display())).unwrap_or_default()
    );
    Ok(())
}
