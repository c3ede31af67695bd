//! The training loop of paper Algorithm 1, with greedy evaluations (Fig. 4), metrics and the
//! final weights. It reads top to bottom like the algorithm; `// Algorithm 1, line N` marks
//! each step.

use crate::checkpoint::{self, Meta, PendingStep, Window, frame_reserve};
use crate::config::TrainConfig;
use crate::learner::{Inputs, Learner, Losses};
use crate::policy::observation_inputs;
use crate::replay::{Batch, FrameId, ReplayBuffer, Transition};
use crate::tensorboard::EventWriter;
use mdrlat_core::{Action, FRAME_STACK, ODOM_HISTORY, Policy, PolicyError, Rng};
use mdrlat_nn::burn::prelude::Device;
use mdrlat_sim::config::Task;
use mdrlat_sim::{
    Env, EpisodeSpec, Observation, Quiet, RunError, RunOptions, SimConfig, SimError, StaticScene,
    VecEnv, run_episodes,
};
use mdrlat_world::World;
use serde::Serialize;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

/// Steps per row of `metrics.csv`.
const LOG_INTERVAL: u64 = 100;

/// Why training stopped.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TrainError {
    /// The settings are inconsistent.
    #[error(transparent)]
    Config(#[from] crate::config::TrainConfigError),
    /// An empty list of training worlds.
    #[error("no training world given")]
    NoWorld,
    /// The simulator failed.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// The network could not decide (non-finite Q-values: the run diverged).
    #[error("acting at step {step}: {source}")]
    Policy {
        /// Environment step.
        step: u64,
        /// What went wrong.
        source: PolicyError,
    },
    /// A greedy evaluation failed.
    #[error("evaluation at step {step}: {source}")]
    Evaluation {
        /// Environment step.
        step: u64,
        /// What went wrong.
        source: RunError,
    },
    /// A learning curve's evaluation failed.
    #[error("learning curve in '{world}' at step {step}: {source}")]
    Curve {
        /// Environment step.
        step: u64,
        /// The world.
        world: String,
        /// What went wrong.
        source: Box<mdrlat_eval::EvalError>,
    },
    /// The learning curves' unseen world cannot be loaded.
    #[error("train.curve_world '{spec}': {source}")]
    CurveWorld {
        /// The world as given.
        spec: String,
        /// What is wrong with it.
        source: mdrlat_world::WorldError,
    },
    /// A checkpoint is missing, corrupt or of another run.
    #[error("{path}: {problem}")]
    Checkpoint {
        /// The file or folder.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// A file could not be written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
}

/// Where training is, for progress bars.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Status {
    /// Environment steps done.
    pub step: u64,
    /// ε now.
    pub epsilon: f32,
    /// Losses of the last gradient step.
    pub losses: Losses,
    /// Episodes finished.
    pub episodes: u64,
    /// Mean accumulated reward of the last evaluation.
    pub last_eval: Option<f32>,
}

/// One greedy evaluation (Fig. 4): accumulated reward of episodes from fixed start poses.
#[derive(Debug, Clone, PartialEq)]
pub struct Evaluation {
    /// Environment step of the run when it was taken.
    pub step: u64,
    /// Accumulated reward of each episode.
    pub rewards: Vec<f32>,
    /// Length of each episode.
    pub lengths: Vec<u32>,
    /// Whether each episode ended in a collision.
    pub collisions: Vec<bool>,
    /// Whether each episode succeeded (`mdrlat_sim::episode_success`): no collision in
    /// obstacle avoidance, the goal reached in navigation.
    pub successes: Vec<bool>,
    /// The learning curves' points at this step: held-out starts of the training world
    /// first, then the unseen world (none when `curve_episodes` is 0).
    pub curves: Vec<CurvePoint>,
}

/// A learning curve's point: the greedy policy in one world by the evaluation protocol
/// (`mdrlat eval`'s episodes, 300 steps, one run of `curve_episodes` episodes).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CurvePoint {
    /// The world.
    pub world: String,
    /// Moving success rate (no collision, at least `train.curve_min_path_m` driven and
    /// `train.curve_min_reach_m` from the start).
    pub moving_success: f64,
    /// The paper's success rate (no collision within 300 steps).
    pub success: f64,
    /// Mean collision-free path, metres.
    pub path_m: f64,
}

