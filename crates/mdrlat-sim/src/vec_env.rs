//! N environments stepped in parallel, with auto-reset.
//!
//! When an episode ends, its environment is reset at once (continuing its own random
//! stream) and the true final observation is kept in [`VecEnv::final_observation`] for
//! the replay buffer, as CleanRL and SB3 do. Keeping it costs a buffer swap, not a copy.
//!
//! The environments are split into one contiguous chunk per thread. The calling thread
//! steps chunk 0 itself; each other chunk belongs to a dedicated worker thread that waits
//! for the next step by spinning briefly, then yielding, then parking. A general-purpose
//! pool (rayon) puts its threads to sleep between steps, and waking a thread on a virtual
//! machine costs about as much as stepping an environment (`docs/performance.md`).

use crate::config::SimConfig;
use crate::env::{Env, Observation, SimError, StepInfo};
use crate::scene::StaticScene;
use mdrlat_core::{Action, Velocity};
use mdrlat_geom::Pose2;
use std::ops::Deref;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How long a worker spins for the next step before yielding, then parking.
const SPIN: Duration = Duration::from_micros(300);
/// How long it then yields before parking.
const YIELD: Duration = Duration::from_micros(500);

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

/// One thread's share of the environments, with its inputs and outputs.
#[derive(Debug)]
struct Chunk {
    envs: Vec<Env>,
    finals: Vec<Observation>,
    /// Per environment: the velocity command of the next step (`None`: it sits this step
    /// out); an action steps with its Table 1 velocity, exactly as `Env::step` does.
    commands: Vec<Option<Velocity>>,
    /// Per environment: the last step's outcome (`None`: it was not stepped).
    results: Vec<Result<Option<VecStep>, SimError>>,
    /// A reset request: environment `first + i` takes stream `first + i` of the seed.
    reset_seed: Option<u64>,
    first: usize,
    /// Finished episodes restart at once (else they wait for [`VecEnv::reset_env`]).
    auto_reset: bool,
    /// Called after each environment's step during [`VecEnv::step_into`] (and only then).
    visit: Option<VisitPtr>,
}

/// What [`VecEnv::step_into`] runs on an environment's own thread after its step: the
/// environment's index, the step, the episode's final observation if the step ended it, and
/// the current observation (after any auto-reset).
type Visit<'a> = dyn Fn(usize, &VecStep, Option<&Observation>, &Observation) + Sync + 'a;

/// A [`Visit`] borrowed for one [`VecEnv::step_into`] call, its lifetime erased so that the
/// long-lived workers can hold it (see the SAFETY argument there).
#[derive(Debug, Clone, Copy)]
struct VisitPtr(*const Visit<'static>);

/// What [`VecEnv::step_into`] calls to fill an environment's slot: the slot, the step, the
/// episode's final observation if the step ended it, the current observation.
pub type SlotWriter<'a, T> =
    dyn Fn(&mut T, &VecStep, Option<&Observation>, &Observation) + Sync + 'a;

/// The slots of one [`VecEnv::step_into`] call, shared with the threads that fill them.
struct SlotsPtr<T>(*mut T);

// SAFETY: each thread writes only its own environments' slots (see `step_into`), and `T` is
// `Send`, so handing the slots to other threads is sound.
#[allow(unsafe_code)]
unsafe impl<T: Send> Sync for SlotsPtr<T> {}

// SAFETY: the pointee is `Sync` (the `Visit` bound), so calling it from any thread is sound;
// `step_into` keeps it alive while any thread can reach it.
#[allow(unsafe_code)]
unsafe impl Send for VisitPtr {}

impl Chunk {
    /// Runs the pending reset or step on the current thread.
    fn run(&mut self) {
        if let Some(seed) = self.reset_seed.take() {
            for (i, (env, r)) in self.envs.iter_mut().zip(&mut self.results).enumerate() {
                *r = env.reset_stream(seed, (self.first + i) as u64).map(|_| None);
            }
            return;
        }
        let auto_reset = self.auto_reset;
        let it =
            self.envs.iter_mut().zip(&mut self.finals).zip(&self.commands).zip(&mut self.results);
        for (k, (((env, fin), &c), out)) in it.enumerate() {
            let Some(c) = c else {
                *out = Ok(None);
                continue;
            };
            let stepped = env.step_command(c).map(|s| VecStep {
                reward: s.reward,
                terminated: s.terminated,
                truncated: s.truncated,
                info: s.info,
            });
            *out = stepped.and_then(|step| {
                let ended = step.terminated || step.truncated;
                if auto_reset && ended {
                    env.swap_observation(fin);
                    env.reset(None)?;
                }
                if let Some(VisitPtr(visit)) = self.visit {
                    // SAFETY: `step_into` set the pointer from a reference that outlives this
                    // call: `step_visiting` clears it only after every chunk has finished.
                    #[allow(unsafe_code)]
                    let visit = unsafe { &*visit };
                    let last = match (ended, auto_reset) {
                        (false, _) => None,
                        (true, true) => Some(&*fin),
                        (true, false) => Some(env.observation()),
                    };
                    visit(self.first + k, &step, last, env.observation());
                }
                Ok(Some(step))
            });
        }
    }
}

fn lock(chunk: &Mutex<Chunk>) -> MutexGuard<'_, Chunk> {
    // A worker that panicked mid-step leaves the lock poisoned; its data is still readable
    // and `VecEnv::step` reports the dead worker as an error.
    chunk.lock().unwrap_or_else(|p| p.into_inner())
}

