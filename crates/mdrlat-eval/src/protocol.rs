//! The success-rate protocol of the paper (section 3.1, SPEC §5): an episode succeeds if no
//! collision happens within 300 steps; a run is 50 episodes from seeded start poses; each
//! (method, world) pair is run 5 times and reported as mean ± std over the runs.
//!
//! Start poses come from the seed alone: episode `e` of run `r` in world `w` is reset with
//! [`episode_seed`]`(seed, w, r, e)`, so every method evaluated with the same seed faces
//! exactly the same starts, pedestrians and sensor noise (a paired comparison), and a
//! world's starts do not depend on which other worlds, how many episodes or how many
//! environments the evaluation has.

use crate::EvalError;
use mdrlat_core::{Action, Decision, Observation, Policy, PolicyError, Rng, Sensors, Velocity};
use mdrlat_geom::Pose2;
use mdrlat_sim::{
    Collision, EpisodeOutcome, EpisodeSpec, MovingRule, Observer, RunOptions, SimConfig,
    StaticScene, VecEnv, run_episodes,
};
use mdrlat_world::World;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// How an evaluation runs (`mdrlat eval` flags; defaults are the paper's protocol).
#[derive(Debug, Clone, PartialEq)]
pub struct EvalSettings {
    /// Episodes per run (the paper's 50).
    pub episodes: u32,
    /// Runs per world, each with other start poses (the paper's 5).
    pub runs: u32,
    /// Steps an episode must survive to succeed (the paper's 300); it ends there.
    pub max_steps: u32,
    /// The seed every start pose is drawn from.
    pub seed: u64,
    /// Environments stepped together, the policy deciding for all of them in one batch.
    /// The outcomes do not depend on it for a policy whose decision for one observation does
    /// not depend on the rest of the batch: the scripted ones, and a network deciding in
    /// forwards of a fixed size (`GreedyPolicy::with_forward_batch`; a forward's rounding
    /// depends on its row count).
    pub envs: usize,
    /// Threads stepping the simulator (0: all cores).
    pub sim_threads: usize,
    /// What a moving success needs beyond the paper's success (`--min-path`, `--min-reach`).
    pub moving: MovingRule,
}

impl Default for EvalSettings {
    fn default() -> Self {
        Self {
            episodes: 50,
            runs: 5,
            max_steps: 300,
            seed: 0,
            envs: 64,
            sim_threads: 1,
            moving: MovingRule::DEFAULT,
        }
    }
}

/// The most environments an evaluation steps together (each holds ~420 KB of frames).
pub const MAX_ENVS: usize = 4096;

/// The most episodes of one world (runs × episodes).
pub const MAX_EPISODES: u64 = 1_000_000;

impl EvalSettings {
    /// Checks the settings.
    ///
    /// # Errors
    /// A count of zero, or more environments than [`MAX_ENVS`].
    pub fn validate(&self) -> Result<(), EvalError> {
        let bad =
            |flag: &str, problem: &str| Err(EvalError::Settings(format!("{flag}: {problem}")));
        if self.episodes == 0 {
            return bad("--episodes 0", "an evaluation needs at least 1 episode per run");
        }
        if self.runs == 0 {
            return bad("--runs 0", "an evaluation needs at least 1 run");
        }
        if self.max_steps == 0 {
            return bad("--max-steps 0", "an episode needs at least 1 step");
        }
        if u64::from(self.runs) * u64::from(self.episodes) > MAX_EPISODES {
            return bad(
                &format!("--runs {} x --episodes {}", self.runs, self.episodes),
                &format!("at most {MAX_EPISODES} episodes per world"),
            );
        }
        if self.envs == 0 || self.envs > MAX_ENVS {
            return bad(&format!("--envs {}", self.envs), &format!("must be 1 to {MAX_ENVS}"));
        }
        self.moving.validate().map_err(EvalError::Settings)
    }

    /// Episodes per world.
    pub fn episodes_per_world(&self) -> usize {
        self.runs as usize * self.episodes as usize
    }
}

/// FNV-1a of a world's name: its part of every episode seed.
fn name_hash(name: &str) -> u64 {
    name.bytes()
        .fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3))
}

/// The seed of episode `episode` of run `run` in the world named `world`: the only input of
/// its start pose, pedestrians and sensor noise.
pub fn episode_seed(seed: u64, world: &str, run: u32, episode: u32) -> u64 {
    Rng::derive(seed ^ name_hash(world), (u64::from(run) << 32) | u64::from(episode)).next_u64()
}

