//! A network that acts: greedy decisions for a batch of observations, from a trained run,
//! the learner's current weights or a fresh initialisation — behind the one
//! [`mdrlat_core::Policy`] interface that `mdrlat eval`, training's evaluation, `rollout`
//! and the ROS node call.

use crate::checkpoint::read_meta;
use crate::learner::{Inputs, check_inputs, net_config, q_forward_with, read_net};
use mdrlat_core::{
    Action, Decision, FRAME_STACK, Observation, Policy, PolicyError, Sensors, catch_panic,
    check_batch, greedy_actions, normalize_depth, normalize_goal, normalize_laser,
};
use mdrlat_nn::burn::prelude::*;
use mdrlat_nn::{QNet, QNetConfig, Variant};
use mdrlat_sim::SimConfig;
use mdrlat_sim::config::Task;
use std::path::{Path, PathBuf};

/// A Q-network acting greedily (no exploration) on batches of observations.
pub struct GreedyPolicy {
    /// The network's settings: variant and goal input.
    config: QNetConfig,
    net: QNet,
    device: Device,
    pool: rayon::ThreadPool,
    source: String,
    /// Rows of every forward (`None`: the whole batch in one forward).
    forward_batch: Option<usize>,
    /// One input buffer per forward of a batch.
    inputs: Vec<Inputs>,
    /// The network prepared once for the CPU's host kernels (on `flex`; `None` elsewhere),
    /// its linear layers' weights in bfloat16 with [`GreedyPolicy::with_bf16_weights`].
    host: Option<mdrlat_nn::host::HostNet>,
}

impl std::fmt::Debug for GreedyPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GreedyPolicy")
            .field("variant", &self.config.variant)
            .field("goal_dim", &self.config.goal_dim)
            .field("source", &self.source)
            .finish()
    }
}

/// The checkpoint folder `path` names: a checkpoint folder itself, or a run directory
/// (its `checkpoint/`, or `checkpoint.old/` if a run was killed during a swap).
fn checkpoint_dir(path: &Path) -> Result<PathBuf, String> {
    if !path.exists() {
        return Err(format!("{}: no such run directory or checkpoint", path.display()));
    }
    [path.to_path_buf(), path.join("checkpoint"), path.join("checkpoint.old")]
        .into_iter()
        .find(|d| d.join("meta.json").is_file())
        .ok_or_else(|| {
            format!(
                "{}: no checkpoint here (expected a run directory with checkpoint/meta.json, \
                 or a checkpoint folder with meta.json)",
                path.display()
            )
        })
}

/// The model file `path` names when it is not a checkpoint: a `.safetensors` file, or a
/// folder holding `model.safetensors` and no checkpoint (a shipped model, `models/…`).
fn model_file(path: &Path) -> Option<PathBuf> {
    if path.is_file() && path.extension().is_some_and(|e| e == "safetensors") {
        return Some(path.to_path_buf());
    }
    let model = path.join("model.safetensors");
    (path.is_dir() && checkpoint_dir(path).is_err() && model.is_file()).then_some(model)
}

fn pool(threads: usize) -> Result<rayon::ThreadPool, String> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .thread_name(|i| format!("policy-{i}"))
        .build()
        .map_err(|e| format!("inference thread pool: {e}"))
}

