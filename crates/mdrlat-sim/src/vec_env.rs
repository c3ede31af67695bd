//! N environments stepped in parallel on a thread pool, with auto-reset.
//!
//! When an episode ends, its environment is reset at once (continuing its own random
//! stream) and the true final observation is kept in [`VecEnv::final_observation`] for
//! the replay buffer, as CleanRL and SB3 do. Keeping it costs a pointer swap, not a copy.
//! The calling thread steps a share of the environments itself (see [`VecEnv::step`]).

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
    /// Threads stepping environments, the caller's included.
    threads: usize,
    /// The `threads − 1` helpers; `None` when stepping on the caller alone.
    pool: Option<rayon::ThreadPool>,
}

/// Steps a contiguous chunk of environments on the current thread.
fn step_chunk(
    envs: &mut [Env],
    finals: &mut [Observation],
    actions: &[Action],
    out: &mut [Option<Result<VecStep, SimError>>],
) {
    for (((env, fin), &a), o) in envs.iter_mut().zip(finals).zip(actions).zip(out) {
        let stepped = env.step(a).map(|s| VecStep {
            reward: s.reward,
            terminated: s.terminated,
            truncated: s.truncated,
            info: s.info,
        });
        *o = Some(stepped.and_then(|step| {
            if step.terminated || step.truncated {
                env.swap_observation(fin);
                env.reset(None)?;
            }
            Ok(step)
        }));
    }
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
        let threads = if threads == 0 {
            std::thread::available_parallelism().map_or(1, |t| t.get())
        } else {
            threads
        };
        let pool = (threads > 1).then(|| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads - 1)
                .thread_name(|i| format!("mdrlat-venv-{i}"))
                .build()
                .expect("cannot create the VecEnv thread pool")
        });
        Ok(Self {
            finals: (0..n).map(|_| Observation::zeros()).collect(),
            outcomes: Vec::with_capacity(n),
            envs,
            threads,
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
        self.threads
    }

    /// Resets every environment; environment `i` is seeded with `seed + i`.
    ///
    /// # Errors
    /// An environment found no free start pose.
    pub fn reset(&mut self, seed: u64) -> Result<(), SimError> {
        let envs = &mut self.envs;
        let mut reset_all = || {
            envs.par_iter_mut()
                .enumerate()
                .try_for_each(|(i, env)| env.reset(Some(seed.wrapping_add(i as u64))).map(|_| ()))
        };
        match &self.pool {
            Some(pool) => pool.install(reset_all),
            None => reset_all(),
        }
    }

    /// Steps every environment with its action; finished episodes are reset at once.
    ///
    /// The environments are split into one contiguous chunk per thread; the calling thread
    /// steps the first chunk itself while the pool's threads step the others, so a step
    /// costs no hand-off to a sleeping thread and one thread costs nothing at all.
    ///
    /// # Errors
    /// Wrong number of actions, or a reset found no free pose.
    pub fn step(&mut self, actions: &[Action]) -> Result<&[VecStep], SimError> {
        let n = self.envs.len();
        if actions.len() != n {
            return Err(SimError::ActionCount { expected: n, got: actions.len() });
        }
        let mut results: Vec<Option<Result<VecStep, SimError>>> = (0..n).map(|_| None).collect();
        let chunks = self.threads.min(n).max(1);
        let bounds: Vec<usize> = (0..=chunks).map(|k| k * n / chunks).collect();
        let mut envs: &mut [Env] = &mut self.envs;
        let mut finals: &mut [Observation] = &mut self.finals;
        let mut outs: &mut [Option<Result<VecStep, SimError>>] = &mut results;
        let mut parts = Vec::with_capacity(chunks);
        for k in 0..chunks {
            let len = bounds[k + 1] - bounds[k];
            let (e, e_rest) = std::mem::take(&mut envs).split_at_mut(len);
            let (f, f_rest) = std::mem::take(&mut finals).split_at_mut(len);
            let (o, o_rest) = std::mem::take(&mut outs).split_at_mut(len);
            (envs, finals, outs) = (e_rest, f_rest, o_rest);
            parts.push((e, f, &actions[bounds[k]..bounds[k + 1]], o));
        }
        let mut parts = parts.into_iter();
        let first = parts.next();
        match &self.pool {
            Some(pool) => pool.in_place_scope(|scope| {
                for (e, f, a, o) in parts {
                    scope.spawn(move |_| step_chunk(e, f, a, o));
                }
                if let Some((e, f, a, o)) = first {
                    step_chunk(e, f, a, o);
                }
            }),
            None => {
                if let Some((e, f, a, o)) = first {
                    step_chunk(e, f, a, o);
                }
            }
        }
        self.outcomes.clear();
        for r in results {
            self.outcomes.push(r.unwrap_or(Err(SimError::NeedsReset))?);
        }
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