impl Evaluation {
    /// Share of successful episodes (obstacle avoidance: the paper's success, here over the
    /// training world's episode length; navigation: goals reached).
    pub fn success_rate(&self) -> f32 {
        let ok = self.successes.iter().filter(|s| **s).count();
        ok as f32 / self.successes.len().max(1) as f32
    }
    /// Share of episodes that ended in a collision.
    pub fn collision_rate(&self) -> f32 {
        let hit = self.collisions.iter().filter(|c| **c).count();
        hit as f32 / self.collisions.len().max(1) as f32
    }

    /// Mean accumulated reward.
    pub fn mean(&self) -> f32 {
        self.rewards.iter().sum::<f32>() / self.rewards.len().max(1) as f32
    }
    /// Population standard deviation of the accumulated reward.
    pub fn std(&self) -> f32 {
        let m = self.mean();
        (self.rewards.iter().map(|r| (r - m) * (r - m)).sum::<f32>()
            / self.rewards.len().max(1) as f32)
            .sqrt()
    }
}

/// The result of a run.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainReport {
    /// Environment steps taken.
    pub steps: u64,
    /// Gradient steps taken.
    pub updates: u64,
    /// Episodes finished.
    pub episodes: u64,
    /// Every evaluation, in order.
    pub evaluations: Vec<Evaluation>,
    /// Wall time, seconds.
    pub seconds: f64,
    /// Where that time went.
    pub timing: Timing,
}

/// Where a training session's wall time went, seconds.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Timing {
    /// Greedy decisions of ε-greedy (Algorithm 1, line 3).
    pub acting: f64,
    /// Environment steps (line 4).
    pub env: f64,
    /// Storing transitions, and the resets of episodes that ended (line 5).
    pub storing: f64,
    /// Sampling batches from the replay buffer (line 6).
    pub sampling: f64,
    /// Gradient steps and target syncs (lines 7–18).
    pub learning: f64,
    /// Greedy evaluations.
    pub evaluation: f64,
    /// Metrics, TensorBoard events, checkpoints, progress.
    pub output: f64,
}