/// Writes the network inputs of `batch` for a network of `config` into `inputs` (one row
/// per observation, oldest frame first) through the shared normalisation of `mdrlat_core`.
///
/// # Errors
/// The network reads a goal and an observation has none (it comes from obstacle avoidance,
/// not the navigation task).
pub fn observation_inputs(
    batch: &[&Observation],
    config: &QNetConfig,
    inputs: &mut Inputs,
) -> Result<(), PolicyError> {
    let variant = config.variant;
    inputs.size = batch.len();
    let fill = |out: &mut Vec<f32>,
                stack: fn(&Observation) -> &mdrlat_core::FrameStack,
                f: fn(&[f32], &mut [f32])| {
        let Some(first) = batch.first() else {
            out.clear();
            return;
        };
        let n = FRAME_STACK * stack(first).frame_len();
        out.resize(n * batch.len(), 0.0);
        for (obs, row) in batch.iter().zip(out.chunks_exact_mut(n)) {
            stack(obs).write_stacked(row, f);
        }
    };
    if variant.uses_laser() {
        fill(&mut inputs.laser, |o| &o.laser, normalize_laser);
    } else {
        inputs.laser.clear();
    }
    if variant.uses_depth() {
        fill(&mut inputs.depth, |o| &o.depth, normalize_depth);
    } else {
        inputs.depth.clear();
    }
    inputs.goal.clear();
    if config.goal_dim > 0 {
        for (row, obs) in batch.iter().enumerate() {
            let goal = obs.goal.ok_or_else(|| {
                PolicyError::Backend(format!(
                    "observation {row} has no goal, but this network was trained for \
                     navigation (run it with --task nav)"
                ))
            })?;
            inputs.goal.extend_from_slice(&normalize_goal(&goal));
        }
    }
    Ok(())
}

/// `path` as a policy's name shows it: relative to the working directory where it lies
/// below it (a sweep passes absolute paths; its tables and titles should not name the
/// machine's folders), else as given.
fn shown(path: &Path) -> String {
    std::env::current_dir()
        .ok()
        .and_then(|cwd| path.strip_prefix(cwd).ok().map(Path::to_path_buf))
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or_else(|| path.to_path_buf())
        .display()
        .to_string()
}

/// The network a trained model stands for, on `device` (with autodiff, for a warm start
/// that trains on from it; without, to act): a run's checkpoint (`path`: a run directory or
/// a checkpoint folder) gives its averaged network where the run keeps one
/// (`train.average_horizon`), else its online network; a model file (`path`: a
/// `.safetensors` file written by [`crate::export::save_safetensors_as`], f32 or f16, or a
/// folder holding `model.safetensors` and no checkpoint) gives its weights. Also returns
/// the network's settings and how to name where it came from.
///
/// # Errors
/// No checkpoint or model, an unreadable or corrupt `meta.json`, another format, or weights
/// that do not fit the variant it names.
pub fn load_weights(path: &Path, device: &Device) -> Result<(QNetConfig, QNet, String), String> {
    if let Some(model) = model_file(path) {
        let (config, net, meta) = crate::export::load_safetensors(&model, device)?;
        // A snapshot (train.snapshot_minutes) also says when it was taken.
        let minutes = meta
            .get("mdrlat_training_minutes")
            .map_or(String::new(), |m| format!(", {m} minutes of training"));
        let scan = scan_note(&config);
        let step =
            meta.get("mdrlat_step").map_or(scan.clone(), |s| format!(" (step {s}{minutes}{scan})"));
        return Ok((config, net, format!("{}{step}", shown(&model))));
    }
    let dir = checkpoint_dir(path)?;
    let meta = read_meta(&dir).map_err(|e| e.to_string())?;
    if meta.depth_memory_frames > mdrlat_sim::sensors::MAX_MEMORY_FRAMES {
        return Err(format!(
            "{}: depth_memory_frames = {}: not 0 to {}",
            dir.join("meta.json").display(),
            meta.depth_memory_frames,
            mdrlat_sim::sensors::MAX_MEMORY_FRAMES
        ));
    }
    let config = net_config(meta.variant, meta.task)
        .with_depth_memory_frames(meta.depth_memory_frames as usize);
    let mut net = config.init(device);
    // A run that keeps an average of its weights acts by it (train.average_horizon).
    let averaged = dir.join(crate::learner::AVERAGE_FILE);
    let (file, which) = if averaged.is_file() {
        (averaged, ", averaged network")
    } else {
        (dir.join("online.bpk"), "")
    };
    read_net(&mut net, &file, meta.variant)?;
    let scan = scan_note(&config);
    Ok((config, net, format!("{} (step {}{which}{scan})", shown(&dir), meta.step)))
}