/// How an episode ended in a collision (`episodes.csv`'s `collision_kind`).
pub fn collision_kind(c: &Collision) -> &'static str {
    match c {
        Collision::Bumper { .. } => "bumper",
        Collision::Pedestrian { .. } => "pedestrian",
        Collision::LaserRange => "laser",
    }
}

/// One evaluated episode.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeRecord {
    /// The world's name.
    pub world: String,
    /// Run index (0-based).
    pub run: u32,
    /// Episode index within the run (0-based).
    pub episode: u32,
    /// The episode's seed ([`episode_seed`]).
    pub seed: u64,
    /// The start pose.
    pub start: Pose2,
    /// Steps survived (`max_steps` for a success).
    pub steps: u32,
    /// The collision that ended it, if one did.
    pub collision: Option<Collision>,
    /// What the bumper hit, for a bumper collision: the obstacle's label in the world file
    /// (`chair seat`, `low box`), else `obstacle N` (its index); empty otherwise.
    pub hit: String,
    /// Distance driven, metres (up to the collision, if one ended it).
    pub path_m: f32,
    /// The farthest the robot got from its start, metres.
    pub reach_m: f32,
    /// Accumulated reward (paper eq. 3).
    pub ret: f32,
    /// The actions taken (a continuous controller's: the nearest Table 1 ones).
    pub actions: Vec<Action>,
    /// The velocity commands (with the seed they reproduce the episode, for figures).
    pub commands: Vec<Velocity>,
    /// The navigation task's goal (`None`: obstacle avoidance).
    pub goal: Option<mdrlat_geom::Vec2>,
    /// The robot reached its goal (navigation).
    pub reached_goal: bool,
}

impl EpisodeRecord {
    /// Obstacle avoidance: no collision within the step budget. Navigation: the goal
    /// reached ([`mdrlat_sim::episode_success`]).
    pub fn success(&self) -> bool {
        mdrlat_sim::episode_success(self.goal, self.reached_goal, self.collision)
    }

    /// The success *and* the travel `rule` asks for ([`mdrlat_sim::moving_success`]).
    pub fn moving_success(&self, rule: &MovingRule) -> bool {
        mdrlat_sim::moving_success(
            self.goal,
            self.reached_goal,
            self.collision,
            self.path_m,
            self.reach_m,
            rule,
        )
    }
}

/// A policy's evaluation in one world.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldEval {
    /// The world's name.
    pub world: String,
    /// Every episode, run by run, in order.
    pub records: Vec<EpisodeRecord>,
    /// Wall time, seconds (not part of any output file: it differs between machines).
    pub wall_s: f64,
    /// Seconds spent inside the policy's decisions.
    pub policy_s: f64,
    /// Decisions made (one per environment step).
    pub decisions: u64,
    /// Batched policy calls made.
    pub batches: u64,
}

/// Where an evaluation is, for progress bars.
#[derive(Debug, Clone, PartialEq)]
pub struct Progress<'a> {
    /// The world being evaluated.
    pub world: &'a str,
    /// Episodes finished in this world.
    pub done: usize,
    /// Episodes of this world.
    pub total: usize,
    /// Finished episodes without a collision (the paper's success).
    pub successes: usize,
    /// Finished episodes that also travelled ([`EvalSettings::moving`]).
    pub moving_successes: usize,
}

/// Times a policy's decisions.
struct Timed<'a> {
    inner: &'a mut dyn Policy,
    busy: Duration,
    decisions: u64,
    batches: u64,
}

impl Policy for Timed<'_> {
    fn name(&self) -> String {
        self.inner.name()
    }
    fn sensors(&self) -> Sensors {
        self.inner.sensors()
    }
    fn depth_memory_frames(&self) -> u32 {
        self.inner.depth_memory_frames()
    }
    fn begin_episode(&mut self, slot: usize, seed: Option<u64>) {
        self.inner.begin_episode(slot, seed);
    }
    fn decide(
        &mut self,
        batch: &[&Observation],
        slots: &[usize],
        out: &mut Vec<Decision>,
    ) -> Result<(), PolicyError> {
        self.timed(batch.len(), |inner| inner.decide(batch, slots, out))
    }
}

impl Timed<'_> {
    /// Runs one decision of `n` observations, adding its time.
    fn timed(
        &mut self,
        n: usize,
        decide: impl FnOnce(&mut dyn Policy) -> Result<(), PolicyError>,
    ) -> Result<(), PolicyError> {
        let t = Instant::now();
        let r = decide(&mut *self.inner);
        self.busy += t.elapsed();
        self.decisions += n as u64;
        self.batches += 1;
        r
    }
}

