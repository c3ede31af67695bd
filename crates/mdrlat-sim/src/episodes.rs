//! The one episode runner: a list of episodes, a [`VecEnv`] and a [`Policy`] in, one
//! outcome per episode out.
//!
//! As Stable-Baselines3's `evaluate_policy`, episodes are dealt to the vector's
//! environments ("slots"): each slot runs an episode, and when it ends takes the next one
//! not yet started; every step, one batched call of the policy decides for all running
//! slots. An episode's start comes from its own seed, the policy restarts any randomness
//! from that seed too ([`Policy::begin_episode`]), and results are returned in the order of
//! the list — so an episode's outcome never depends on how many slots there are or which
//! episodes ran beside it (for a policy whose decision for one observation does not depend
//! on the rest of the batch). Training's evaluation (Fig. 4), `mdrlat rollout`,
//! `mdrlat eval` and the tests all run episodes through [`run_episodes`].

use crate::env::{Collision, Env, Observation, SimError};
use crate::rollout::TrajectoryRow;
use crate::vec_env::VecEnv;
use mdrlat_core::{Action, Decision, Policy, PolicyError, Velocity};
use mdrlat_geom::{Pose2, Vec2};

/// One episode to run.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EpisodeSpec {
    /// Its seed: `Some` reseeds the environment (start pose, pedestrians, noise: stream 0 of
    /// the seed, as `Env::reset(Some(seed))`) and the policy's randomness; `None` continues
    /// the streams of the slot's previous episode.
    pub seed: Option<u64>,
    /// A fixed start pose (`None`: drawn from the spawn regions).
    pub pose: Option<Pose2>,
}

/// What happened in one episode.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeOutcome {
    /// The start pose.
    pub start: Pose2,
    /// Steps taken.
    pub steps: u32,
    /// Accumulated reward (paper eq. 3), summed in `f32` step by step.
    pub reward: f32,
    /// The collision that ended it, if one did.
    pub collision: Option<Collision>,
    /// The navigation task's goal (`None` in obstacle avoidance).
    pub goal: Option<Vec2>,
    /// The robot reached the goal (navigation).
    pub reached_goal: bool,
    /// The environment's time limit ended it (`max_episode_steps`).
    pub truncated: bool,
    /// Distance driven, metres (sum of the straight distances between step poses): the
    /// collision-free path, since an episode ends at its collision.
    pub path_m: f32,
    /// The farthest the robot got from its start at any step, metres.
    pub reach_m: f32,
    /// Every action taken, in order (a continuous controller's: the nearest Table 1 ones).
    pub actions: Vec<Action>,
    /// Every velocity command, in order: with the episode's seed they reproduce it exactly
    /// ([`crate::ReplayPolicy`]).
    pub commands: Vec<Velocity>,
    /// Every step, when [`RunOptions::record_rows`] asked for them.
    pub rows: Vec<TrajectoryRow>,
}

/// The one success rule: in obstacle avoidance (no goal) an episode without a collision
/// within its steps; in navigation one that reached its goal.
pub fn episode_success(
    goal: Option<Vec2>,
    reached_goal: bool,
    collision: Option<Collision>,
) -> bool {
    match goal {
        None => collision.is_none(),
        Some(_) => reached_goal,
    }
}

/// What an episode must show to count as a *moving* success, beyond the paper's rule: a
/// policy that turns in place or circles on the spot never collides, so the paper's success
/// ("no collision within 300 steps") counts it; the moving success does not.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MovingRule {
    /// Metres driven at least (`--min-path`).
    pub min_path_m: f32,
    /// Metres from the start at least, at some step (`--min-reach`).
    pub min_reach_m: f32,
}

impl MovingRule {
    /// The defaults: 5 m driven, 2 m from the start (a 300-step episode at the slow 0.2 m/s
    /// drives 12 m; turning in place drives 0 m, the tightest forward circle of Table 1
    /// reaches 0.76 m).
    pub const DEFAULT: MovingRule = MovingRule { min_path_m: 5.0, min_reach_m: 2.0 };

    /// Checks both thresholds (finite and not negative), naming the flag.
    ///
    /// # Errors
    /// The first bad threshold, as `--min-path -1: ...`.
    pub fn validate(&self) -> Result<(), String> {
        for (flag, v) in [("--min-path", self.min_path_m), ("--min-reach", self.min_reach_m)] {
            if !v.is_finite() || v < 0.0 {
                return Err(format!("{flag} {v}: must be a finite distance of 0 m or more"));
            }
        }
        Ok(())
    }
}

