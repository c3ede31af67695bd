//! Checkpoints that resume a run exactly: weights, target, Adam moments, counters, the
//! replay buffer, the environment's state and every random stream.
//!
//! A checkpoint is the folder `checkpoint/` of a run directory:
//! `meta.json` (format version, variant, counters, RNG and environment state, the replay
//! file's length and checksum), `online.bpk`, `target.bpk`, `optimizer.bpk` (burnpack; with
//! the auxiliary loss's own Adam also `optimizer-aux.bpk`; with `train.average_horizon` the
//! averaged network, `average.bpk`), `replay.bin` and `clock.json` (seconds of training so
//! far, [`CLOCK_FILE`]). It is written to `checkpoint.tmp/` and then swapped in, so a run killed
//! at any moment (even `kill -9`) keeps its previous checkpoint and loses at most one
//! checkpoint interval. The replay buffer is saved in full (0.8 GB for depth variants):
//! without it a resumed run would relearn from an empty buffer and diverge from the
//! uninterrupted one.

use crate::config::TrainConfig;
use crate::error::TrainError;
use crate::learner::Learner;
use crate::replay::{FrameId, ReplayBuffer};
use mdrlat_core::Rng;
use mdrlat_nn::Variant;
use mdrlat_nn::burn::prelude::Device;
use mdrlat_sim::EnvState;
use mdrlat_sim::config::Task;
use serde::{Deserialize, Serialize};
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

/// Version of the checkpoint format this build reads and writes.
pub const CHECKPOINT_FORMAT: u32 = 1;

/// The checkpoint's clock: seconds of training up to it (every session counted, the work
/// redone after a restart once). Kept out of `meta.json`, whose bytes a seed fixes.
pub const CLOCK_FILE: &str = "clock.json";

/// What [`CLOCK_FILE`] holds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct TrainingClock {
    training_seconds: f64,
}

/// Frame slots the training loop reserves beyond the replay capacity: an episode of L steps
/// stores L + 1 frames, so with capacity / 8 spare slots the buffer holds its full capacity
/// whenever episodes average 8 steps or more (and ~89% of it at 4).
pub fn frame_reserve(capacity: usize) -> usize {
    (capacity / 8).max(64)
}

/// Running sums of the current `metrics.csv` window.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Window {
    /// Sum of TD losses.
    pub td: f64,
    /// Sum of auxiliary losses.
    pub at: f64,
    /// Sum of mean Q.
    pub q: f64,
    /// Gradient steps in the window.
    pub updates: u32,
    /// Sum of finished episodes' rewards.
    pub episode_reward: f64,
    /// Sum of finished episodes' lengths.
    pub episode_length: f64,
    /// Episodes finished in the window.
    pub episodes: u32,
}

impl Window {
    /// One gradient step's losses.
    pub fn add_losses(&mut self, losses: &crate::learner::Losses) {
        self.td += f64::from(losses.td);
        self.at += f64::from(losses.at);
        self.q += f64::from(losses.q_mean);
        self.updates += 1;
    }
}