impl Timing {
    /// The parts, named, in loop order.
    pub fn parts(&self) -> [(&'static str, f64); 7] {
        [
            ("acting", self.acting),
            ("env", self.env),
            ("storing", self.storing),
            ("sampling", self.sampling),
            ("learning", self.learning),
            ("evaluation", self.evaluation),
            ("output", self.output),
        ]
    }
}

/// Seconds since the last split: a stopwatch for [`Timing`].
struct Lap(Instant);

impl Lap {
    fn split(&mut self) -> f64 {
        let now = Instant::now();
        let s = (now - self.0).as_secs_f64();
        self.0 = now;
        s
    }
}

fn odom_of(obs: &Observation) -> [f32; 2 * ODOM_HISTORY] {
    let mut o = [0.0; 2 * ODOM_HISTORY];
    for (k, v) in obs.odom.iter().enumerate() {
        o[2 * k] = v.v;
        o[2 * k + 1] = v.w;
    }
    o
}

/// A CSV file with a header, named in errors.
struct Csv {
    path: PathBuf,
    out: BufWriter<File>,
}

impl Csv {
    fn create(path: PathBuf, header: &str) -> Result<Self, TrainError> {
        let file =
            File::create(&path).map_err(|source| TrainError::Io { path: path.clone(), source })?;
        let mut csv = Csv { path, out: BufWriter::new(file) };
        csv.line(header)?;
        // The header on disk at once: a run stopped before its first rows leaves a readable
        // (empty) table, not an empty file.
        csv.flush()?;
        Ok(csv)
    }
    fn line(&mut self, text: &str) -> Result<(), TrainError> {
        writeln!(self.out, "{text}")
            .map_err(|source| TrainError::Io { path: self.path.clone(), source })
    }
    fn flush(&mut self) -> Result<(), TrainError> {
        self.out.flush().map_err(|source| TrainError::Io { path: self.path.clone(), source })
    }
}

/// Greedy episodes of the learner's online network from the fixed start poses
/// `eval_seed + k` (the same for every run), one per environment of `venv`, through the
/// episode runner; each runs to the environment's own end (collision or time limit). Then
/// the learning curves: the same policy in each of `curve_worlds` by the evaluation protocol
/// ([`mdrlat_eval::evaluate_world`], the one `mdrlat eval` runs).
///
/// # Errors
/// The simulator failed to reset, or the network could not decide.
pub fn evaluate(
    venv: &mut VecEnv,
    learner: &Learner,
    config: &TrainConfig,
    sim: &SimConfig,
    curve_worlds: &[World],
    step: u64,
) -> Result<Evaluation, TrainError> {
    let eval_error = |source| TrainError::Evaluation { step, source };
    // The run's share of the cores (RAYON_NUM_THREADS when a sweep runs several at once).
    let threads = rayon::current_num_threads();
    // A thread pool that cannot start is the policy's failure, not an observer's.
    let mut policy = learner
        .greedy_policy(threads)
        .map_err(|e| TrainError::Policy { step, source: PolicyError::Backend(e) })?;
    let specs: Vec<EpisodeSpec> = (0..u64::from(config.eval_episodes))
        .map(|k| EpisodeSpec { seed: Some(config.eval_seed + k), pose: None })
        .collect();
    let outcomes = run_episodes(venv, &mut policy, &specs, &RunOptions::default(), &mut Quiet)
        .map_err(eval_error)?;
    let settings = mdrlat_eval::EvalSettings {
        episodes: config.curve_episodes,
        runs: 1,
        seed: config.eval_seed,
        envs: (config.curve_episodes as usize).clamp(1, 64),
        sim_threads: 1,
        moving: config.curve_rule(),
        ..mdrlat_eval::EvalSettings::default()
    };
    let mut curves = Vec::with_capacity(curve_worlds.len());
    for world in curve_worlds {
        let e = mdrlat_eval::evaluate_world(world, sim, &mut policy, &settings, &mut |_| {})
            .map_err(|source| TrainError::Curve {
                step,
                world: world.name.clone(),
                source: Box::new(source),
            })?;
        let s = mdrlat_eval::WorldSummary::new("curve", &e, &settings);
        curves.push(CurvePoint {
            world: world.name.clone(),
            moving_success: s.moving_success_mean,
            success: s.success_mean,
            path_m: s.path_m_mean,
        });
    }
    Ok(Evaluation {
        step,
        rewards: outcomes.iter().map(|o| o.reward).collect(),
        lengths: outcomes.iter().map(|o| o.steps).collect(),
        collisions: outcomes.iter().map(|o| o.collision.is_some()).collect(),
        successes: outcomes.iter().map(|o| o.success()).collect(),
        curves,
    })
}

/// Keeps the rows of a run's CSV file before `step` (and at `step` with `keep_step`): those
/// a resumed run will not write again. A file written by an older version with fewer
/// columns gets `header` and its old rows empty fields for the new columns, so every row
/// has the header's width. Opens the file for appending.
fn reopen(path: PathBuf, header: &str, step: u64, keep_step: bool) -> Result<Csv, TrainError> {
    let io = |source| TrainError::Io { path: path.clone(), source };
    let text = std::fs::read_to_string(&path).map_err(io)?;
    let old_header = text.lines().next().unwrap_or_default();
    let (old_fields, fields): (Vec<&str>, Vec<&str>) =
        (old_header.split(',').collect(), header.split(',').collect());
    // The same columns, or the first columns of today's (an older version's file).
    if old_fields.len() > fields.len() || fields[..old_fields.len()] != old_fields[..] {
        return Err(TrainError::Checkpoint {
            path: path.clone(),
            problem: format!(
                "its header '{old_header}' is not this version's '{header}' nor its first \
                 columns: written by another mdrlat; resume it with that one"
            ),
        });
    }
    let missing = fields.len() - old_fields.len();
    let mut kept = String::with_capacity(text.len());
    for (i, line) in text.lines().enumerate() {
        if i == 0 {
            kept.push_str(if missing > 0 { header } else { line });
            kept.push('\n');
            continue;
        }
        let row_step = line.split(',').next().and_then(|f| f.parse::<u64>().ok());
        if row_step.is_some_and(|s| s < step || (s == step && keep_step)) {
            kept.push_str(line);
            kept.push_str(&",".repeat(missing));
            kept.push('\n');
        }
    }
    std::fs::write(&path, kept).map_err(io)?;
    let file = std::fs::OpenOptions::new().append(true).open(&path).map_err(io)?;
    Ok(Csv { path, out: BufWriter::new(file) })
}

/// The header of `metrics.csv`.
const METRICS_HEADER: &str =
    "step,loss_td,loss_at,q_mean,epsilon,episode_reward,episode_length,episodes";
/// The header of `eval.csv`: Fig. 4's reward on fixed starts of the training world, then
/// the learning curves (held-out starts of the training world, then the unseen world named
/// in `config.toml`'s `train.curve_world`; empty where a run has no curves).
pub const EVAL_HEADER: &str = "step,eval_reward_mean,eval_reward_std,eval_length_mean,\
eval_success_rate,eval_collision_rate,train_moving_success,train_success,train_path_m,\
unseen_moving_success,unseen_success,unseen_path_m";

/// One training environment and where it is: its world, its episode so far and the
/// replay frames of its observation's stack.
struct Slot {
    env: Env,
    world: usize,
    episode_reward: f32,
    episode_length: u32,
    stack: [FrameId; FRAME_STACK],
    /// Steps whose n-step transitions wait for the steps after them.
    pending: std::collections::VecDeque<PendingStep>,
}

/// Trains `config.variant` in `worlds` (at least one; with several, the environments move
/// from world to world, see [`TrainConfig::envs`]) for `config.total_steps` steps on
/// `device`, writing `metrics.csv`, `eval.csv` and checkpoints into `dir` (which must exist);
/// with `resume`, continues exactly from the checkpoint in `dir`. `progress` is called after
/// every step. The first world is the one of Fig. 4's evaluations and of the learning
/// curves' held-out starts.
///
/// # Errors
/// Invalid settings, a simulator failure, a missing or bad checkpoint, or a file that
/// cannot be written.
pub fn train(
    worlds: Vec<World>,
    sim: &SimConfig,
    config: &TrainConfig,
    device: &Device,
    dir: &Path,
    resume: bool,
    mut progress: impl FnMut(&Status),
) -> Result<(TrainReport, Learner), TrainError> {
    config.validate()?;
    let Some(first_world) = worlds.first().cloned() else {
        return Err(TrainError::NoWorld);
    };
    let (task, nav) = (sim.task, sim.task == Task::Nav);
    let started = Instant::now();
    // The learning curves' worlds: the training world's held-out starts, then the unseen one.
    let mut curve_worlds = Vec::new();
    if config.curve_episodes > 0 {
        curve_worlds.push(first_world);
        if let Some(spec) = config.curve_world_for(task) {
            let unseen = mdrlat_world::load(&spec)
                .map_err(|source| TrainError::CurveWorld { spec: spec.clone(), source })?;
            curve_worlds.push(unseen);
        }
    }
    let scenes: Vec<Arc<StaticScene>> =
        worlds.into_iter().map(|w| Arc::new(StaticScene::new(Arc::new(w), sim))).collect();
    let (n_envs, n_step) = (config.envs, config.n_step as usize);
    // One environment per evaluation episode, stepped on this thread, the network deciding
    // for all of them at once.
    let slots = config.eval_episodes.min(32) as usize;
    let mut eval_envs = VecEnv::new(scenes[0].clone(), sim.clone(), slots, 1)?;
    let variant = config.variant;
    let push_latest = |replay: &mut ReplayBuffer, obs: &Observation| {
        replay.push_frame(obs.laser.latest(), obs.depth.latest())
    };
    // The goal of an observation in the robot frame, stored with each transition
    // (navigation; zeros in obstacle avoidance, where the buffer does not keep it).
    let goal_of = |obs: &Observation| obs.goal.unwrap_or_default();
    let scene_of = |world: usize, path: &Path| {
        scenes.get(world).cloned().ok_or_else(|| TrainError::Checkpoint {
            path: path.to_path_buf(),
            problem: format!("names training world {world}; the run has {}", scenes.len()),
        })
    };

    // Algorithm 1, line 1: replay buffer D, online network θ, target θ⁻ = θ — or all of it,
    // with the environments and every random stream, from the checkpoint.
    let (mut learner, mut replay, mut run, mut envs, mut metrics, mut evals_csv) = if resume {
        let (run, learner, replay) = checkpoint::load(dir, config, task, device)?;
        let meta_path = checkpoint::folder(dir).join("meta.json");
        let first = checkpoint::EnvSlot {
            world: run.world,
            episode_reward: run.episode_reward,
            episode_length: run.episode_length,
            stack: run.stack,
            env: run.env.clone(),
            pending: run.pending.clone(),
        };
        let mut envs = Vec::with_capacity(n_envs);
        for saved in std::iter::once(&first).chain(&run.more_envs) {
            let mut env = Env::new(scene_of(saved.world, &meta_path)?, sim.clone())?;
            env.restore(&saved.env)?;
            envs.push(Slot {
                env,
                world: saved.world,
                episode_reward: saved.episode_reward,
                episode_length: saved.episode_length,
                stack: saved.stack,
                pending: saved.pending.iter().copied().collect(),
            });
        }
        // A partial-window row at the checkpoint step is written again, complete — unless
        // the run is already at its end (killed after its last checkpoint): then nothing
        // would write it again, and it is kept.
        let metrics = reopen(
            dir.join("metrics.csv"),
            METRICS_HEADER,
            run.step,
            run.step % LOG_INTERVAL == 0 || run.step >= config.total_steps,
        )?;
        let evals = reopen(dir.join("eval.csv"), EVAL_HEADER, run.step, true)?;
        (learner, replay, run, envs, metrics, evals)
    } else {
        // Seeding in one block: network init (inside Learner::new), environments (one
        // stream each), exploration and replay sampling — each its own stream of the seed.
        let mut replay = ReplayBuffer::new(
            config.replay_capacity,
            frame_reserve(config.replay_capacity),
            variant.uses_laser(),
            variant.uses_depth(),
        )
        .with_goals(nav)
        .with_envs(n_envs, config.n_step as usize);
        let mut envs = Vec::with_capacity(n_envs);
        for k in 0..n_envs {
            let world = k % scenes.len();
            let mut env = Env::new(scenes[world].clone(), sim.clone())?;
            env.reset_stream(config.seed, k as u64)?;
            let first = push_latest(&mut replay, env.observation());
            let stack = [first; FRAME_STACK];
            let pending = std::collections::VecDeque::new();
            envs.push(Slot { env, world, episode_reward: 0.0, episode_length: 0, stack, pending });
        }
        let run = Meta {
            format: checkpoint::CHECKPOINT_FORMAT,
            mdrlat_version: env!("CARGO_PKG_VERSION").to_string(),
            variant,
            task,
            step: 0,
            updates: 0,
            episodes: 0,
            episode_reward: 0.0,
            episode_length: 0,
            stack: envs[0].stack,
            explore_rng: Rng::derive(config.seed, 101),
            sample_rng: Rng::derive(config.seed, 102),
            window: Window::default(),
            env: envs[0].env.state(),
            pending: Vec::new(),
            world: 0,
            more_envs: Vec::new(),
            replay_bytes: 0,
            replay_checksum: 0,
        };
        let metrics = Csv::create(dir.join("metrics.csv"), METRICS_HEADER)?;
        let evals = Csv::create(dir.join("eval.csv"), EVAL_HEADER)?;
        (Learner::new(config, task, device), replay, run, envs, metrics, evals)
    };
    let mut events = EventWriter::create(dir)
        .map_err(|source| TrainError::Io { path: dir.to_path_buf(), source })?;
    let tb_err =
        |events: &EventWriter, source| TrainError::Io { path: events.path().to_path_buf(), source };
    if resume {
        events.session_start(run.step).map_err(|e| tb_err(&events, e))?;
    }
    let mut inputs = Inputs::default();
    let mut batch = Batch::default();
    let mut status = Status { step: run.step, episodes: run.episodes, ..Status::default() };
    let mut report = TrainReport {
        steps: 0,
        updates: 0,
        episodes: 0,
        evaluations: Vec::new(),
        seconds: 0.0,
        timing: Timing::default(),
    };
    let (mut lap, mut timing) = (Lap(Instant::now()), Timing::default());
    let (mut actions, mut greedy_envs) = (vec![0usize; n_envs], Vec::with_capacity(n_envs));
    // The demonstrator of the first `demo_steps` steps, watching every environment.
    let mut demonstrator = if run.step < config.demo_steps {
        let avoid = mdrlat_sim::AvoidPolicy::new(sim, mdrlat_sim::AvoidConfig::default())
            .map_err(|e| TrainError::Policy { step: run.step, source: PolicyError::Backend(e) })?;
        Some(avoid)
    } else {
        None
    };
    let (mut demo_actions, all_envs): (Vec<Action>, Vec<usize>) =
        (Vec::with_capacity(n_envs), (0..n_envs).collect());

    // Algorithm 1, line 2, for every environment in turn: a tick steps each once.
    let mut done_steps = run.step;
    while done_steps < config.total_steps {
        // Line 3: ε-greedy on each environment's s_k; the greedy ones in one forward pass.
        // During the demonstrations an exploratory action may be `avoid`'s.
        greedy_envs.clear();
        demo_actions.clear();
        if done_steps >= config.demo_steps {
            demonstrator = None;
        }
        if let Some(demo) = demonstrator.as_mut() {
            let observations: Vec<&Observation> =
                envs.iter().map(|s| s.env.observation()).collect();
            demo.act(&observations, &all_envs, &mut demo_actions)
                .map_err(|source| TrainError::Policy { step: done_steps + 1, source })?;
        }
        for (k, action) in actions.iter_mut().enumerate() {
            let epsilon = config.epsilon(done_steps + k as u64);
            if run.explore_rng.uniform() < f64::from(epsilon) {
                *action = match demo_actions.get(k) {
                    Some(a) if run.explore_rng.uniform() < f64::from(config.demo_share) => {
                        a.index()
                    }
                    _ => run.explore_rng.below(Action::COUNT),
                };
            } else {
                greedy_envs.push(k);
            }
        }
        if !greedy_envs.is_empty() {
            let at = done_steps + 1 + greedy_envs[0] as u64;
            let observations: Vec<&Observation> =
                greedy_envs.iter().map(|&k| envs[k].env.observation()).collect();
            observation_inputs(&observations, learner.net_config(), &mut inputs)
                .map_err(|source| TrainError::Policy { step: at, source })?;
            let greedy = learner
                .greedy(&inputs)
                .map_err(|source| TrainError::Policy { step: at, source })?;
            for (&k, a) in greedy_envs.iter().zip(&greedy) {
                actions[k] = a.index();
            }
        }
        timing.acting += lap.split();
        let mut checkpoint_due = false;
        for (k, slot) in envs.iter_mut().enumerate() {
            let t = done_steps + 1 + k as u64;
            let epsilon = config.epsilon(t - 1);
            let action = actions[k];
            let (odom, goal) = (odom_of(slot.env.observation()), goal_of(slot.env.observation()));
            // Line 4: execute a_k, observe r_k and s_{k+1}.
            let a = Action::new(action).unwrap_or_else(|| unreachable!("action index < 10"));
            let s = slot.env.step(a)?;
            timing.env += lap.split();
            let (reward, terminated, done) = (s.reward, s.terminated, s.terminated || s.truncated);
            // Line 5: store (s_k, a_k, r_k, s_{k+1}); s_{k+1} is the true final observation at
            // an episode's end, and only a collision or the goal (terminated) marks it
            // terminal. With n-step returns, (s_k, a_k, Σ γ^i r_{k+i}, s_{k+n}) once the n-th
            // step is done, and every waiting step at an episode's end.
            let newest = push_latest(&mut replay, s.observation);
            let stack = slot.stack;
            let next = [stack[1], stack[2], stack[3], newest];
            let next_goal = goal_of(s.observation);
            let step = PendingStep { obs: stack, action: action as u8, reward, odom, goal };
            slot.pending.push_back(step);
            let ready = if done { slot.pending.len() } else { slot.pending.len() / n_step };
            for _ in 0..ready {
                let steps = slot.pending.len();
                let ret = slot
                    .pending
                    .iter()
                    .rev()
                    .map(|p| p.reward)
                    .reduce(|later, r| r + config.gamma * later);
                let Some(first) = slot.pending.pop_front() else { break };
                replay.push(Transition {
                    obs: first.obs,
                    next,
                    action: first.action,
                    reward: ret.unwrap_or(first.reward),
                    terminated,
                    steps: steps as u8,
                    odom: first.odom,
                    goal: first.goal,
                    next_goal,
                });
            }
            slot.episode_reward += reward;
            slot.episode_length += 1;
            if done {
                run.window.episode_reward += f64::from(slot.episode_reward);
                run.window.episode_length += f64::from(slot.episode_length);
                run.window.episodes += 1;
                run.episodes += 1;
                (slot.episode_reward, slot.episode_length) = (0.0, 0);
                if let Some(demo) = demonstrator.as_mut() {
                    demo.begin_episode(k, None);
                }
                if scenes.len() > 1 {
                    // The next world, keeping the environment's random streams.
                    slot.world = (slot.world + 1) % scenes.len();
                    slot.env.move_to(scenes[slot.world].clone())?;
                } else {
                    slot.env.reset(None)?;
                }
                let first = push_latest(&mut replay, slot.env.observation());
                slot.stack = [first; FRAME_STACK];
            } else {
                slot.stack = next;
            }
            timing.storing += lap.split();

            // Lines 6–15: gradient steps on random batches.
            if replay.len() as u64 >= config.learning_starts
                && t.is_multiple_of(config.train_frequency)
            {
                for _ in 0..config.gradient_steps {
                    let idx = replay.sample_indices(config.batch_size, &mut run.sample_rng);
                    replay.write_batch_as(&idx, &mut batch, learner.depth_layout());
                    timing.sampling += lap.split();
                    let losses = learner.update(&batch);
                    status.losses = losses;
                    run.window.td += f64::from(losses.td);
                    run.window.at += f64::from(losses.at);
                    run.window.q += f64::from(losses.q_mean);
                    run.window.updates += 1;
                }
            }
            // Lines 16–18: θ⁻ ← θ every N_t steps.
            if t.is_multiple_of(config.target_update_interval) {
                learner.sync_target();
            }
            timing.learning += lap.split();

            if t.is_multiple_of(LOG_INTERVAL) || t == config.total_steps {
                let w = run.window;
                let mean = |x: f64, n: u32| {
                    if n > 0 { format!("{:.6}", x / f64::from(n)) } else { String::new() }
                };
                metrics.line(&format!(
                    "{t},{},{},{},{epsilon:.6},{},{},{}",
                    mean(w.td, w.updates),
                    mean(w.at, w.updates),
                    mean(w.q, w.updates),
                    mean(w.episode_reward, w.episodes),
                    mean(w.episode_length, w.episodes),
                    run.episodes
                ))?;
                let per = |x: f64, n: u32| if n > 0 { (x / f64::from(n)) as f32 } else { f32::NAN };
                events
                    .scalars(
                        t,
                        &[
                            ("losses/td", per(w.td, w.updates)),
                            ("losses/at", per(w.at, w.updates)),
                            ("losses/q_mean", per(w.q, w.updates)),
                            ("charts/epsilon", epsilon),
                            ("charts/episode_reward", per(w.episode_reward, w.episodes)),
                            ("charts/episode_length", per(w.episode_length, w.episodes)),
                        ],
                    )
                    .map_err(|e| tb_err(&events, e))?;
                metrics.flush()?; // one write per 100 steps: `tail -f metrics.csv` works
                // A run's last row may cover a partial window; its sums stay open (and go
                // into the checkpoint) so that an extended run logs exactly what one long run
                // would.
                if t.is_multiple_of(LOG_INTERVAL) {
                    run.window = Window::default();
                }
            }
            timing.output += lap.split();
            if t.is_multiple_of(config.eval_interval) {
                let e = evaluate(&mut eval_envs, &learner, config, sim, &curve_worlds, t)?;
                write_evaluation(&e, &mut evals_csv, &mut events)?;
                status.last_eval = Some(e.mean());
                report.evaluations.push(e);
            }
            timing.evaluation += lap.split();
            // A checkpoint every interval and at the end (so a finished run can be
            // extended; unless `final_checkpoint` is off), written once the tick is done:
            // every environment then stands after its step.
            checkpoint_due |= t.is_multiple_of(config.checkpoint_interval)
                || (t == config.total_steps && config.final_checkpoint);
            status.step = t;
            status.epsilon = epsilon;
            status.episodes = run.episodes;
            progress(&status);
            timing.output += lap.split();
        }
        done_steps += n_envs as u64;
        if checkpoint_due {
            events.flush().map_err(|e| tb_err(&events, e))?;
            metrics.flush()?;
            evals_csv.flush()?;
            run.step = done_steps;
            run.updates = learner.updates();
            let [first, rest @ ..] = envs.as_slice() else { unreachable!("train.envs >= 1") };
            (run.env, run.world, run.stack) = (first.env.state(), first.world, first.stack);
            run.pending = first.pending.iter().copied().collect();
            (run.episode_reward, run.episode_length) = (first.episode_reward, first.episode_length);
            run.more_envs = rest
                .iter()
                .map(|s| checkpoint::EnvSlot {
                    world: s.world,
                    episode_reward: s.episode_reward,
                    episode_length: s.episode_length,
                    stack: s.stack,
                    env: s.env.state(),
                    pending: s.pending.iter().copied().collect(),
                })
                .collect();
            checkpoint::save(dir, &mut run, &learner, &replay)?;
            timing.output += lap.split();
        }
    }
    metrics.flush()?;
    evals_csv.flush()?;
    events.flush().map_err(|e| tb_err(&events, e))?;
    report.steps = config.total_steps;
    report.updates = learner.updates();
    report.episodes = run.episodes;
    report.seconds = started.elapsed().as_secs_f64();
    report.timing = timing;
    Ok((report, learner))
}

/// One evaluation's row of `eval.csv` and its TensorBoard scalars.
fn write_evaluation(
    e: &Evaluation,
    evals_csv: &mut Csv,
    events: &mut EventWriter,
) -> Result<(), TrainError> {
    let t = e.step;
    let mean_len =
        e.lengths.iter().map(|&l| f64::from(l)).sum::<f64>() / e.lengths.len().max(1) as f64;
    // The curves' columns: held-out training starts, then the unseen world.
    let mut curve_cells = String::new();
    for k in 0..2 {
        match e.curves.get(k) {
            Some(c) => curve_cells
                .push_str(&format!(",{:.6},{:.6},{:.3}", c.moving_success, c.success, c.path_m)),
            None => curve_cells.push_str(",,,"),
        }
    }
    evals_csv.line(&format!(
        "{t},{:.6},{:.6},{mean_len:.2},{:.6},{:.6}{curve_cells}",
        e.mean(),
        e.std(),
        e.success_rate(),
        e.collision_rate()
    ))?;
    let mut scalars = vec![
        ("eval/reward_mean".to_string(), e.mean()),
        ("eval/reward_std".to_string(), e.std()),
        ("eval/length_mean".to_string(), mean_len as f32),
        ("eval/success_rate".to_string(), e.success_rate()),
        ("eval/collision_rate".to_string(), e.collision_rate()),
    ];
    for (c, which) in e.curves.iter().zip(["train", "unseen"]) {
        scalars.extend([
            (format!("curves/{which}_moving_success"), c.moving_success as f32),
            (format!("curves/{which}_success"), c.success as f32),
            (format!("curves/{which}_path_m"), c.path_m as f32),
        ]);
    }
    let named: Vec<(&str, f32)> = scalars.iter().map(|(k, v)| (k.as_str(), *v)).collect();
    events
        .scalars(t, &named)
        .map_err(|source| TrainError::Io { path: events.path().to_path_buf(), source })?;
    evals_csv.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_new_csv_has_its_header_on_disk_before_any_row() {
        let dir = std::env::temp_dir().join(format!("mdrlat-csv-header-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join("eval.csv");
        let csv = Csv::create(path.clone(), EVAL_HEADER).expect("create");
        // Read while the writer is still open, as after a run killed before its first rows.
        assert_eq!(std::fs::read_to_string(&path).expect("read"), format!("{EVAL_HEADER}\n"));
        drop(csv);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn resuming_a_run_of_an_older_version_widens_its_csv_to_the_new_header() {
        let dir = std::env::temp_dir().join(format!("mdrlat-reopen-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join("eval.csv");
        let old = "step,eval_reward_mean,eval_reward_std,eval_length_mean\n\
                   5000,1.0,0.5,10.00\n10000,2.0,0.5,20.00\n15000,3.0,0.5,30.00\n";
        std::fs::write(&path, old).expect("write");
        let mut csv = reopen(path.clone(), EVAL_HEADER, 10_000, true).expect("reopen");
        csv.line("15000,4.0,0.5,40.00,0.200000,0.800000,0.1,0.2,3.0,0.1,0.2,3.0").expect("append");
        csv.flush().expect("flush");
        let text = std::fs::read_to_string(&path).expect("read");
        assert_eq!(
            text,
            format!(
                "{EVAL_HEADER}\n5000,1.0,0.5,10.00,,,,,,,,\n10000,2.0,0.5,20.00,,,,,,,,\n15000,4.0,0.5,40.00,0.200000,0.800000,0.1,0.2,3.0,0.1,0.2,3.0\n"
            )
        );
        for line in text.lines() {
            assert_eq!(line.split(',').count(), 12, "{line}");
        }
        // A file with the current header is kept as it is.
        let mut csv = reopen(path.clone(), EVAL_HEADER, 20_000, true).expect("reopen");
        csv.flush().expect("flush");
        assert_eq!(std::fs::read_to_string(&path).expect("read"), text);
        // One whose columns are not this version's (a newer one's) is an error, not a mix.
        std::fs::write(&path, format!("{EVAL_HEADER},future_column\n5000{}\n", ",1".repeat(12)))
            .expect("write");
        let e = reopen(path.clone(), EVAL_HEADER, 5000, true).map(|_| ()).expect_err("newer");
        assert!(e.to_string().contains("future_column"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