/// Signals shared by the caller and the workers.
#[derive(Debug, Default)]
struct Control {
    /// Bumped once per step or reset; workers run when it changes.
    epoch: AtomicU64,
    /// Workers finished with the current epoch.
    done: AtomicUsize,
    stop: AtomicBool,
    /// A worker died: every later call fails.
    dead: AtomicBool,
}

#[derive(Debug)]
struct Worker {
    handle: JoinHandle<()>,
}

fn worker_loop(control: Arc<Control>, chunk: Arc<Mutex<Chunk>>) {
    let mut seen = 0u64;
    loop {
        let started = Instant::now();
        let mut spins = 0u32;
        let mut waited = Duration::ZERO;
        loop {
            if control.stop.load(Ordering::Acquire) {
                return;
            }
            let e = control.epoch.load(Ordering::Acquire);
            if e != seen {
                seen = e;
                break;
            }
            spins = spins.wrapping_add(1);
            if spins.is_multiple_of(64) {
                waited = started.elapsed();
            }
            if waited < SPIN {
                std::hint::spin_loop();
            } else if waited < SPIN + YIELD {
                std::thread::yield_now();
            } else {
                std::thread::park_timeout(Duration::from_millis(10));
            }
        }
        // A panic is caught so that `done` is always counted: `run_all` waits for every
        // worker (`step_into` relies on it), and the dead flag fails every later call.
        let ran = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| lock(&chunk).run()));
        if ran.is_err() {
            control.dead.store(true, Ordering::Release);
        }
        control.done.fetch_add(1, Ordering::AcqRel);
        if ran.is_err() {
            return;
        }
    }
}

/// A vector of environments over one shared scene.
#[derive(Debug)]
pub struct VecEnv {
    /// Chunk 0 is stepped by the caller, chunk k > 0 by worker k − 1.
    chunks: Vec<Arc<Mutex<Chunk>>>,
    /// First environment index of each chunk, plus the total at the end.
    bounds: Vec<usize>,
    workers: Vec<Worker>,
    control: Arc<Control>,
    outcomes: Vec<VecStep>,
    masked: Vec<Option<VecStep>>,
    auto_reset: bool,
}

/// An observation inside a [`VecEnv`], borrowed for as long as this guard lives.
pub struct ObservationRef<'a> {
    chunk: MutexGuard<'a, Chunk>,
    index: usize,
    last: bool,
}

impl Deref for ObservationRef<'_> {
    type Target = Observation;
    fn deref(&self) -> &Observation {
        if self.last {
            &self.chunk.finals[self.index]
        } else {
            self.chunk.envs[self.index].observation()
        }
    }
}

/// An environment inside a [`VecEnv`], borrowed for as long as this guard lives.
pub struct EnvRef<'a> {
    chunk: MutexGuard<'a, Chunk>,
    index: usize,
}

impl Deref for EnvRef<'_> {
    type Target = Env;
    fn deref(&self) -> &Env {
        &self.chunk.envs[self.index]
    }
}