/// Everything of a run that is not weights or replay.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Meta {
    /// [`CHECKPOINT_FORMAT`].
    pub format: u32,
    /// The mdrlat version that wrote it.
    pub mdrlat_version: String,
    /// Network variant.
    pub variant: Variant,
    /// The task it learns (absent for obstacle avoidance: such checkpoints' `meta.json` is
    /// as before navigation existed).
    #[serde(default, skip_serializing_if = "Task::is_avoid")]
    pub task: Task,
    /// The scan its network reads (`sim.laser.depth_memory_frames`; absent: the laser's
    /// own, as in every checkpoint before it).
    #[serde(default, skip_serializing_if = "is_zero_u32")]
    pub depth_memory_frames: u32,
    /// Environment steps done.
    pub step: u64,
    /// Gradient steps done.
    pub updates: u64,
    /// Episodes finished.
    pub episodes: u64,
    /// Reward so far of the running episode.
    pub episode_reward: f32,
    /// Length so far of the running episode.
    pub episode_length: u32,
    /// Replay frame ids of the current observation's stack.
    pub stack: [FrameId; 4],
    /// Exploration stream.
    pub explore_rng: Rng,
    /// Replay sampling stream.
    pub sample_rng: Rng,
    /// The open metrics window.
    pub window: Window,
    /// The training environment (the first, with `train.envs` > 1).
    pub env: EnvState,
    /// The first environment's steps whose n-step transitions are not stored yet, oldest
    /// first (`train.n_step` > 1).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub pending: Vec<PendingStep>,
    /// Which training world the first environment is in (an index into the run's worlds;
    /// absent with one world).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub world: usize,
    /// The environments after the first (`train.envs` > 1), in order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub more_envs: Vec<EnvSlot>,
    /// The replay's priorities, with prioritised replay (`train.priority_alpha` > 0;
    /// absent otherwise, as in every checkpoint before it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub priorities: Option<crate::priority::PriorityState>,
    /// Bytes of `replay.bin`.
    pub replay_bytes: u64,
    /// FNV-1a 64 of `replay.bin`.
    pub replay_checksum: u64,
}

/// One training environment beyond the first, where it is in its episode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EnvSlot {
    /// Its world (an index into the run's worlds).
    pub world: usize,
    /// Reward so far of its running episode.
    pub episode_reward: f32,
    /// Length so far of its running episode.
    pub episode_length: u32,
    /// Replay frame ids of its observation's stack.
    pub stack: [FrameId; 4],
    /// Its state.
    pub env: EnvState,
    /// Its steps whose n-step transitions are not stored yet, oldest first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub pending: Vec<PendingStep>,
}

/// An environment step whose n-step transition waits for the steps after it
/// (`train.n_step`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PendingStep {
    /// Frames of its observation.
    pub obs: [FrameId; 4],
    /// The action taken.
    pub action: u8,
    /// Its reward.
    pub reward: f32,
    /// Its observation's odometry (the auxiliary task's target).
    pub odom: [f32; 6],
    /// Its observation's goal.
    pub goal: [f32; 3],
}

fn is_zero_u32(n: &u32) -> bool {
    *n == 0
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// FNV-1a over everything that passes through.
struct Hashing<T> {
    inner: T,
    hash: u64,
    bytes: u64,
}

impl<T> Hashing<T> {
    fn new(inner: T) -> Self {
        Self { inner, hash: 0xcbf2_9ce4_8422_2325, bytes: 0 }
    }
    fn feed(&mut self, data: &[u8]) {
        for &b in data {
            self.hash = (self.hash ^ u64::from(b)).wrapping_mul(0x100_0000_01b3);
        }
        self.bytes += data.len() as u64;
    }
}

impl<W: Write> Write for Hashing<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.feed(&buf[..n]);
        Ok(n)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

impl<R: Read> Read for Hashing<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.feed(&buf[..n]);
        Ok(n)
    }
}

fn bad(path: &Path, problem: impl Into<String>) -> TrainError {
    TrainError::Checkpoint { path: path.to_path_buf(), problem: problem.into() }
}

/// The checkpoint folder of a run directory.
pub fn folder(run_dir: &Path) -> PathBuf {
    run_dir.join("checkpoint")
}