impl Default for MovingRule {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The moving success rule: [`episode_success`] *and*, in obstacle avoidance, at least
/// `rule.min_path_m` driven and at least `rule.min_reach_m` from the start at some step. In
/// navigation reaching the goal is already travel: the moving success is the success.
pub fn moving_success(
    goal: Option<Vec2>,
    reached_goal: bool,
    collision: Option<Collision>,
    path_m: f32,
    reach_m: f32,
    rule: &MovingRule,
) -> bool {
    episode_success(goal, reached_goal, collision)
        && (goal.is_some() || (path_m >= rule.min_path_m && reach_m >= rule.min_reach_m))
}

impl EpisodeOutcome {
    /// See [`episode_success`].
    pub fn success(&self) -> bool {
        episode_success(self.goal, self.reached_goal, self.collision)
    }

    /// See [`moving_success`].
    pub fn moving_success(&self, rule: &MovingRule) -> bool {
        moving_success(
            self.goal,
            self.reached_goal,
            self.collision,
            self.path_m,
            self.reach_m,
            rule,
        )
    }
}

/// How episodes run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunOptions {
    /// An episode stops after this many steps even if the environment's time limit is
    /// later (the evaluation protocol's 300).
    pub max_steps: u32,
    /// Keep every step's row in [`EpisodeOutcome::rows`].
    pub record_rows: bool,
}

impl Default for RunOptions {
    fn default() -> Self {
        Self { max_steps: u32::MAX, record_rows: false }
    }
}

/// Why running episodes stopped.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RunError {
    /// The simulator failed (e.g. no free start pose).
    #[error(transparent)]
    Sim(#[from] SimError),
    /// The policy could not decide (episode and slot named).
    #[error("policy '{policy}' in episode {episode}: {source}")]
    Policy {
        /// The policy's name.
        policy: String,
        /// An episode of the batch that failed (the first, in slot order).
        episode: usize,
        /// What went wrong.
        source: PolicyError,
    },
    /// The observer failed (e.g. a file could not be written).
    #[error("{0}")]
    Observer(Box<dyn std::error::Error + Send + Sync>),
    /// Episodes were given to a vector without environments.
    #[error("{0} episodes to run, but the vector has no environments")]
    NoEnvironments(usize),
}

/// Watches episodes as they run: progress bars, CSV rows, animation frames.
pub trait Observer {
    /// Whether [`Observer::on_step`] should be called (it costs a lock per step).
    fn wants_steps(&self) -> bool {
        false
    }
    /// After every step of episode `episode` (index in the list), with its environment.
    ///
    /// # Errors
    /// Any; running stops with [`RunError::Observer`].
    fn on_step(
        &mut self,
        episode: usize,
        env: &Env,
        row: &TrajectoryRow,
    ) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
        let _ = (episode, env, row);
        Ok(())
    }
    /// When episode `episode` has ended.
    fn on_episode(&mut self, episode: usize, outcome: &EpisodeOutcome) {
        let _ = (episode, outcome);
    }
}

/// An observer that watches nothing.
#[derive(Debug, Clone, Copy, Default)]
pub struct Quiet;

impl Observer for Quiet {}

/// A slot's running episode.
#[derive(Debug)]
struct Running {
    episode: usize,
    outcome: EpisodeOutcome,
    /// Pose after the last step (the start before the first), for the path length.
    last: Pose2,
    /// Path length in `f64`, stored rounded into the outcome at the end.
    path_m: f64,
}

/// Runs every episode of `specs` with `policy` on the environments of `venv` (all of them
/// slots; fewer episodes than slots leave the rest idle) and returns their outcomes in the
/// order of `specs`. With `max_steps` 0 an episode is reset and ends at once, without a
/// step. The vector's auto-reset mode is restored on return.
///
/// # Errors
/// A fixed start pose outside the world or not finite, a reset that found no free pose, a
/// policy that could not decide, or a failing observer.
pub fn run_episodes(
    venv: &mut VecEnv,
    policy: &mut dyn Policy,
    specs: &[EpisodeSpec],
    options: &RunOptions,
    observer: &mut dyn Observer,
) -> Result<Vec<EpisodeOutcome>, RunError> {
    let slots = venv.len();
    if slots == 0 && !specs.is_empty() {
        return Err(RunError::NoEnvironments(specs.len()));
    }
    let auto_reset = venv.auto_reset();
    venv.set_auto_reset(false);
    let result = run(venv, policy, specs, options, observer);
    venv.set_auto_reset(auto_reset);
    result
}