impl VecEnv {
    /// `n` environments over `scene`, stepped on `threads` threads (0: all cores), the
    /// calling thread included.
    ///
    /// # Errors
    /// An invalid configuration.
    ///
    /// # Panics
    /// If the OS refuses to start a worker thread.
    pub fn new(
        scene: Arc<StaticScene>,
        config: SimConfig,
        n: usize,
        threads: usize,
    ) -> Result<Self, SimError> {
        let threads = if threads == 0 {
            std::thread::available_parallelism().map_or(1, |t| t.get())
        } else {
            threads
        };
        let parts = threads.clamp(1, n.max(1));
        let bounds: Vec<usize> = (0..=parts).map(|k| k * n / parts).collect();
        let mut chunks = Vec::with_capacity(parts);
        for k in 0..parts {
            let len = bounds[k + 1] - bounds[k];
            let envs = (0..len)
                .map(|_| Env::new(scene.clone(), config.clone()))
                .collect::<Result<Vec<_>, _>>()?;
            chunks.push(Arc::new(Mutex::new(Chunk {
                envs,
                finals: (0..len).map(|_| Observation::zeros()).collect(),
                commands: Vec::with_capacity(len),
                results: (0..len).map(|_| Err(SimError::NeedsReset)).collect(),
                reset_seed: None,
                first: bounds[k],
                auto_reset: true,
                visit: None,
            })));
        }
        let control = Arc::new(Control::default());
        let workers = chunks[1..]
            .iter()
            .enumerate()
            .map(|(k, chunk)| {
                let (control, chunk) = (control.clone(), chunk.clone());
                let handle = std::thread::Builder::new()
                    .name(format!("mdrlat-venv-{}", k + 1))
                    .spawn(move || worker_loop(control, chunk))
                    .expect("cannot start a VecEnv worker thread");
                Worker { handle }
            })
            .collect();
        Ok(Self {
            chunks,
            bounds,
            workers,
            control,
            outcomes: Vec::with_capacity(n),
            masked: Vec::with_capacity(n),
            auto_reset: true,
        })
    }

    /// Whether finished episodes restart at once (the default, for training) or wait, with
    /// their final observation in place, for [`VecEnv::reset_env`] (the episode runner's
    /// mode: it decides which episode an environment runs next).
    pub fn auto_reset(&self) -> bool {
        self.auto_reset
    }

    /// Sets the mode [`VecEnv::auto_reset`] reports: whether finished episodes restart at
    /// once or wait for [`VecEnv::reset_env`].
    pub fn set_auto_reset(&mut self, on: bool) {
        self.auto_reset = on;
        for c in &self.chunks {
            lock(c).auto_reset = on;
        }
    }

    /// Number of environments.
    pub fn len(&self) -> usize {
        self.bounds[self.bounds.len() - 1]
    }

    /// True with no environments.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Threads stepping the environments, the caller's included.
    pub fn threads(&self) -> usize {
        self.chunks.len()
    }

