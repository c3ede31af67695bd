//! The training loop of paper Algorithm 1. It reads top to bottom like the algorithm;
//! `// Algorithm 1, line N` marks each step. The environments come in from the caller
//! ([`TrainEnvs`]), everything a run writes goes out through its [`RunDir`]: the metrics
//! through the [`MetricsSink`], the rest through [`checkpoint`].

use crate::checkpoint::{self, Window, frame_reserve};
use crate::collect::{Explorer, TrainEnvs};
use crate::config::{TrainConfig, TrainConfigError};
use crate::error::TrainError;
use crate::evaluation::{Evaluation, evaluate};
use crate::learner::{Learner, Losses};
use crate::replay::{Batch, ReplayBuffer};
use crate::run_dir::RunDir;
use crate::sink::{LOG_INTERVAL, MetricsSink};
use crate::timing::{Clock, Timing};
use mdrlat_nn::burn::prelude::Device;
use mdrlat_sim::VecEnv;
use mdrlat_sim::config::Task;
use mdrlat_world::World;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

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

/// The result of a run.
#[derive(Debug, Clone, PartialEq, Default)]
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
    /// The run was asked to stop ([`train_until`]) before `total_steps`: it wrote a
    /// checkpoint at `steps`, from which `--resume` continues exactly.
    pub stopped: bool,
}

/// Trains `config.variant` in `envs` (one environment per `train.envs`, freshly built: the
/// run starts or restores every one of them; their simulator settings are the run's) for
/// `config.total_steps` steps on `device`, into the run directory `dir`; with `resume`,
/// continues exactly from its checkpoint. `progress` is called after every step. Fig. 4's
/// evaluations and the learning curves' held-out starts are in the first world of `envs`.
///
/// # Errors
/// Invalid settings, a simulator failure, a missing or bad checkpoint, or a file that
/// cannot be written.
pub fn train(
    envs: TrainEnvs,
    config: &TrainConfig,
    device: &Device,
    dir: &RunDir,
    resume: bool,
    progress: impl FnMut(&Status),
) -> Result<(TrainReport, Learner), TrainError> {
    train_until(envs, config, device, dir, resume, progress, &AtomicBool::new(false))
}