fn run(
    venv: &mut VecEnv,
    policy: &mut dyn Policy,
    specs: &[EpisodeSpec],
    options: &RunOptions,
    observer: &mut dyn Observer,
) -> Result<Vec<EpisodeOutcome>, RunError> {
    let slots = venv.len();
    let mut done: Vec<Option<EpisodeOutcome>> = (0..specs.len()).map(|_| None).collect();
    let mut running: Vec<Option<Running>> = (0..slots).map(|_| None).collect();
    let mut next = 0usize;
    let start = |venv: &mut VecEnv,
                 policy: &mut dyn Policy,
                 observer: &mut dyn Observer,
                 done: &mut Vec<Option<EpisodeOutcome>>,
                 slot: usize,
                 next: &mut usize|
     -> Result<Option<Running>, RunError> {
        loop {
            let Some(spec) = specs.get(*next) else { return Ok(None) };
            let started = start_one(venv, policy, spec, slot, *next)?;
            *next += 1;
            if options.max_steps > 0 {
                return Ok(Some(started));
            }
            // A zero step budget: the episode ends where it starts.
            observer.on_episode(started.episode, &started.outcome);
            done[started.episode] = Some(started.outcome);
        }
    };
    for (slot, r) in running.iter_mut().enumerate() {
        *r = start(venv, policy, observer, &mut done, slot, &mut next)?;
    }

    let (mut active, mut decisions) = (Vec::new(), Vec::new());
    let mut masked = vec![None; slots];
    loop {
        active.clear();
        active.extend(running.iter().enumerate().filter(|(_, r)| r.is_some()).map(|(i, _)| i));
        if active.is_empty() {
            break;
        }
        let decided = venv.with_observations(|obs| {
            let batch: Vec<&Observation> = active.iter().map(|&i| obs[i]).collect();
            policy.decide(&batch, &active, &mut decisions)
        });
        let first_episode = running[active[0]].as_ref().map_or(0, |r| r.episode);
        let policy_error =
            |source| RunError::Policy { policy: policy.name(), episode: first_episode, source };
        decided.map_err(policy_error)?;
        if decisions.len() != active.len() {
            return Err(policy_error(PolicyError::Count {
                expected: active.len(),
                got: decisions.len(),
            }));
        }
        masked.iter_mut().for_each(|m| *m = None);
        for (&slot, d) in active.iter().zip(&decisions) {
            masked[slot] = Some(d.command);
        }
        let stepped = venv.step_masked_commands(&masked)?.to_vec();
        for (&slot, &Decision { action, command }) in active.iter().zip(&decisions) {
            let Some(s) = stepped[slot] else { continue };
            let Some(r) = running[slot].as_mut() else { continue };
            r.path_m += f64::from((s.info.pose.position() - r.last.position()).length());
            r.last = s.info.pose;
            let o = &mut r.outcome;
            o.path_m = r.path_m as f32;
            o.reach_m = o.reach_m.max((s.info.pose.position() - o.start.position()).length());
            let row = TrajectoryRow {
                action,
                reward: s.reward,
                terminated: s.terminated,
                truncated: s.truncated,
                info: s.info,
            };
            o.steps += 1;
            o.reward += s.reward;
            o.actions.push(action);
            o.commands.push(command);
            o.collision = s.info.collision;
            o.reached_goal = s.info.reached_goal;
            o.truncated = s.truncated;
            if options.record_rows {
                o.rows.push(row);
            }
            if observer.wants_steps() {
                let env = venv.env(slot);
                observer.on_step(r.episode, &env, &row).map_err(RunError::Observer)?;
            }
            if s.terminated || s.truncated || o.steps >= options.max_steps {
                if let Some(finished) = running[slot].take() {
                    observer.on_episode(finished.episode, &finished.outcome);
                    done[finished.episode] = Some(finished.outcome);
                }
                running[slot] = start(venv, policy, observer, &mut done, slot, &mut next)?;
            }
        }
    }
    Ok(done.into_iter().map(|o| o.unwrap_or_else(|| unreachable!("every episode ran"))).collect())
}

/// Resets `slot` for episode `episode` of the list.
fn start_one(
    venv: &mut VecEnv,
    policy: &mut dyn Policy,
    spec: &EpisodeSpec,
    slot: usize,
    episode: usize,
) -> Result<Running, RunError> {
    venv.reset_env(slot, spec.seed, spec.pose)?;
    policy.begin_episode(slot, spec.seed);
    let pose = venv.env(slot).pose();
    let outcome = EpisodeOutcome {
        start: pose,
        steps: 0,
        reward: 0.0,
        collision: None,
        goal: venv.env(slot).goal(),
        reached_goal: false,
        truncated: false,
        path_m: 0.0,
        reach_m: 0.0,
        actions: Vec::new(),
        commands: Vec::new(),
        rows: Vec::new(),
    };
    Ok(Running { episode, outcome, last: pose, path_m: 0.0 })
}