/// What a network's source line says about its scan: nothing for the laser's own.
fn scan_note(config: &QNetConfig) -> String {
    match config.depth_memory_frames {
        0 => String::new(),
        n => format!(", reading the scan with {n} frames of the camera's memory"),
    }
}

impl GreedyPolicy {
    /// The policy of a run's checkpoint (`path`: a run directory or a checkpoint folder): its
    /// averaged network where the run keeps one (`train.average_horizon`), else its online
    /// network; or a model file (`path`: a `.safetensors` file written by
    /// [`crate::export::save_safetensors_as`], f32 or f16, or a folder holding
    /// `model.safetensors` and no checkpoint), computing on `threads` CPU threads.
    ///
    /// # Errors
    /// No checkpoint or model, an unreadable or corrupt `meta.json`, another format, or weights that
    /// do not fit the variant it names.
    pub fn load(path: &Path, device: &Device, threads: usize) -> Result<Self, String> {
        let (config, net, source) = load_weights(path, device)?;
        Self::from_net(config, net, device, threads, source)
    }

    /// A freshly initialised `variant` network of `task` (seeded), for testing a deployment
    /// before any training.
    ///
    /// # Errors
    /// The thread pool cannot start.
    pub fn untrained(
        variant: Variant,
        task: Task,
        seed: u64,
        device: &Device,
        threads: usize,
    ) -> Result<Self, String> {
        let config = net_config(variant, task);
        let net = config.init_seeded(device, seed);
        Self::from_net(config, net, device, threads, format!("untrained, seed {seed}"))
    }

    /// A policy over `net`, a network of `config` without autodiff on `device`; `source`
    /// says where its weights came from.
    ///
    /// # Errors
    /// The thread pool cannot start.
    pub fn from_net(
        config: QNetConfig,
        net: QNet,
        device: &Device,
        threads: usize,
        source: String,
    ) -> Result<Self, String> {
        // A one-thread policy runs a single decision's network on the calling thread.
        let host = net.host(&config).map(|h| if threads <= 1 { h.on_calling_thread() } else { h });
        Ok(Self {
            config,
            net,
            device: device.clone(),
            pool: pool(threads)?,
            source,
            forward_batch: None,
            inputs: Vec::new(),
            host,
        })
    }

    /// Decides in forwards of exactly `rows` observations (the last one padded with zero
    /// rows), on the pool's threads side by side. A forward's rounding depends on its row
    /// count, not on the other rows (tested), so with a fixed `rows` an observation's
    /// decision is the same whatever batch it arrives in: an evaluation's outcomes then do
    /// not depend on how many environments step together. `None` (the default): one
    /// forward of the whole batch, the cheapest for single decisions (the robot).
    pub fn with_forward_batch(mut self, rows: Option<usize>) -> Self {
        self.forward_batch = rows.map(|r| r.max(1));
        self
    }

    /// The network (for exporting it).
    pub fn net(&self) -> &QNet {
        &self.net
    }

    /// Opt-in reduced precision for inference: the linear layers read their weights
    /// rounded to bfloat16 (half the bytes; products still summed in f32), which makes a
    /// single decision — a pass over every weight, bound by memory — faster (measured side
    /// by side on one core: `docs/performance.md`). Decisions can differ from the
    /// f32 network's where two actions' Q-values are closer than the rounding; never the
    /// default.
    ///
    /// # Errors
    /// The CPU lacks the kernel (AVX-512F), or the backend is not the CPU's.
    pub fn with_bf16_weights(mut self) -> Result<Self, String> {
        let host =
            self.host.take().ok_or("bfloat16 weights need the cpu device (the host kernels)")?;
        self.host =
            Some(host.with_bf16_weights().ok_or(
                "bfloat16 weights need AVX-512F, which this CPU lacks (run without --bf16)",
            )?);
        self.source.push_str(", bf16 weights");
        Ok(self)
    }