/// Writes a checkpoint of the run in `run_dir` (atomically replacing the previous one).
///
/// # Errors
/// A file cannot be written.
pub fn save(
    run_dir: &Path,
    meta: &mut Meta,
    learner: &Learner,
    replay: &ReplayBuffer,
    training_seconds: f64,
) -> Result<(), TrainError> {
    let tmp = run_dir.join("checkpoint.tmp");
    let _ = std::fs::remove_dir_all(&tmp);
    std::fs::create_dir_all(&tmp).map_err(|e| bad(&tmp, e.to_string()))?;
    learner.save(&tmp).map_err(|e| bad(&tmp, e))?;
    let replay_path = tmp.join("replay.bin");
    let file = File::create(&replay_path).map_err(|e| bad(&replay_path, e.to_string()))?;
    let mut w = Hashing::new(BufWriter::with_capacity(1 << 20, file));
    replay
        .write_to(&mut w)
        .and_then(|()| w.flush())
        .map_err(|e| bad(&replay_path, e.to_string()))?;
    meta.replay_bytes = w.bytes;
    meta.replay_checksum = w.hash;
    meta.priorities = replay.priorities().map(|p| p.state(replay.len()));
    let meta_path = tmp.join("meta.json");
    let text = serde_json::to_string(meta).map_err(|e| bad(&meta_path, e.to_string()))?;
    File::create(&meta_path)
        .and_then(|mut f| f.write_all(text.as_bytes()).and_then(|()| f.sync_all()))
        .map_err(|e| bad(&meta_path, e.to_string()))?;
    let clock_path = tmp.join(CLOCK_FILE);
    let clock = serde_json::to_string(&TrainingClock { training_seconds })
        .map_err(|e| bad(&clock_path, e.to_string()))?;
    File::create(&clock_path)
        .and_then(|mut f| f.write_all(clock.as_bytes()).and_then(|()| f.sync_all()))
        .map_err(|e| bad(&clock_path, e.to_string()))?;
    // Swap. Until the new folder is in place, either `checkpoint/` or `checkpoint.old/`
    // holds a complete checkpoint (load falls back to the latter).
    let dest = folder(run_dir);
    let old = run_dir.join("checkpoint.old");
    if dest.exists() {
        let _ = std::fs::remove_dir_all(&old);
        std::fs::rename(&dest, &old).map_err(|e| bad(&dest, e.to_string()))?;
    }
    std::fs::rename(&tmp, &dest).map_err(|e| bad(&dest, e.to_string()))?;
    if let Ok(d) = File::open(run_dir) {
        let _ = d.sync_all(); // the renames reach the disk
    }
    let _ = std::fs::remove_dir_all(&old);
    Ok(())
}

/// Reads and checks the `meta.json` of the checkpoint folder `dir`.
///
/// # Errors
/// Missing, unreadable or corrupt, or another format version.
pub fn read_meta(dir: &Path) -> Result<Meta, TrainError> {
    let meta_path = dir.join("meta.json");
    let text = std::fs::read_to_string(&meta_path).map_err(|e| bad(&meta_path, e.to_string()))?;
    let meta: Meta =
        serde_json::from_str(&text).map_err(|e| bad(&meta_path, format!("corrupt: {e}")))?;
    if meta.format != CHECKPOINT_FORMAT {
        return Err(bad(
            &meta_path,
            format!("format {} (this build reads {CHECKPOINT_FORMAT})", meta.format),
        ));
    }
    Ok(meta)
}

/// The checkpoint folder a resume reads: `checkpoint/`, or `checkpoint.old/` when the run
/// was killed in the middle of a swap.
fn resume_folder(run_dir: &Path) -> PathBuf {
    let dir = folder(run_dir);
    if !dir.is_dir() && run_dir.join("checkpoint.old").is_dir() {
        return run_dir.join("checkpoint.old");
    }
    dir
}

/// Seconds of training up to the checkpoint of `run_dir` (see [`CLOCK_FILE`]); `None` for a
/// checkpoint written before the clock existed.
///
/// # Errors
/// The clock file is unreadable, corrupt or not a finite, non-negative number of seconds.
pub fn training_seconds(run_dir: &Path) -> Result<Option<f64>, TrainError> {
    let path = resume_folder(run_dir).join(CLOCK_FILE);
    let text = match std::fs::read_to_string(&path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(bad(&path, e.to_string())),
    };
    let clock: TrainingClock =
        serde_json::from_str(&text).map_err(|e| bad(&path, format!("corrupt: {e}")))?;
    if !clock.training_seconds.is_finite() || clock.training_seconds < 0.0 {
        return Err(bad(&path, format!("{} is not a time", clock.training_seconds)));
    }
    Ok(Some(clock.training_seconds))
}

