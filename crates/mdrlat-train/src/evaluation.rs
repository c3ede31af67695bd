//! Greedy evaluations during training: Fig. 4's accumulated reward from fixed starts of the
//! training world, and the learning curves by the evaluation protocol (`mdrlat eval`'s).

use crate::config::TrainConfig;
use crate::error::TrainError;
use crate::learner::Learner;
use mdrlat_core::PolicyError;
use mdrlat_sim::{EpisodeSpec, Quiet, RunOptions, SimConfig, VecEnv, run_episodes};
use mdrlat_world::World;
use serde::Serialize;

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
