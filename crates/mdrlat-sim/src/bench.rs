//! Measuring simulator throughput: environment steps per second with full sensors.

use crate::config::SimConfig;
use crate::env::{Env, SimError};
use crate::scene::StaticScene;
use crate::vec_env::VecEnv;
use mdrlat_core::{Action, Rng};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// One throughput measurement.
#[derive(Debug, Clone, PartialEq)]
pub struct Throughput {
    /// World name.
    pub world: String,
    /// Environments stepped.
    pub envs: usize,
    /// Threads stepping them.
    pub threads: usize,
    /// Environment steps taken (summed over environments).
    pub steps: u64,
    /// Wall time, seconds.
    pub seconds: f64,
}

impl Throughput {
    /// Environment steps per second.
    pub fn steps_per_s(&self) -> f64 {
        self.steps as f64 / self.seconds
    }
}

/// Steps one environment with random actions for at least `min_time`, resetting on episode
/// ends (resets are counted in the time).
///
/// # Errors
/// A reset found no free pose.
pub fn one_env(
    scene: Arc<StaticScene>,
    config: &SimConfig,
    min_time: Duration,
) -> Result<Throughput, SimError> {
    let mut env = Env::new(scene.clone(), config.clone())?;
    let mut rng = Rng::seed_from_u64(1);
    env.reset(Some(0))?;
    let start = Instant::now();
    let mut steps = 0u64;
    while start.elapsed() < min_time {
        for _ in 0..100 {
            let a = Action::new(rng.below(Action::COUNT)).unwrap_or_else(|| unreachable!());
            let s = env.step(a)?;
            if s.terminated || s.truncated {
                env.reset(None)?;
            }
        }
        steps += 100;
    }
    Ok(Throughput {
        world: scene.world.name.clone(),
        envs: 1,
        threads: 1,
        steps,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Steps a [`VecEnv`] of `envs` environments on `threads` threads (0: all cores) with random
/// actions for at least `min_time` (auto-resets included).
///
/// # Errors
/// A reset found no free pose.
pub fn vec_env(
    scene: Arc<StaticScene>,
    config: &SimConfig,
    envs: usize,
    threads: usize,
    min_time: Duration,
) -> Result<Throughput, SimError> {
    let world = scene.world.name.clone();
    let mut venv = VecEnv::new(scene, config.clone(), envs, threads)?;
    venv.reset(0)?;
    let mut rng = Rng::seed_from_u64(1);
    let mut actions = vec![Action::new(0).unwrap_or_else(|| unreachable!()); envs];
    let start = Instant::now();
    let mut steps = 0u64;
    while start.elapsed() < min_time {
        for _ in 0..10 {
            for a in actions.iter_mut() {
                *a = Action::new(rng.below(Action::COUNT)).unwrap_or_else(|| unreachable!());
            }
            venv.step(&actions)?;
            steps += envs as u64;
        }
    }
    Ok(Throughput {
        world,
        envs,
        threads: venv.threads(),
        steps,
        seconds: start.elapsed().as_secs_f64(),
    })
}