/// [`train`], stopping early once `stop` is set (by a signal handler, say): the tick under
/// way finishes, a checkpoint is written at its step whatever `train.checkpoint_interval`
/// and `train.final_checkpoint` say, and the report says `stopped`. Nothing is lost: the
/// run resumes from there exactly as if it had not stopped.
///
/// # Errors
/// As [`train`].
pub fn train_until(
    mut envs: TrainEnvs,
    config: &TrainConfig,
    device: &Device,
    dir: &RunDir,
    resume: bool,
    mut progress: impl FnMut(&Status),
    stop: &AtomicBool,
) -> Result<(TrainReport, Learner), TrainError> {
    config.validate()?;
    if envs.len() != config.envs {
        let problem = format!("{}, but {} environments were given", config.envs, envs.len());
        return Err(TrainConfigError { field: "train.envs", problem }.into());
    }
    // The simulator's settings are the environments' own: evaluations and the
    // demonstrator use the same.
    let sim = &envs.sim().clone();
    let (task, started) = (sim.task, Instant::now());
    let curve_worlds = curve_worlds(config, task, &envs.first_scene().world)?;
    // One environment per evaluation episode, the network deciding for all at once.
    let eval_slots = config.eval_episodes.min(32) as usize;
    let mut eval_envs = VecEnv::new(envs.first_scene().clone(), sim.clone(), eval_slots, 1)?;

    // Algorithm 1, line 1: replay buffer D, online network θ, target θ⁻ = θ — or all of it,
    // with the environments and every random stream, from the checkpoint.
    let (mut learner, mut replay, mut run, mut sink) = if resume {
        let (run, mut learner, replay) = checkpoint::load(dir.path(), config, task, device)?;
        if run.depth_memory_frames != sim.laser.depth_memory_frames {
            return Err(TrainError::Checkpoint {
                path: dir.checkpoint().join("meta.json"),
                problem: format!(
                    "its network reads {}; the run's settings draw {} \
                     (sim.laser.depth_memory_frames)",
                    crate::learner::scan_name(run.depth_memory_frames as usize),
                    crate::learner::scan_name(sim.laser.depth_memory_frames as usize)
                ),
            });
        }
        learner.set_depth_memory_frames(sim.laser.depth_memory_frames);
        envs.restore(&run, &dir.checkpoint().join("meta.json"))?;
        let sink = MetricsSink::resume(dir, run.step, config.total_steps)?;
        (learner, replay, run, sink)
    } else {
        // A warm start's model is read first: a bad one stops the run before it writes.
        let mut learner = Learner::new(config, task, device);
        learner.set_depth_memory_frames(sim.laser.depth_memory_frames);
        if !config.init_from.is_empty() {
            learner.warm_start(config, sim)?;
        }
        let mut replay = empty_replay(config, task);
        envs.start(config.seed, &mut replay)?;
        let run = envs.fresh_meta(config, task);
        let sink = MetricsSink::create(dir)?;
        (learner, replay, run, sink)
    };
    // The training clock: the checkpoint's seconds (or its TensorBoard time, for one written
    // before the clock file), then this process's from here on.
    let trained_before = if resume {
        trained_seconds_at(dir, run.step, config.snapshot_minutes > 0.0)?
    } else {
        0.0
    };
    let clock_start = Instant::now();
    let trained = || trained_before + clock_start.elapsed().as_secs_f64();
    let mut snapshots = SnapshotClock::new(config.snapshot_minutes, trained_before);
    let mut explorer = Explorer::new(sim, config, envs.len(), run.step)?;
    let mut batch = Batch::default();
    let mut status = Status { step: run.step, episodes: run.episodes, ..Status::default() };
    let (mut report, mut clock) = (TrainReport::default(), Clock::start());

    // Line 2, for every environment in turn: a tick steps each once.
    let mut done_steps = run.step;
    while done_steps < config.total_steps {
        // Line 3: ε-greedy on each environment's s_k (the greedy ones in one forward pass).
        explorer.choose(&envs, &learner, config, done_steps, &mut run.explore_rng)?;
        clock.split(|t| &mut t.acting);
        let mut checkpoint_due = false;
        for k in 0..envs.len() {
            let (t, epsilon) = (done_steps + 1 + k as u64, config.epsilon(done_steps + k as u64));
            // Lines 4–5: execute a_k, observe r_k and s_{k+1}, store the transition.
            if let Some(end) = envs.step(k, explorer.actions[k], &mut replay, config, &mut clock)? {
                run.window.episode_reward += f64::from(end.reward);
                run.window.episode_length += f64::from(end.length);
                (run.window.episodes, run.episodes) = (run.window.episodes + 1, run.episodes + 1);
                explorer.episode_ended(k);
            }
            clock.split(|t| &mut t.storing);
            // Lines 6–15: gradient steps on random batches.
            if replay.len() as u64 >= config.learning_starts
                && t.is_multiple_of(config.train_frequency)
            {
                for _ in 0..config.gradient_steps {
                    // Uniform (the paper's), or by priority with importance-sampling weights.
                    let beta = config.priority_beta_at(t);
                    let (idx, weights) =
                        replay.sample_weighted(config.batch_size, beta, &mut run.sample_rng);
                    replay.write_batch_as(&idx, &mut batch, learner.depth_layout());
                    batch.weights = weights;
                    clock.split(|t| &mut t.sampling);
                    status.losses = learner.update(&batch);
                    replay.update_priorities(&idx, learner.td_errors());
                    run.window.add_losses(&status.losses);
                }
            }
            // Lines 16–18: θ⁻ ← θ every N_t steps.
            if t.is_multiple_of(config.target_update_interval) {
                learner.sync_target();
            }
            clock.split(|t| &mut t.learning);
            if t.is_multiple_of(LOG_INTERVAL) || t == config.total_steps {
                sink.log(t, &run.window, epsilon, run.episodes)?;
                // A run's last row may cover a partial window: its sums stay open (and go
                // into the checkpoint), so an extended run logs what one long run would.
                if t.is_multiple_of(LOG_INTERVAL) {
                    run.window = Window::default();
                }
            }
            clock.split(|t| &mut t.output);
            if t.is_multiple_of(config.eval_interval) {
                let e = evaluate(&mut eval_envs, &learner, config, sim, &curve_worlds, t)?;
                sink.evaluation(&e)?;
                status.last_eval = Some(e.mean());
                report.evaluations.push(e);
            }
            clock.split(|t| &mut t.evaluation);
            // A checkpoint every interval and at the end (so that a finished run can be
            // extended), written once the tick is done: every environment stands after its step.
            checkpoint_due |= t.is_multiple_of(config.checkpoint_interval)
                || (t == config.total_steps && config.final_checkpoint);
            (status.step, status.epsilon, status.episodes) = (t, epsilon, run.episodes);
            progress(&status);
            clock.split(|t| &mut t.output);
        }
        done_steps += envs.len() as u64;
        let stopping = stop.load(Ordering::Relaxed) && done_steps < config.total_steps;
        checkpoint_due |= stopping;
        if let Some(minute) = snapshots.due(trained()) {
            let minutes = trained() / 60.0;
            dir.save_snapshot(&learner, done_steps, minute, minutes, config.model_precision)?;
            clock.split(|t| &mut t.output);
        }
        if checkpoint_due {
            sink.flush()?;
            (run.step, run.updates) = (done_steps, learner.updates());
            envs.save_into(&mut run);
            checkpoint::save(dir.path(), &mut run, &learner, &replay, trained())?;
            clock.split(|t| &mut t.output);
        }
        if stopping {
            report.stopped = true;
            break;
        }
    }
    sink.flush()?;
    (report.steps, report.updates, report.episodes) =
        (done_steps.min(config.total_steps), learner.updates(), run.episodes);
    (report.seconds, report.timing) = (started.elapsed().as_secs_f64(), clock.timing);
    Ok((report, learner))
}

