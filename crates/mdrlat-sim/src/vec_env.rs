//! N environments stepped in parallel on a thread pool, with auto-reset.
//!
//! When an episode ends, its environment is reset at once (continuing its own random
//! stream) and the true final observation is kept in [`VecEnv::final_observation`] for
//! the replay buffer, as CleanRL and SB3 do. Keeping it costs a pointer swap, not a copy.

use crate::config::SimConfig;
use crate::env::{Env, Observation, SimError, StepInfo};
use crate::scene::StaticScene;
use mdrlat_core::Action;
use rayon::prelude::*;
use std::sync::Arc;

/// The outcome of one environment's step in a [`VecEnv`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VecStep {
    /// Paper eq. (3).
    pub reward: f32,
    /// A collision ended the episode.
    pub terminated: bool,
    /// The time limit ended the episode.
    pub truncated: bool,
    /// Diagnostics of the step (pose etc. before any auto-reset).
    pub info: StepInfo,
}

/// A vector of environments over one shared scene.
#[derive(Debug)]
pub struct VecEnv {
    envs: Vec<Env>,
    finals: Vec<Observation>,
    outcomes: Vec<VecStep>,
    pool: rayon::ThreadPool,
}

impl VecEnv {
    /// `n` environments over `scene`, stepped on `threads` threads (0: all cores).
    ///
    /// # Errors
    /// An invalid configuration.
    ///
    /// # Panics
    /// If the thread pool cannot be created (the OS refused threads).
    pub fn new(
        scene: Arc<StaticScene>,
        config: SimConfig,
        n: usize,
        threads: usize,
    ) -> Result<Self, SimError> {
        let envs = (0..n)
            .map(|_| Env::new(scene.clone(), config.clone()))
            .collect::<Result<Vec<_>, _>>()?;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("cannot create the VecEnv thread pool");
        Ok(Self {
            finals: (0..n).map(|_| Observation::zeros()).collect(),
            outcomes: Vec::with_capacity(n),
            envs,
            pool,
        })
    }

    /// Number of environments.
    pub fn len(&self) -> usize {
        self.envs.len()
    }

    /// True with no environments.
    pub fn is_empty(&self) -> bool {
        self.envs.is_empty()
    }

    /// Threads stepping the environments.
    pub fn threads(&self) -> usize {
        self.pool.current_num_threads()
    }

    /// Resets every environment; environment `i` is seeded with `seed + i`.
    ///
    /// # Errors
    /// An environment found no free start pose.
    pub fn reset(&mut self, seed: u64) -> Result<(), SimError> {
        let envs = &mut self.envs;
        self.pool.install(|| {
            envs.par_iter_mut()
                .enumerate()
                .try_for_each(|(i, env)| env.reset(Some(seed.wrapping_add(i as u64))).map(|_| ()))
        })
    }

    /// Steps every environment with its action; finished episodes are reset at once.
    ///
    /// # Errors
    /// Wrong number of actions, or a reset found no free pose.
    pub fn step(&mut self, actions: &[Action]) -> Result<&[VecStep], SimError> {
        if actions.len() != self.envs.len() {
            return Err(SimError::ActionCount { expected: self.envs.len(), got: actions.len() });
        }
        let (envs, finals) = (&mut self.envs, &mut self.finals);
        let results: Result<Vec<VecStep>, SimError> = self.pool.install(|| {
            envs.par_iter_mut()
                .zip(finals.par_iter_mut())
                .zip(actions.par_iter())
                .map(|((env, fin), &a)| {
                    let s = env.step(a)?;
                    let out = VecStep {
                        reward: s.reward,
                        terminated: s.terminated,
                        truncated: s.truncated,
                        info: s.info,
                    };
                    if out.terminated || out.truncated {
                        env.swap_observation(fin);
                        env.reset(None)?;
                    }
                    Ok(out)
                })
                .collect()
        });
        self.outcomes = results?;
        Ok(&self.outcomes)
    }

    /// The current observation of environment `i` (after any auto-reset).
    pub fn observation(&self, i: usize) -> &Observation {
        self.envs[i].observation()
    }

    /// The true last observation of environment `i`'s episode if the last step ended it.
    pub fn final_observation(&self, i: usize) -> Option<&Observation> {
        let o = self.outcomes.get(i)?;
        (o.terminated || o.truncated).then_some(&self.finals[i])
    }

    /// The environments.
    pub fn envs(&self) -> &[Env] {
        &self.envs
    }
}