/// Counts finished episodes for the progress callback.
struct Counter<'a> {
    world: &'a str,
    total: usize,
    done: usize,
    successes: usize,
    moving_successes: usize,
    rule: MovingRule,
    progress: &'a mut dyn FnMut(&Progress<'_>),
}

impl Observer for Counter<'_> {
    fn on_episode(&mut self, _episode: usize, outcome: &EpisodeOutcome) {
        self.done += 1;
        self.successes += usize::from(outcome.success());
        self.moving_successes += usize::from(outcome.moving_success(&self.rule));
        (self.progress)(&Progress {
            world: self.world,
            done: self.done,
            total: self.total,
            successes: self.successes,
            moving_successes: self.moving_successes,
        });
    }
}

/// The simulator settings of an evaluation: `sim` with the episode's time limit at the
/// protocol's step budget, so that surviving it is exactly `truncated`.
pub fn eval_sim_config(sim: &SimConfig, settings: &EvalSettings) -> SimConfig {
    SimConfig { max_episode_steps: settings.max_steps, ..sim.clone() }
}

/// The episodes of one world, run-major: `(run, episode, seed)`.
pub fn world_episodes(world: &str, settings: &EvalSettings) -> Vec<(u32, u32, u64)> {
    (0..settings.runs)
        .flat_map(|r| (0..settings.episodes).map(move |e| (r, e)))
        .map(|(r, e)| (r, e, episode_seed(settings.seed, world, r, e)))
        .collect()
}

/// Evaluates `policy` in `world` by the protocol of `settings`; `progress` is called after
/// every episode.
///
/// # Errors
/// Invalid settings, a world whose spawn regions are blocked, or a policy that cannot
/// decide.
pub fn evaluate_world(
    world: &World,
    sim: &SimConfig,
    policy: &mut dyn Policy,
    settings: &EvalSettings,
    progress: &mut dyn FnMut(&Progress<'_>),
) -> Result<WorldEval, EvalError> {
    settings.validate()?;
    let started = Instant::now();
    let sim = eval_sim_config(sim, settings);
    let scene = Arc::new(StaticScene::new(Arc::new(world.clone()), &sim));
    let episodes = world_episodes(&world.name, settings);
    let slots = settings.envs.min(episodes.len());
    let mut venv = VecEnv::new(scene, sim, slots, settings.sim_threads)?;
    let specs: Vec<EpisodeSpec> =
        episodes.iter().map(|&(_, _, seed)| EpisodeSpec { seed: Some(seed), pose: None }).collect();
    let mut timed = Timed { inner: policy, busy: Duration::ZERO, decisions: 0, batches: 0 };
    let mut counter = Counter {
        world: &world.name,
        total: specs.len(),
        done: 0,
        successes: 0,
        moving_successes: 0,
        rule: settings.moving,
        progress,
    };
    let options = RunOptions { max_steps: settings.max_steps, record_rows: false };
    let outcomes = run_episodes(&mut venv, &mut timed, &specs, &options, &mut counter).map_err(
        |e| match e {
            mdrlat_sim::RunError::Policy { policy, episode, source } => {
                let (run, episode, seed) = episodes[episode];
                EvalError::Policy { policy, world: world.name.clone(), run, episode, seed, source }
            }
            other => EvalError::Run(other),
        },
    )?;
    let records = episodes
        .iter()
        .zip(outcomes)
        .map(|(&(run, episode, seed), o)| EpisodeRecord {
            world: world.name.clone(),
            run,
            episode,
            seed,
            start: o.start,
            steps: o.steps,
            hit: match o.collision {
                Some(Collision::Bumper { obstacle }) => world
                    .obstacles
                    .get(obstacle)
                    .and_then(|ob| ob.label.clone())
                    .unwrap_or_else(|| format!("obstacle {obstacle}")),
                _ => String::new(),
            },
            collision: o.collision,
            path_m: o.path_m,
            reach_m: o.reach_m,
            ret: o.reward,
            actions: o.actions,
            commands: o.commands,
            goal: o.goal,
            reached_goal: o.reached_goal,
        })
        .collect();
    Ok(WorldEval {
        world: world.name.clone(),
        records,
        wall_s: started.elapsed().as_secs_f64(),
        policy_s: timed.busy.as_secs_f64(),
        decisions: timed.decisions,
        batches: timed.batches,
    })
}