    /// The variant.
    pub fn variant(&self) -> Variant {
        self.config.variant
    }

    /// The task it was trained for: navigation when the network reads a goal.
    pub fn task(&self) -> Task {
        Task::of_goal_dim(self.config.goal_dim)
    }

    /// The network's settings.
    pub fn config(&self) -> &QNetConfig {
        &self.config
    }

    /// An error unless the network was trained for `task` (a navigation network needs the
    /// goal, an obstacle-avoidance one has never seen it); `what` names the network.
    ///
    /// # Errors
    /// The tasks differ.
    pub fn check_task(&self, task: Task, what: &str) -> Result<(), String> {
        if self.task() == task {
            return Ok(());
        }
        let trained = match self.task() {
            Task::Avoid => "obstacle avoidance (no goal input)",
            Task::Nav => "navigation (a goal input)",
        };
        Err(format!(
            "{what}: a {} network trained for {trained}; this run is --task {task}: \
             it needs a network trained with --task {task}",
            self.variant()
        ))
    }

    /// Fits `sim` to the network: its task must be the network's ([`Self::check_task`]) and
    /// it draws the scan the network reads ([`Self::adopt_scan`]). Every command that feeds
    /// a trained network a simulator (eval, demo, diagnose, export's comparison) calls it.
    ///
    /// # Errors
    /// Another task, or another scan, naming `what`.
    pub fn fit_sim(&self, sim: &mut SimConfig, what: &str) -> Result<(), String> {
        self.check_task(sim.task, what)?;
        self.adopt_scan(sim, what)
    }

    /// Makes `sim` draw the scan the network reads: a `sim` of the laser's own scan takes
    /// the network's memory (`sim.laser.depth_memory_frames`); one that asks for another
    /// is an error naming `what`. Everything that feeds a trained network observations
    /// (evaluation, the ROS nodes, Python) calls it, so no network ever reads a scan it
    /// was not trained on.
    ///
    /// # Errors
    /// `sim` asks for a memory the network was not trained with.
    pub fn adopt_scan(&self, sim: &mut SimConfig, what: &str) -> Result<(), String> {
        let (model, asked) =
            (self.config.depth_memory_frames as u32, sim.laser.depth_memory_frames);
        if asked == 0 || asked == model {
            sim.laser.depth_memory_frames = model;
            return Ok(());
        }
        Err(format!(
            "{what}: the {} network reads {}; the settings ask for {} \
             (sim.laser.depth_memory_frames = {asked}): leave it 0 to take the network's",
            self.variant(),
            crate::learner::scan_name(model as usize),
            crate::learner::scan_name(asked as usize),
        ))
    }

    /// Where the weights came from, for logs.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// Q-values `[B][actions]` (row-major) for a batch of network inputs (normalised, in
    /// the network's layout; see [`observation_inputs`]).
    ///
    /// # Errors
    /// Inputs of the wrong size, or a backend failure.
    pub fn q_values(&self, inputs: &Inputs) -> Result<Vec<f32>, PolicyError> {
        let host = self.host.as_ref();
        let forward = || q_forward_with(&self.net, host, &self.config, &self.device, inputs);
        if self.on_calling_thread(inputs.size) { forward() } else { self.pool.install(forward) }
    }

    /// Whether a forward of `rows` rows runs on the calling thread rather than in the
    /// pool: one row, one thread, on the host kernels (see `HostNet::on_calling_thread`;
    /// handing a decision to the pool's thread and waiting for it costs a measurable share
    /// of a decision; `docs/performance.md`).
    fn on_calling_thread(&self, rows: usize) -> bool {
        rows == 1 && self.pool.current_num_threads() == 1 && self.host.is_some()
    }
}

impl Policy for GreedyPolicy {
    fn name(&self) -> String {
        format!("{} from {}", self.config.variant, self.source)
    }