/// Seconds of training up to the checkpoint at `step` of the run in `dir`: its clock file,
/// else (a checkpoint from before the clock) the run's TensorBoard time at that step. Event
/// files that cannot be read count 0 seconds, unless the run takes snapshots (`needed`),
/// whose minutes would then be wrong: an error.
fn trained_seconds_at(dir: &RunDir, step: u64, needed: bool) -> Result<f64, TrainError> {
    if let Some(s) = checkpoint::training_seconds(dir.path())? {
        return Ok(s);
    }
    let times = match crate::tensorboard::training_seconds(dir.path()) {
        Ok(times) => times,
        Err(e) if needed => {
            let problem = format!(
                "no clock.json, and its TensorBoard events cannot time the run for \
                 train.snapshot_minutes: {e}"
            );
            return Err(TrainError::Checkpoint { path: checkpoint::folder(dir.path()), problem });
        }
        Err(_) => Vec::new(),
    };
    Ok(times.iter().take_while(|&&(s, _)| s <= step).last().map_or(0.0, |&(_, t)| t))
}

/// When the next snapshot of the policy is due (`train.snapshot_minutes`).
#[derive(Debug, Clone, Copy, PartialEq)]
struct SnapshotClock {
    /// Seconds between snapshots (0: none).
    every_s: f64,
    /// The next snapshot's index k (due at k · every_s).
    next: u64,
}

impl SnapshotClock {
    /// Snapshots every `minutes` (0: none) for a run that has trained `trained_s` seconds.
    fn new(minutes: f64, trained_s: f64) -> Self {
        let every_s = minutes * 60.0;
        let next = if every_s > 0.0 { (trained_s / every_s).floor() as u64 + 1 } else { 0 };
        Self { every_s, next }
    }

    /// The minute of the snapshot due at `trained_s` seconds of training, if one is: the
    /// latest multiple passed (a tick longer than the interval skips the ones before it).
    fn due(&mut self, trained_s: f64) -> Option<f64> {
        if self.every_s <= 0.0 || trained_s < self.next as f64 * self.every_s {
            return None;
        }
        let k = (trained_s / self.every_s).floor() as u64;
        self.next = k + 1;
        Some(k as f64 * self.every_s / 60.0)
    }
}

/// The learning curves' worlds: the training world's held-out starts, then the unseen one
/// (none when `train.curve_episodes` is 0).
fn curve_worlds(config: &TrainConfig, task: Task, first: &World) -> Result<Vec<World>, TrainError> {
    let mut worlds = Vec::new();
    if config.curve_episodes > 0 {
        worlds.push(first.clone());
        if let Some(spec) = config.curve_world_for(task) {
            let unseen = mdrlat_world::load(&spec)
                .map_err(|source| TrainError::CurveWorld { spec: spec.clone(), source })?;
            worlds.push(unseen);
        }
    }
    Ok(worlds)
}

/// A new run's empty replay buffer D: the frames its variant reads, the goals of navigation,
/// room for every environment's transitions in flight.
fn empty_replay(config: &TrainConfig, task: Task) -> ReplayBuffer {
    let (v, cap) = (config.variant, config.replay_capacity);
    ReplayBuffer::new(cap, frame_reserve(cap), v.uses_laser(), v.uses_depth())
        .with_goals(task == Task::Nav)
        .with_envs(config.envs, config.n_step as usize)
        .with_priorities(config.priorities())
}

#[cfg(test)]
mod tests {
    use super::SnapshotClock;

    #[test]
    fn snapshots_fall_due_at_each_multiple_of_the_interval() {
        let mut c = SnapshotClock::new(2.0, 0.0);
        assert_eq!(c.due(0.0), None);
        assert_eq!(c.due(119.9), None);
        assert_eq!(c.due(120.0), Some(2.0));
        assert_eq!(c.due(121.0), None, "one snapshot per multiple");
        // A tick that spans two intervals writes the later one.
        assert_eq!(c.due(500.0), Some(8.0));
        assert_eq!(c.due(530.0), None);
        assert_eq!(c.due(600.0), Some(10.0));
    }

    #[test]
    fn a_resumed_run_counts_on_from_its_checkpoint_and_zero_means_none() {
        let mut c = SnapshotClock::new(10.0, 1_500.0); // 25 minutes trained
        assert_eq!(c.due(1_700.0), None);
        assert_eq!(c.due(1_800.0), Some(30.0));
        let mut off = SnapshotClock::new(0.0, 0.0);
        assert_eq!(off.due(1e9), None);
    }
}