    /// Runs chunk 0 here and the others on their workers; waits for all.
    fn run_all(&mut self) -> Result<(), SimError> {
        if self.control.dead.load(Ordering::Acquire) {
            return Err(SimError::WorkerDied);
        }
        self.control.done.store(0, Ordering::Release);
        self.control.epoch.fetch_add(1, Ordering::AcqRel);
        for w in &self.workers {
            w.handle.thread().unpark();
        }
        // A panic here is held until the workers are done: they may be using what
        // `step_into` lent them, which unwinding would free.
        let here = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            lock(&self.chunks[0]).run();
        }));
        // Every worker counts itself done, even after a panic (`worker_loop`), so this waits
        // for all of them: none is still running this epoch when it returns.
        let mut spins = 0u32;
        while self.control.done.load(Ordering::Acquire) < self.workers.len() {
            spins = spins.wrapping_add(1);
            if spins.is_multiple_of(1024) {
                std::thread::yield_now();
            } else {
                std::hint::spin_loop();
            }
        }
        if let Err(panic) = here {
            std::panic::resume_unwind(panic);
        }
        if self.control.dead.load(Ordering::Acquire) {
            return Err(SimError::WorkerDied);
        }
        Ok(())
    }

    /// Resets every environment; environment `i` takes random stream `i` of `seed` (see
    /// [`Env::reset_stream`]), so runs with neighbouring seeds share no random numbers.
    ///
    /// # Errors
    /// An environment found no free start pose.
    pub fn reset(&mut self, seed: u64) -> Result<(), SimError> {
        for c in &self.chunks {
            lock(c).reset_seed = Some(seed);
        }
        self.run_all()?;
        self.outcomes.clear();
        for c in &self.chunks {
            for r in &lock(c).results {
                if let Err(e) = r {
                    return Err(e.clone());
                }
            }
        }
        Ok(())
    }

    /// Steps every environment with its action; finished episodes are reset at once.
    ///
    /// # Errors
    /// Wrong number of actions, a step before `reset`, or a reset that found no free pose.
    pub fn step(&mut self, actions: &[Action]) -> Result<&[VecStep], SimError> {
        self.step_visiting(actions, None)
    }

    /// [`VecEnv::step`] with `visit` called after each environment's step.
    fn step_visiting(
        &mut self,
        actions: &[Action],
        visit: Option<VisitPtr>,
    ) -> Result<&[VecStep], SimError> {
        if actions.len() != self.len() {
            return Err(SimError::ActionCount { expected: self.len(), got: actions.len() });
        }
        for c in &self.chunks {
            lock(c).visit = visit;
        }
        // `run_all` returns only once every thread has finished its chunk (workers count
        // themselves done even when they panic), and chunks run only inside it: after this
        // no thread can reach `visit` any more.
        let ran = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            self.run_commands(actions.iter().map(|&a| Some(a.command())))
        }));
        // Cleared on every path, a panic included: a later call must not find it.
        for c in &self.chunks {
            lock(c).visit = None;
        }
        ran.unwrap_or_else(|panic| std::panic::resume_unwind(panic))?;
        self.outcomes.clear();
        for c in &self.chunks {
            for r in &lock(c).results {
                self.outcomes.push(r.clone()?.ok_or(SimError::NeedsReset)?);
            }
        }
        Ok(&self.outcomes)
    }

    /// [`VecEnv::step`], and on each environment's own thread right after its step (and any
    /// auto-reset) `write(&mut outs[i], step, final, current)`: `final` the episode's last
    /// observation if the step ended it, `current` the observation the next action sees.
    /// The writes run in parallel, each while the frames it reads are still in its core's
    /// cache — how the Python bindings fill numpy buffers without a serial copy afterwards.
    ///
    /// # Errors
    /// As [`VecEnv::step`].
    ///
    /// # Panics
    /// If `outs` does not hold one slot per environment.
    pub fn step_into<T: Send>(
        &mut self,
        actions: &[Action],
        outs: &mut [T],
        write: &SlotWriter<'_, T>,
    ) -> Result<&[VecStep], SimError> {
        assert_eq!(outs.len(), self.len(), "step_into: one slot per environment");
        let slots = SlotsPtr(outs.as_mut_ptr());
        let visit = move |i: usize, s: &VecStep, last: Option<&Observation>, now: &Observation| {
            let slots = &slots;
            // SAFETY: `i < outs.len()` (asserted above), and each environment is stepped by
            // exactly one thread, once, per call: no slot is reached twice, so the `&mut`
            // references are disjoint; `outs` stays mutably borrowed for the whole call.
            #[allow(unsafe_code)]
            let slot = unsafe { &mut *slots.0.add(i) };
            write(slot, s, last, now);
        };
        let visit: &Visit<'_> = &visit;
        // SAFETY: only the lifetime is erased; `step_visiting` clears every copy of the
        // pointer before it returns, and no thread runs a chunk after that (see there), so
        // the closure outlives every use.
        #[allow(unsafe_code)]
        let ptr = VisitPtr(unsafe {
            std::mem::transmute::<*const Visit<'_>, *const Visit<'static>>(visit)
        });
        self.step_visiting(actions, Some(ptr))
    }

    /// Steps the environments whose action is `Some`; the others sit this step out (their
    /// outcome is `None`). Finished episodes restart only with auto-reset on.
    ///
    /// # Errors
    /// Wrong number of actions, or a step of an environment whose episode has ended.
    pub fn step_masked(
        &mut self,
        actions: &[Option<Action>],
    ) -> Result<&[Option<VecStep>], SimError> {
        if actions.len() != self.len() {
            return Err(SimError::ActionCount { expected: self.len(), got: actions.len() });
        }
        self.run_commands(actions.iter().map(|a| a.map(Action::command)))?;
        self.masked_outcomes()
    }

    /// [`VecEnv::step_masked`] with velocity commands (`Env::step_command`), as a continuous
    /// controller drives the robot.
    ///
    /// # Errors
    /// Wrong number of commands, or a step of an environment whose episode has ended.
    pub fn step_masked_commands(
        &mut self,
        commands: &[Option<Velocity>],
    ) -> Result<&[Option<VecStep>], SimError> {
        if commands.len() != self.len() {
            return Err(SimError::ActionCount { expected: self.len(), got: commands.len() });
        }
        self.run_commands(commands.iter().copied())?;
        self.masked_outcomes()
    }

    /// The outcomes of the last masked step, in order.
    fn masked_outcomes(&mut self) -> Result<&[Option<VecStep>], SimError> {
        self.masked.clear();
        self.outcomes.clear();
        for c in &self.chunks {
            for r in &lock(c).results {
                self.masked.push(r.clone()?);
            }
        }
        Ok(&self.masked)
    }

    fn run_commands(
        &mut self,
        commands: impl Iterator<Item = Option<Velocity>>,
    ) -> Result<(), SimError> {
        let mut commands = commands;
        for (k, c) in self.chunks.iter().enumerate() {
            let mut c = lock(c);
            c.commands.clear();
            c.commands.extend(commands.by_ref().take(self.bounds[k + 1] - self.bounds[k]));
        }
        self.run_all()
    }

    /// Starts a new episode in environment `i` alone, on the calling thread, as
    /// [`Env::reset_with`] does: `Some(seed)` reseeds its streams (stream 0 of `seed`: the
    /// same start as `Env::reset(Some(seed))`), `pose` fixes the start.
    ///
    /// # Errors
    /// `pose` is not finite or lies outside the world ([`SimError::BadPose`]); no
    /// collision-free pose could be drawn.
    ///
    /// # Panics
    /// If `i >= len()`.
    pub fn reset_env(
        &mut self,
        i: usize,
        seed: Option<u64>,
        pose: Option<Pose2>,
    ) -> Result<(), SimError> {
        let (k, index) = self.locate(i);
        let mut chunk = lock(&self.chunks[k]);
        chunk.envs[index].reset_with(seed, pose)?;
        chunk.results[index] = Ok(None);
        Ok(())
    }

    /// Calls `f` with the current observation of every environment, in order (one lock per
    /// thread's share, held while `f` runs): a batched policy reads them all at once.
    pub fn with_observations<R>(&self, f: impl FnOnce(&[&Observation]) -> R) -> R {
        let guards: Vec<MutexGuard<'_, Chunk>> = self.chunks.iter().map(|c| lock(c)).collect();
        let obs: Vec<&Observation> =
            guards.iter().flat_map(|g| g.envs.iter().map(Env::observation)).collect();
        f(&obs)
    }

    /// Environment `i` itself (to draw it, or read its pedestrians), borrowed for as long as
    /// the guard lives.
    ///
    /// # Panics
    /// If `i >= len()`.
    pub fn env(&self, i: usize) -> EnvRef<'_> {
        let (k, index) = self.locate(i);
        EnvRef { chunk: lock(&self.chunks[k]), index }
    }

    fn locate(&self, i: usize) -> (usize, usize) {
        assert!(i < self.len(), "environment {i} out of range (have {})", self.len());
        let k = self.bounds.partition_point(|&b| b <= i) - 1;
        (k, i - self.bounds[k])
    }

    /// The current observation of environment `i` (after any auto-reset).
    ///
    /// # Panics
    /// If `i >= len()`.
    pub fn observation(&self, i: usize) -> ObservationRef<'_> {
        let (k, index) = self.locate(i);
        ObservationRef { chunk: lock(&self.chunks[k]), index, last: false }
    }

    /// The true last observation of environment `i`'s episode if the last step ended it.
    ///
    /// # Panics
    /// If `i >= len()`.
    pub fn final_observation(&self, i: usize) -> Option<ObservationRef<'_>> {
        let o = self.outcomes.get(i)?;
        let (k, index) = self.locate(i);
        // Without auto-reset the final observation is still the environment's own.
        (o.terminated || o.truncated).then(|| ObservationRef {
            chunk: lock(&self.chunks[k]),
            index,
            last: self.auto_reset,
        })
    }
}

impl Drop for VecEnv {
    fn drop(&mut self) {
        self.control.stop.store(true, Ordering::Release);
        for w in self.workers.drain(..) {
            w.handle.thread().unpark();
            let _ = w.handle.join();
        }
    }
}