    fn sensors(&self) -> Sensors {
        // The scan with the camera's memory is drawn from the camera's images.
        let v = self.config.variant;
        Sensors { laser: v.uses_laser(), depth: v.uses_depth() || self.depth_memory_frames() > 0 }
    }

    fn depth_memory_frames(&self) -> u32 {
        self.config.depth_memory_frames as u32
    }

    fn decide(
        &mut self,
        batch: &[&Observation],
        slots: &[usize],
        out: &mut Vec<Decision>,
    ) -> Result<(), PolicyError> {
        check_batch(batch, slots)?;
        if batch.is_empty() {
            out.clear();
            return Ok(());
        }
        let rows = self.forward_batch.unwrap_or(batch.len());
        let chunks: Vec<&[&Observation]> = batch.chunks(rows).collect();
        if self.inputs.len() < chunks.len() {
            self.inputs.resize_with(chunks.len(), Inputs::default);
        }
        let on_caller = self.on_calling_thread(rows);
        let (net, config, device) = (&self.net, &self.config, &self.device);
        let host = self.host.as_ref();
        let inputs = &mut self.inputs[..chunks.len()];
        // Per forward, values whose greedy actions are the Q-values': the Q-values, or for a
        // single observation on the host kernels what `HostNet::decide_one` gives — the
        // advantages alone wherever their lead settles the action (the value head's weights
        // are then not read), else the Q-values.
        let one = |(chunk, inputs): (&&[&Observation], &mut Inputs)| {
            observation_inputs(chunk, config, inputs)?;
            pad_rows(inputs, rows);
            let mut values = match host {
                Some(host) if rows == 1 => {
                    check_inputs(config, inputs)?;
                    host.decide_one(&inputs.host()).into_values()
                }
                _ => q_forward_with(net, host, config, device, inputs)?,
            };
            values.truncate(chunk.len() * Action::COUNT);
            Ok(values)
        };
        let forward = || -> Result<Vec<Vec<f32>>, PolicyError> {
            if on_caller {
                return chunks.iter().zip(inputs.iter_mut()).map(one).collect();
            }
            self.pool.install(|| {
                use rayon::prelude::*;
                chunks.par_iter().zip(inputs.par_iter_mut()).map(one).collect()
            })
        };
        // A panicking backend is a failed decision, reported as one, not a crash.
        let q = catch_panic("the network backend", forward);
        let q: Vec<f32> = q?.concat();
        let mut actions = Vec::with_capacity(batch.len());
        greedy_actions(&q, batch.len(), &mut actions)?;
        out.clear();
        out.extend(actions.into_iter().map(Decision::from));
        Ok(())
    }
}

/// Pads `inputs` with rows of zeros up to `rows` rows.
fn pad_rows(inputs: &mut Inputs, rows: usize) {
    if inputs.size >= rows {
        return;
    }
    let per = |v: &[f32], size: usize| v.len().checked_div(size).unwrap_or(0);
    let (l, d) = (per(&inputs.laser, inputs.size), per(&inputs.depth, inputs.size));
    let g = per(&inputs.goal, inputs.size);
    inputs.laser.resize(l * rows, 0.0);
    inputs.depth.resize(d * rows, 0.0);
    inputs.goal.resize(g * rows, 0.0);
    inputs.size = rows;
}

#[cfg(test)]
mod tests {
    use super::shown;
    use std::path::Path;

    #[test]
    fn a_policy_names_its_path_relative_to_the_working_directory() {
        let cwd = std::env::current_dir().expect("cwd");
        assert_eq!(
            shown(&cwd.join("sweep/train/mdrlat-s0/checkpoint")),
            "sweep/train/mdrlat-s0/checkpoint"
        );
        assert_eq!(shown(Path::new("runs/a")), "runs/a");
        assert_eq!(shown(&cwd), cwd.display().to_string());
        let outside = Path::new("/nonexistent-root-for-test/run");
        assert_eq!(shown(outside), "/nonexistent-root-for-test/run");
    }
}