/// Reads the checkpoint of `run_dir` for a run with `config` of `task`.
///
/// # Errors
/// No checkpoint, a truncated or corrupt file, another format version, or a checkpoint of
/// another variant, task or replay size.
pub fn load(
    run_dir: &Path,
    config: &TrainConfig,
    task: Task,
    device: &Device,
) -> Result<(Meta, Learner, ReplayBuffer), TrainError> {
    let dir = resume_folder(run_dir);
    if !dir.is_dir() {
        return Err(bad(&dir, "no checkpoint to resume from (none was written yet?)"));
    }
    let meta = read_meta(&dir)?;
    let meta_path = dir.join("meta.json");
    if meta.variant != config.variant {
        return Err(bad(
            &meta_path,
            format!(
                "the checkpoint is a {} network; the run asks for {}",
                meta.variant, config.variant
            ),
        ));
    }
    if meta.task != task {
        return Err(bad(
            &meta_path,
            format!(
                "the checkpoint learns the {} task; the run asks for --task {task} \
                 (sim.task)",
                meta.task
            ),
        ));
    }
    let learner =
        Learner::load(config, task, device, &dir, meta.updates).map_err(|e| bad(&dir, e))?;
    let replay_path = dir.join("replay.bin");
    let file = File::open(&replay_path).map_err(|e| bad(&replay_path, e.to_string()))?;
    let size = file.metadata().map(|m| m.len()).unwrap_or(0);
    if size != meta.replay_bytes {
        return Err(bad(
            &replay_path,
            format!("truncated: {size} bytes, the checkpoint wrote {}", meta.replay_bytes),
        ));
    }
    if meta.more_envs.len() + 1 != config.envs {
        return Err(bad(
            &meta_path,
            format!(
                "the checkpoint steps {} environments; the run asks for train.envs = {}",
                meta.more_envs.len() + 1,
                config.envs
            ),
        ));
    }
    let mut r = Hashing::new(BufReader::with_capacity(1 << 20, file));
    let (v, cap) = (config.variant, config.replay_capacity);
    let replay = ReplayBuffer::read_from(
        &mut r,
        size,
        cap,
        frame_reserve(cap),
        v.uses_laser(),
        v.uses_depth(),
        task == Task::Nav,
        (config.envs, config.n_step as usize),
    )
    .map_err(|e| bad(&replay_path, e.to_string()))?;
    if r.hash != meta.replay_checksum {
        return Err(bad(&replay_path, "checksum mismatch: the file is corrupt"));
    }
    let priorities = match (&meta.priorities, config.priority_alpha > 0.0) {
        (None, false) => None,
        (Some(state), true) => Some(
            crate::priority::Priorities::restore(
                cap,
                config.priority_alpha,
                config.priority_epsilon,
                state,
                replay.len(),
            )
            .map_err(|e| bad(&meta_path, format!("replay priorities: {e}")))?,
        ),
        (held, _) => {
            let with = |p: bool| if p { "prioritised" } else { "uniform" };
            return Err(bad(
                &meta_path,
                format!(
                    "the checkpoint's replay is {}, the run asks for {} replay \
                     (train.priority_alpha = {})",
                    with(held.is_some()),
                    with(held.is_none()),
                    config.priority_alpha
                ),
            ));
        }
    };
    let replay = replay.with_priorities(priorities);
    let stacks = std::iter::once(&meta.stack)
        .chain(meta.more_envs.iter().map(|s| &s.stack))
        .chain(meta.pending.iter().map(|p| &p.obs))
        .chain(meta.more_envs.iter().flat_map(|s| s.pending.iter().map(|p| &p.obs)));
    if !stacks.flatten().all(|&id| replay.holds_frame(id)) {
        return Err(bad(
            &meta_path,
            "the current frame stack refers to frames the replay file does not hold",
        ));
    }
    if meta.step > config.total_steps {
        return Err(bad(
            &meta_path,
            format!(
                "the checkpoint is at step {}, beyond train.total_steps {}: give --steps",
                meta.step, config.total_steps
            ),
        ));
    }
    Ok((meta, learner, replay))
}
