//! The learning rule: double DQN with a dueling network and the auxiliary velocity task
//! (paper eqs. 10, 12, 13; Algorithm 1 lines 6–17).

use crate::adam::{AdamCounts, FusedAdam};
use crate::config::{AVERAGE_EVERY, AuxOptimizer, TrainConfig};
use crate::error::TrainError;
use crate::replay::{Batch, DepthLayout};
use mdrlat_core::{
    Action, DEPTH_COLS, DEPTH_ROWS, FRAME_STACK, LASER_BEAMS, ODOM_HISTORY, PolicyError,
    greedy_actions,
};
use mdrlat_nn::burn::module::Module;
use mdrlat_nn::burn::optim::{GradientsParams, ModuleOptimizer};
use mdrlat_nn::burn::prelude::*;
use mdrlat_nn::burn::store::{BurnpackStore, ModuleSnapshot};
use mdrlat_nn::host::{HostGrad, HostInputs, HostNet};
use mdrlat_nn::{QNet, QNetConfig, Variant};
use mdrlat_sim::SimConfig;
use mdrlat_sim::config::Task;
use std::path::Path;
use std::sync::Arc;

/// Losses of one gradient step.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Losses {
    /// Paper eq. (13), mean over the batch.
    pub td: f32,
    /// Paper eq. (12), mean over the batch (0 without the auxiliary task).
    pub at: f32,
    /// Mean Q(s, a) of the batch, for monitoring.
    pub q_mean: f32,
}

/// A gradient step's [`Losses`] still on the device, `[td, at, q_mean]`: read in one
/// transfer after the step's work is queued, since every read waits for the device (three
/// reads in the middle of a step stalled a GPU three times).
struct PendingLosses(Tensor<1>);

impl PendingLosses {
    /// The losses, and what follows them in the tensor (the rows' TD errors where they
    /// were asked for).
    fn read(self) -> (Losses, Vec<f32>) {
        let data = self.0.into_data().convert_dtype(mdrlat_nn::burn::tensor::DType::F32);
        let v = data.try_to_vec::<f32>().unwrap_or_default();
        let at = |i: usize| v.get(i).copied().unwrap_or(f32::NAN);
        let rest = v.get(3..).map(<[f32]>::to_vec).unwrap_or_default();
        (Losses { td: at(0), at: at(1), q_mean: at(2) }, rest)
    }
}

/// Network inputs of a batch of observations, as flat arrays in the network's layout.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Inputs {
    /// Rows.
    pub size: usize,
    /// `[B, 4, 512]` normalised laser (empty when unused).
    pub laser: Vec<f32>,
    /// `[B, 4, 128, 160]` normalised depth (empty when unused).
    pub depth: Vec<f32>,
    /// `[B, 3]` normalised goal (`mdrlat_core::normalize_goal`; empty without a goal input).
    pub goal: Vec<f32>,
}

impl Inputs {
    /// The same rows for the host kernels.
    pub(crate) fn host(&self) -> HostInputs<'_> {
        HostInputs { batch: self.size, laser: &self.laser, depth: &self.depth, goal: &self.goal }
    }
}

/// The observations `s` (`next`: `s'`) of a batch for the host kernels.
fn batch_inputs(batch: &Batch, next: bool) -> HostInputs<'_> {
    let (laser, depth, goal) = if next {
        (&batch.next_laser, &batch.next_depth, &batch.next_goal)
    } else {
        (&batch.laser, &batch.depth, &batch.goal)
    };
    HostInputs { batch: batch.size, laser, depth, goal }
}

/// Eq. (10) on host rows: `y = r + (1 − terminated) · Q⁻(s', argmax_a' Q(s', a')) · γ`
/// (`γ^steps` for n-step returns), in burn's order of operations; ties go to the first
/// action.
fn host_targets(online_next: &[f32], target_next: &[f32], batch: &Batch, gamma: f32) -> Vec<f32> {
    let actions = online_next.len() / batch.size.max(1);
    (0..batch.size)
        .map(|i| {
            let row = &online_next[i * actions..(i + 1) * actions];
            let best = (0..actions).fold(0, |best, a| if row[a] > row[best] { a } else { best });
            let q_next = target_next[i * actions + best];
            batch.rewards[i] + ((1.0 - batch.terminated[i]) * q_next) * discount(gamma, batch, i)
        })
        .collect()
}

/// The online network, its target copy and the optimiser.
pub struct Learner {
    variant: Variant,
    /// The network's settings: the variant and, for navigation, the goal input.
    net_config: QNetConfig,
    /// Device with autodiff, where the online network trains.
    train_device: Device,
    /// The same device without autodiff, for targets and acting.
    device: Device,
    online: QNet,
    /// `online` without autodiff, refreshed after every optimiser step: acting and the
    /// double-DQN argmax use it, so the module is not re-mapped on every call.
    plain: QNet,
    target: QNet,
    /// The running average of the online weights (`train.average_horizon`), once the first
    /// [`AVERAGE_EVERY`] gradient steps are done: the policy the run evaluates and ships.
    averaged: Option<QNet>,
    /// `train.average_horizon` (0: no average).
    average_horizon: u64,
    /// Adam of the TD loss (eq. 13), and of the auxiliary loss too with
    /// [`AuxOptimizer::Joint`].
    optim: ModuleOptimizer,
    /// The auxiliary loss's own Adam (eq. 12), with [`AuxOptimizer::Separate`] in a variant
    /// with the auxiliary task: it steps the streams, the fusion and the velocity head with
    /// that loss's gradient and its own moments, after `optim`'s step with the TD gradient
    /// of the same forward pass.
    optim_aux: Option<ModuleOptimizer>,
    /// How many parameter updates the fused Adam pass made, and how many went to burn's.
    adam_counts: Arc<AdamCounts>,
    gamma: f32,
    learning_rate: f64,
    aux_weight: f32,
    updates: u64,
    /// See [`Learner::phase_times`].
    phase_ms: [f64; 3],
    /// The last gradient step's TD errors `y − Q(s, a)`, one per row, where its batch had
    /// importance-sampling weights (prioritised replay); empty otherwise.
    td_errors: Vec<f32>,
    /// Independent forwards run on two threads: on burn's `flex` CPU backend each leaves a
    /// core idle in its single-threaded stretches (a measurably shorter MDRLAT step on 2
    /// cores; `docs/performance.md`); LibTorch already spreads every kernel over all cores
    /// and only oversubscribes.
    side_by_side: bool,
    /// Gradient steps on the host kernels where the backend allows (see
    /// [`Learner::uses_host_kernels`]).
    host_kernels: bool,
    /// [`crate::replay::depth_table`] on the device, for batches of frames (made on first use).
    depth_table: std::sync::OnceLock<Tensor<1>>,
}

impl std::fmt::Debug for Learner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Learner")
            .field("variant", &self.variant)
            .field("updates", &self.updates)
            .finish()
    }
}

/// A batch's network inputs: laser stacks, depth input, goals (each where the network reads
/// it).
type NetInputs = (Option<Tensor<3>>, Option<mdrlat_nn::DepthInput>, Option<Tensor<2>>);

/// `inputs` as inputs of a forward with autodiff (constants of its graph).
fn with_autodiff((l, d, g): NetInputs) -> NetInputs {
    let d = d.map(|d| match d {
        mdrlat_nn::DepthInput::Stacks(t) => mdrlat_nn::DepthInput::Stacks(t.autodiff()),
        mdrlat_nn::DepthInput::Patches(t) => mdrlat_nn::DepthInput::Patches(t.autodiff()),
    });
    (l.map(Tensor::autodiff), d, g.map(Tensor::autodiff))
}

/// Laser stacks `[B, 4, 512]` as a tensor.
pub(crate) fn tensor3(data: &[f32], b: usize, device: &Device) -> Tensor<3> {
    Tensor::from_data(TensorData::new(data.to_vec(), [b, FRAME_STACK, LASER_BEAMS]), device)
}

/// Depth stacks `[B, 4, 128, 160]` as the network's input on `device` (see
/// `mdrlat_nn::depth_input`).
pub(crate) fn tensor4(data: &[f32], b: usize, device: &Device) -> mdrlat_nn::DepthInput {
    mdrlat_nn::depth_input(data, b, DEPTH_ROWS, DEPTH_COLS, device)
}

/// Q-values `[B][actions]` (row-major) of `net`, a network of `config` without autodiff on
/// `device`, for a batch of network inputs: the one forward every greedy decision uses.
///
/// # Errors
/// Inputs of the wrong size for the batch, or a backend failure.
pub(crate) fn q_forward(
    net: &QNet,
    config: &QNetConfig,
    device: &Device,
    inputs: &Inputs,
) -> Result<Vec<f32>, PolicyError> {
    q_forward_with(net, None, config, device, inputs)
}

/// The goal stacks `[B, goal_dim]` as a tensor (`None` without a goal input).
fn goal_tensor(goal: &[f32], b: usize, goal_dim: usize, device: &Device) -> Option<Tensor<2>> {
    (goal_dim > 0).then(|| Tensor::from_data(TensorData::new(goal.to_vec(), [b, goal_dim]), device))
}

/// An error unless `inputs` has the sizes a network of `config` reads.
pub(crate) fn check_inputs(config: &QNetConfig, inputs: &Inputs) -> Result<(), PolicyError> {
    let (b, variant) = (inputs.size, config.variant);
    if variant.uses_laser() && inputs.laser.len() != b * FRAME_STACK * LASER_BEAMS {
        return Err(PolicyError::Backend(format!(
            "laser input has {} values, expected {b} x 4 x 512",
            inputs.laser.len()
        )));
    }
    if variant.uses_depth() && inputs.depth.len() != b * FRAME_STACK * DEPTH_ROWS * DEPTH_COLS {
        return Err(PolicyError::Backend(format!(
            "depth input has {} values, expected {b} x 4 x 128 x 160",
            inputs.depth.len()
        )));
    }
    if inputs.goal.len() != b * config.goal_dim {
        return Err(PolicyError::Backend(format!(
            "goal input has {} values, expected {b} x {}",
            inputs.goal.len(),
            config.goal_dim
        )));
    }
    Ok(())
}

/// [`q_forward`], through `host` when given (a host network prepared once, e.g. with
/// bfloat16 weights) instead of one read from `net`.
pub(crate) fn q_forward_with(
    net: &QNet,
    host: Option<&HostNet>,
    config: &QNetConfig,
    device: &Device,
    inputs: &Inputs,
) -> Result<Vec<f32>, PolicyError> {
    check_inputs(config, inputs)?;
    let (b, variant) = (inputs.size, config.variant);
    if b == 0 {
        return Ok(Vec::new());
    }
    if let Some(host) = host {
        return Ok(host.q_values(&inputs.host()));
    }
    if let Some(host) = net.host(config) {
        return Ok(host.q_values(&inputs.host()));
    }
    let l = variant.uses_laser().then(|| tensor3(&inputs.laser, b, device));
    let d = variant.uses_depth().then(|| tensor4(&inputs.depth, b, device));
    let g = goal_tensor(&inputs.goal, b, config.goal_dim, device);
    let q = net.q_values(l, d, g);
    q.into_data()
        .try_to_vec::<f32>()
        .map_err(|e| PolicyError::Backend(format!("reading Q-values: {e:?}")))
}

/// Loads burnpack weights at `path` into `net`, which must be a `variant` network.
///
/// # Errors
/// A missing, truncated or foreign file, or weights of another variant.
pub fn read_net(net: &mut QNet, path: &Path, variant: Variant) -> Result<(), String> {
    if !path.is_file() {
        return Err(format!("{}: missing", path.display()));
    }
    let mut store = BurnpackStore::from_file(path).auto_extension(false);
    load_all(net, &mut store, path, variant)
}

/// The settings of a `variant` network for `task` (a goal input for navigation).
pub fn net_config(variant: Variant, task: Task) -> QNetConfig {
    QNetConfig::new(variant).with_goal_dim(task.goal_dim())
}

/// The weights a warm-started run begins with (`train.init_from`, which must be set), on
/// `device`, and where they came from: the model must be a `config.variant` network for
/// `sim.task`, reading the scan `sim` draws (`sim.laser.depth_memory_frames`). Callers
/// check it before creating a run directory; [`Learner::warm_start`] loads it.
///
/// # Errors
/// No model there, or one of another variant, task or scan.
pub fn init_weights(
    config: &TrainConfig,
    sim: &SimConfig,
    device: &Device,
) -> Result<(QNet, String), TrainError> {
    let err = |problem| TrainError::InitFrom { path: config.init_from.clone(), problem };
    let (net_config, net, source) =
        crate::policy::load_weights(Path::new(&config.init_from), device).map_err(err)?;
    let (model_task, task) = (Task::of_goal_dim(net_config.goal_dim), sim.task);
    if net_config.variant != config.variant || model_task != task {
        return Err(err(format!(
            "the model is a {} network for {model_task}; this run trains a {} network for {task}",
            net_config.variant, config.variant
        )));
    }
    let memory = sim.laser.depth_memory_frames as usize;
    if net_config.depth_memory_frames != memory {
        return Err(err(format!(
            "the model reads {}; this run draws {} (sim.laser.depth_memory_frames)",
            scan_name(net_config.depth_memory_frames),
            scan_name(memory)
        )));
    }
    Ok((net, source))
}

/// The scan a network with `depth_memory_frames` reads, in words.
pub fn scan_name(depth_memory_frames: usize) -> String {
    match depth_memory_frames {
        0 => "the laser's own scan".into(),
        n => format!("the scan with {n} frames of the camera's memory"),
    }
}

/// Loads every tensor of `store` into `net`; a file that does not fit the variant exactly
/// (errors, missing or unexpected tensors) is an error naming `path`.
pub(crate) fn load_all(
    net: &mut QNet,
    store: &mut impl mdrlat_nn::burn::store::ModuleStore,
    path: &Path,
    variant: Variant,
) -> Result<(), String> {
    let r = net.load_from(store).map_err(|e| format!("{}: {e}", path.display()))?;
    if !r.errors.is_empty() || !r.missing.is_empty() || !r.unused.is_empty() {
        return Err(format!(
            "{}: does not fit a {variant} network ({} errors, {} missing, {} unexpected tensors)",
            path.display(),
            r.errors.len(),
            r.missing.len(),
            r.unused.len()
        ));
    }
    Ok(())
}

/// Rewrites a burnpack file with its tensors' data in name order. burn writes an optimiser's
/// state in the order of a hash map, which differs in every process; in name order the same
/// state gives the same file bytes (the tensors are found by name either way).
fn in_name_order(path: &Path) -> Result<(), String> {
    let reader = burn_pack::Reader::from_file(path).map_err(|e| e.to_string())?;
    let metadata = reader.metadata().clone();
    let scalars = reader.scalars().clone();
    let mut tensors = reader.into_tensors().map_err(|e| e.to_string())?;
    tensors.sort_by(|a, b| a.name.cmp(&b.name));
    let mut writer = burn_pack::Writer::new(tensors).auto_extension(false).overwrite(true);
    for (key, value) in &metadata {
        writer = writer.with_metadata(key, value);
    }
    for (key, value) in scalars {
        writer = writer.with_scalar(&key, value);
    }
    writer.write_to_file(path).map_err(|e| e.to_string())
}

/// `γ^steps` of row `i` (γ itself for one step, and for batches made without steps).
fn discount(gamma: f32, batch: &Batch, i: usize) -> f32 {
    match batch.steps.get(i) {
        Some(&k) if k > 1 => gamma.powi(i32::from(k)),
        _ => gamma,
    }
}

/// The TD loss's Adam state in a checkpoint (both losses' with one optimiser).
pub const OPTIMIZER_FILE: &str = "optimizer.bpk";
/// The auxiliary loss's Adam state in a checkpoint, where it has its own.
pub const AUX_OPTIMIZER_FILE: &str = "optimizer-aux.bpk";
/// The averaged network's file in a checkpoint (`train.average_horizon`).
pub const AVERAGE_FILE: &str = "average.bpk";

/// Milliseconds from each of three phase starts to the next, the last up to now.
fn phase_ms(starts: [std::time::Instant; 3]) -> [f64; 3] {
    let now = std::time::Instant::now();
    let ends = [starts[1], starts[2], now];
    std::array::from_fn(|i| (ends[i] - starts[i]).as_secs_f64() * 1e3)
}

/// Hands a host gradient to burn's optimiser, as a tensor of its parameter's rank.
fn register(grads: &mut GradientsParams, g: HostGrad, device: &Device) {
    let id = g.id;
    match g.dims.len() {
        1 => grads.register::<1>(id, g.into_tensor(device)),
        2 => grads.register::<2>(id, g.into_tensor(device)),
        3 => grads.register::<3>(id, g.into_tensor(device)),
        _ => grads.register::<4>(id, g.into_tensor(device)),
    }
}

/// Host gradients as burn's optimiser takes them.
fn to_params(host: Vec<HostGrad>, device: &Device) -> GradientsParams {
    let mut grads = GradientsParams::new();
    for g in host {
        register(&mut grads, g, device);
    }
    grads
}

impl Learner {
    /// A fresh learner of `task` (navigation adds the goal input): the network is
    /// initialised from `seed` on `device`, the target is a copy (Algorithm 1, line 1).
    pub fn new(config: &TrainConfig, task: Task, device: &Device) -> Self {
        let device = device.clone();
        let side_by_side = mdrlat_nn::is_flex(&device);
        let train_device = device.clone().autodiff();
        let net_config = net_config(config.variant, task);
        let online = net_config.init_seeded(&train_device, config.seed);
        let target = online.valid();
        let plain = online.valid();
        let adam = FusedAdam::new(config.adam_epsilon);
        let adam_counts = adam.counts();
        let separate =
            config.variant.auxiliary_task() && config.aux_optimizer == AuxOptimizer::Separate;
        let optim_aux = separate.then(|| adam.clone().into_module_optimizer());
        let optim = adam.into_module_optimizer();
        Self {
            variant: config.variant,
            net_config,
            train_device,
            device,
            online,
            plain,
            target,
            averaged: None,
            average_horizon: config.average_horizon,
            optim,
            optim_aux,
            adam_counts,
            gamma: config.gamma,
            learning_rate: config.learning_rate,
            aux_weight: config.aux_loss_weight,
            updates: 0,
            phase_ms: [0.0; 3],
            td_errors: Vec::new(),
            side_by_side,
            host_kernels: true,
            depth_table: std::sync::OnceLock::new(),
        }
    }

    /// Records the scan the network reads (`sim.laser.depth_memory_frames`): its models
    /// carry it ([`crate::export::DEPTH_MEMORY_KEY`]).
    pub fn set_depth_memory_frames(&mut self, frames: u32) {
        self.net_config.depth_memory_frames = frames as usize;
    }

    /// The variant.
    pub fn variant(&self) -> Variant {
        self.variant
    }

    /// The task it learns: navigation when the network reads a goal.
    pub fn task(&self) -> Task {
        Task::of_goal_dim(self.net_config.goal_dim)
    }

    /// The network's settings.
    pub fn net_config(&self) -> &QNetConfig {
        &self.net_config
    }

    /// Gradient steps taken.
    pub fn updates(&self) -> u64 {
        self.updates
    }

    /// The last gradient step's TD errors `y − Q(s, a)`, one per row of its batch, where
    /// the batch had importance-sampling weights (prioritised replay: the rows' new
    /// priorities); empty otherwise.
    pub fn td_errors(&self) -> &[f32] {
        &self.td_errors
    }

    /// How this learner wants its batches' depth input: as frames on LibTorch (the CPU or a
    /// GPU builds the stacks, from a third of the bytes), as stacks elsewhere (the host
    /// kernels read them, and `flex` cuts patches from them on the host).
    pub fn depth_layout(&self) -> DepthLayout {
        if self.variant.uses_depth() && mdrlat_nn::is_libtorch(&self.device) {
            DepthLayout::Frames
        } else {
            DepthLayout::Stacks
        }
    }

    /// A batch's distinct depth frames on the device, normalised (`[F, 128 × 160]`), where
    /// the batch carries frames ([`DepthLayout::Frames`]): the stored millimetres go as
    /// 16-bit integers and become network inputs through [`crate::replay::depth_table`], so
    /// the stacks hold exactly the values of [`DepthLayout::Stacks`].
    fn device_frames(&self, batch: &Batch) -> Option<Tensor<2>> {
        let frames = &batch.depth_frames;
        if frames.is_empty() {
            return None;
        }
        let table = self.depth_table.get_or_init(|| {
            // Entry j is the value of the millimetres whose bits read j − 32768 as an i16.
            let t = crate::replay::depth_table();
            let rotated: Vec<f32> =
                (0..1usize << 16).map(|j| t[(j + (1 << 15)) & 0xFFFF]).collect();
            Tensor::from_data(TensorData::new(rotated, [1 << 16]), &self.device)
        });
        // The bits of each u16 as an i16 (16-bit integers travel as they are).
        let mm: Vec<i16> = frames.mm.iter().map(|&v| v as i16).collect();
        let mm = Tensor::<1, Int>::from_data(
            TensorData::new(mm, [frames.mm.len()]),
            mdrlat_nn::burn::tensor::TensorCreationOptions::new(self.device.clone())
                .with_dtype(mdrlat_nn::burn::tensor::DType::I16),
        );
        let index = mm.cast(mdrlat_nn::burn::tensor::IntDType::I64) + (1 << 15);
        Some(table.clone().select(0, index).reshape([frames.len(), DEPTH_ROWS * DEPTH_COLS]))
    }

    /// Puts a batch's depth inputs of `s` and `s'` on the device as a gradient step does
    /// (for `bench train --profile`; on a GPU it returns once the host's copies and the
    /// transfer are done, before the kernels that build the stacks have run).
    pub fn depth_to_device(&self, batch: &Batch) {
        let frames = self.device_frames(batch);
        for next in [false, true] {
            let _ = self.inputs(batch, frames.as_ref(), next);
        }
    }

    /// A batch's `s` (`next`: `s'`) as the network's input tensors on the plain device (see
    /// [`with_autodiff`] for the online forward); the depth stacks from `frames` (of
    /// [`Learner::device_frames`]) where the batch carries frames.
    fn inputs(&self, batch: &Batch, frames: Option<&Tensor<2>>, next: bool) -> NetInputs {
        let dev = &self.device;
        let (laser, depth, goal) = if next {
            (&batch.next_laser, &batch.next_depth, &batch.next_goal)
        } else {
            (&batch.laser, &batch.depth, &batch.goal)
        };
        let b = batch.size;
        let depth = self.variant.uses_depth().then(|| match frames {
            Some(frames) => {
                let rows = if next { &batch.depth_frames.next } else { &batch.depth_frames.obs };
                let rows =
                    Tensor::<1, Int>::from_data(TensorData::new(rows.clone(), [rows.len()]), dev);
                mdrlat_nn::DepthInput::Stacks(frames.clone().select(0, rows).reshape([
                    b,
                    FRAME_STACK,
                    DEPTH_ROWS,
                    DEPTH_COLS,
                ]))
            }
            None => tensor4(depth, b, dev),
        });
        (
            self.variant.uses_laser().then(|| tensor3(laser, b, dev)),
            depth,
            goal_tensor(goal, b, self.net_config.goal_dim, dev),
        )
    }

    /// Q-values of the online network for a batch of network inputs, `[B][actions]`
    /// row-major (empty if the backend failed).
    pub fn q_values(&self, inputs: &Inputs) -> Vec<f32> {
        q_forward(&self.plain, &self.net_config, &self.device, inputs).unwrap_or_default()
    }

    /// The greedy action of each row of `inputs` (Algorithm 1, line 3, without
    /// exploration), by the one rule of [`mdrlat_core::greedy_actions`].
    ///
    /// # Errors
    /// A non-finite Q-value (the network diverged), or a backend failure.
    pub fn greedy(&self, inputs: &Inputs) -> Result<Vec<Action>, PolicyError> {
        let q = q_forward(&self.plain, &self.net_config, &self.device, inputs)?;
        let mut out = Vec::with_capacity(inputs.size);
        greedy_actions(&q, inputs.size, &mut out)?;
        Ok(out)
    }

    /// The online network's greedy policy (a snapshot of the current weights), acting on
    /// `threads` CPU threads: training's evaluation runs it through the episode runner.
    /// Drop it before the next update, so the fused Adam may write the weights in place.
    ///
    /// # Errors
    /// The thread pool cannot start.
    pub fn greedy_policy(&self, threads: usize) -> Result<crate::GreedyPolicy, String> {
        let which = if self.averaged.is_some() { "averaged" } else { "online" };
        crate::GreedyPolicy::from_net(
            self.net_config.clone(),
            self.policy_net(),
            &self.device,
            threads,
            format!("{which} network, update {}", self.updates),
        )
    }

    /// Algorithm 1, lines 7–11, eq. (10): `y = r + γ (1 − terminated) Q⁻(s', argmax_a' Q(s', a'))`.
    /// Only `terminated` zeroes the bootstrap: a time-limit truncation bootstraps.
    ///
    /// # Shapes
    /// `[B, 1]`, on the plain device.
    fn targets(&self, batch: &Batch, frames: Option<&Tensor<2>>) -> Tensor<2> {
        let b = batch.size;
        let (nl, nd, ng) = self.inputs(batch, frames, true);
        let (online_next, target_next) = self.both(
            || self.plain.q_values(nl.clone(), nd.clone(), ng.clone()),
            || self.target.q_values(nl.clone(), nd.clone(), ng.clone()),
        );
        let best_next = online_next.argmax(1); // [B, 1]
        let q_next = target_next.gather(1, best_next); // [B, 1]
        let rewards =
            Tensor::<2>::from_data(TensorData::new(batch.rewards.clone(), [b, 1]), &self.device);
        let alive: Vec<f32> = batch.terminated.iter().map(|t| 1.0 - t).collect();
        let alive = Tensor::<2>::from_data(TensorData::new(alive, [b, 1]), &self.device);
        if batch.steps.iter().all(|&k| k <= 1) {
            return rewards + alive * q_next * self.gamma;
        }
        // n-step returns: each row's bootstrap discounted by γ^steps.
        let discounts: Vec<f32> = (0..b).map(|i| discount(self.gamma, batch, i)).collect();
        let discounts = Tensor::<2>::from_data(TensorData::new(discounts, [b, 1]), &self.device);
        rewards + alive * q_next * discounts
    }

    /// The TD targets `y` of a batch (eq. 10), for tests and diagnostics.
    #[doc(alias = "eq10")]
    pub fn td_targets(&self, batch: &Batch) -> Vec<f32> {
        if let Some((online, target)) = self.host_nets_for(batch) {
            let next = batch_inputs(batch, true);
            let (qo, qt) = rayon::join(|| online.q_values(&next), || target.q_values(&next));
            return host_targets(&qo, &qt, batch, self.gamma);
        }
        let frames = self.device_frames(batch);
        self.targets(batch, frames.as_ref()).into_data().try_to_vec::<f32>().unwrap_or_default()
    }

    /// The online (autodiff-free copy) and target networks for the host kernels, on `flex`
    /// unless they are switched off.
    fn host_nets(&self) -> Option<(HostNet, HostNet)> {
        if !self.host_kernels {
            return None;
        }
        let config = &self.net_config;
        Some((self.plain.host(config)?, self.target.host(config)?))
    }

    /// [`Learner::host_nets`] for `batch`: a batch of depth frames goes to burn's path,
    /// which builds the stacks on the device.
    fn host_nets_for(&self, batch: &Batch) -> Option<(HostNet, HostNet)> {
        self.host_nets().filter(|_| batch.depth_frames.is_empty())
    }

    /// Whether gradient steps run on the host kernels (`mdrlat_nn::host`): on `flex`, unless
    /// switched off with [`Learner::set_host_kernels`].
    pub fn uses_host_kernels(&self) -> bool {
        self.host_nets().is_some()
    }

    /// Switches the host kernels off (burn's autodiff computes the gradients, as on every
    /// other backend) or back on: for benchmarks and tests that compare the two.
    pub fn set_host_kernels(&mut self, on: bool) {
        self.host_kernels = on;
    }

    /// Q⁻(s', a) of the target network for every action, `[B][actions]` row-major.
    pub fn target_q_next(&self, batch: &Batch) -> Vec<f32> {
        if let Some((_, target)) = self.host_nets_for(batch) {
            return target.q_values(&batch_inputs(batch, true));
        }
        let frames = self.device_frames(batch);
        let (nl, nd, ng) = self.inputs(batch, frames.as_ref(), true);
        self.target.q_values(nl, nd, ng).into_data().try_to_vec::<f32>().unwrap_or_default()
    }

    /// Runs two independent computations, side by side where that pays (see
    /// `side_by_side`).
    fn both<A: Send, B: Send>(
        &self,
        a: impl FnOnce() -> A + Send,
        b: impl FnOnce() -> B + Send,
    ) -> (A, B) {
        if self.side_by_side { rayon::join(a, b) } else { (a(), b()) }
    }

    /// Lines 10–11 (targets, no autodiff) and the online forward of line 12 (with autodiff):
    /// they do not depend on each other, so they run side by side.
    fn targets_and_forward(&self, batch: &Batch) -> (Tensor<2>, mdrlat_nn::QOutput) {
        let frames = self.device_frames(batch);
        let frames = frames.as_ref();
        self.both(
            || self.targets(batch, frames),
            || {
                let (l, d, g) = with_autodiff(self.inputs(batch, frames, false));
                self.online.forward(l, d, g)
            },
        )
    }

    /// Milliseconds of the last gradient step's three phases: targets beside the online
    /// forward (lines 10–12), the losses and backward pass, the Adam step (line 15) and the
    /// read of the losses. On the host kernels the second phase is the heads' backward, the
    /// third the rest of the backward beside the heads' and the fusion's Adam steps, then the
    /// streams' Adam step. On a GPU the first two are the time to queue their work, and the
    /// third waits, in the read, for the whole step.
    pub fn phase_times(&self) -> [f64; 3] {
        self.phase_ms
    }

    /// Parameter updates of the Adam steps so far: `(fused, through burn's Adam)`. On the CPU
    /// backends and LibTorch GPUs every step after the first is fused (in place), except the
    /// one after each target sync (the target then shares the online weights, which must not
    /// change under it).
    pub fn adam_paths(&self) -> (u64, u64) {
        (self.adam_counts.fused(), self.adam_counts.fallback())
    }

    /// One gradient step on a sampled batch (Algorithm 1, lines 7–15).
    pub fn update(&mut self, batch: &Batch) -> Losses {
        let t0 = std::time::Instant::now();
        let losses = match self.host_nets_for(batch) {
            Some((online, target)) => self.host_update(online, &target, batch, t0),
            None => {
                let (grads, aux_grads, losses, t1) = self.gradients(batch);
                let t2 = std::time::Instant::now();
                let online = self.take_online();
                let mut online = self.optim.step(self.learning_rate, online, grads);
                if let (Some(optim), Some(grads)) = (self.optim_aux.as_mut(), aux_grads) {
                    online = optim.step(self.learning_rate, online, grads);
                }
                self.online = online;
                self.plain = self.online.valid();
                // Read once the Adam step is queued too (a read waits for the device).
                let (losses, td_errors) = losses.read();
                self.td_errors = td_errors;
                self.phase_ms = phase_ms([t0, t1, t2]);
                losses
            }
        };
        self.updates += 1;
        if self.average_horizon > 0 && self.updates.is_multiple_of(AVERAGE_EVERY) {
            self.move_average();
        }
        losses
    }

    /// One move of the averaged network toward the online one (see
    /// [`TrainConfig::average_horizon`]): the `n`-th move weighs the online weights
    /// `max(AVERAGE_EVERY / horizon, 1 / n)`; the first copies them.
    fn move_average(&mut self) {
        let n = self.updates / AVERAGE_EVERY;
        let w = (AVERAGE_EVERY as f64 / self.average_horizon as f64).max(1.0 / n as f64);
        let from = self.averaged.as_ref().unwrap_or(&self.plain);
        let moved = from.blend_toward(&self.plain, w.min(1.0) as f32);
        self.averaged = Some(moved.unwrap_or_else(|e| unreachable!("one architecture: {e}")));
    }

    /// The online network, moved out for line 15's Adam step, with the stale
    /// autodiff-free copy dropped first, so that each parameter has a single owner and the
    /// fused pass may update it in place. (The placeholder is never used: a panic in the
    /// step is a bug that ends the run.)
    fn take_online(&mut self) -> QNet {
        let online = std::mem::replace(&mut self.online, self.target.clone());
        self.plain = self.target.clone();
        online
    }

    /// [`Learner::update`] on the host kernels. The heads' gradients come first in the
    /// backward pass; their Adam step (line 15 for 55 % of MDRLAT's parameters: a
    /// memory-bound pass) runs beside the fusion's backward (compute-bound products), the
    /// fusion's Adam step beside the streams' backward, then the streams' Adam step. Each
    /// parameter's update is the same arithmetic on the same gradient as in one step after
    /// the whole backward pass, so the result is the same bytes (checked against that
    /// order: 1,300-step MDRLAT and 1,200-step multi-AT runs wrote identical model and
    /// optimiser files).
    fn host_update(
        &mut self,
        mut online: HostNet,
        target: &HostNet,
        batch: &Batch,
        t0: std::time::Instant,
    ) -> Losses {
        let (tape, dq, dvel, losses, td_errors) = self.host_losses(&online, target, batch);
        self.td_errors = td_errors;
        let t1 = std::time::Instant::now();
        if self.optim_aux.is_some() {
            return self.host_update_separate(
                online,
                &tape,
                &dq,
                dvel.as_deref(),
                losses,
                [t0, t1],
            );
        }
        let (head_grads, dh) = online.backward_heads(&tape, &dq, dvel.as_deref());
        online.release_heads();
        let t2 = std::time::Instant::now();
        let device = self.device.clone();
        let to_params = |host| to_params(host, &device);
        let head_grads = to_params(head_grads);
        let net = self.take_online();
        let (optim, lr) = (&mut self.optim, self.learning_rate);
        let mut clock = mdrlat_nn::host::StageClock::start();
        let (net, (fusion_grads, d_feat)) = rayon::join(
            || optim.step(lr, net, head_grads),
            || online.backward_fusion(&tape, &dh, &mut clock),
        );
        online.release_fusion();
        let fusion_grads = to_params(fusion_grads);
        let (net, stream_grads) = rayon::join(
            || optim.step(lr, net, fusion_grads),
            || online.backward_streams(&tape, &d_feat, &mut clock),
        );
        // The network's last references to the streams' weights go before their step.
        drop(online);
        self.online = self.optim.step(lr, net, to_params(stream_grads));
        self.plain = self.online.valid();
        self.phase_ms = phase_ms([t0, t1, t2]);
        losses
    }

    /// [`Learner::host_update`] with the auxiliary loss's own Adam: the backward pass of the
    /// fusion and the streams runs once for each loss's share of the representation's
    /// gradient (the host kernels' tape is read twice, unlike burn's graph), then the TD
    /// loss's Adam steps with its gradient and the auxiliary loss's Adam with the other.
    fn host_update_separate(
        &mut self,
        mut online: HostNet,
        tape: &mdrlat_nn::host::Tape,
        dq: &[f32],
        dvel: Option<&[f32]>,
        losses: Losses,
        [t0, t1]: [std::time::Instant; 2],
    ) -> Losses {
        let (mut td_grads, dh_td, aux) = online.backward_heads_parts(tape, dq, dvel);
        online.release_heads();
        let t2 = std::time::Instant::now();
        let mut clock = mdrlat_nn::host::StageClock::start();
        let mut rest = |grads: &mut Vec<HostGrad>, dh: &[f32]| {
            let (fusion, d_feat) = online.backward_fusion(tape, dh, &mut clock);
            grads.extend(fusion);
            grads.extend(online.backward_streams(tape, &d_feat, &mut clock));
        };
        rest(&mut td_grads, &dh_td);
        let aux_grads = aux.map(|(mut grads, dh)| {
            rest(&mut grads, &dh);
            grads
        });
        drop(online);
        let device = self.device.clone();
        let to_params = |host| to_params(host, &device);
        let lr = self.learning_rate;
        let net = self.take_online();
        let mut net = self.optim.step(lr, net, to_params(td_grads));
        if let (Some(optim), Some(grads)) = (self.optim_aux.as_mut(), aux_grads) {
            net = optim.step(lr, net, to_params(grads));
        }
        self.online = net;
        self.plain = self.online.valid();
        self.phase_ms = phase_ms([t0, t1, t2]);
        losses
    }

    /// Lines 7–14: the targets, the losses and their gradients: of their weighted sum, or with
    /// a separate auxiliary optimiser the TD loss's and (second) the auxiliary loss's apart.
    /// Every tensor of the autodiff graph is dropped on return, so the graph holds no
    /// parameter any more. The instant is the end of the forward phase (on a GPU: of queueing
    /// it).
    fn gradients(
        &self,
        batch: &Batch,
    ) -> (GradientsParams, Option<GradientsParams>, PendingLosses, std::time::Instant) {
        let b = batch.size;
        let (y, out) = self.targets_and_forward(batch);
        // A constant of the graph, where it was computed (no round trip through the host).
        let y = y.autodiff();
        let t1 = std::time::Instant::now();

        // Line 12, eq. (13): (y − Q(s, a))².
        let actions = Tensor::<2, Int>::from_data(
            TensorData::new(batch.actions.clone(), [b, 1]),
            &self.train_device,
        );
        let q_sa = out.q.gather(1, actions); // [B, 1]
        let q_mean = q_sa.clone().inner().mean(); // [1]
        // With prioritised replay each row's square weighs its importance-sampling weight,
        // and the rows' errors go back with the losses (the replay's new priorities).
        let (td, errors) = if batch.weights.is_empty() {
            ((y - q_sa).square().mean(), None) // [1]
        } else {
            let w = Tensor::<2>::from_data(
                TensorData::new(batch.weights.clone(), [b, 1]),
                &self.train_device,
            );
            let err = y - q_sa;
            let errors = err.clone().inner().reshape([b]);
            ((err.square() * w).mean(), Some(errors))
        };

        // Lines 13–14, eq. (12): Σ over t−2..t of (v − ṽ)² + (ω − ω̃)².
        let aux_loss = |v_hat: Tensor<2>| {
            let target = Tensor::<2>::from_data(
                TensorData::new(batch.odom.clone(), [b, 2 * ODOM_HISTORY]),
                &self.train_device,
            );
            (target - v_hat).square().sum_dim(1).mean() // [1]
        };
        let at = out.velocity.map(aux_loss);
        let (loss, aux_grads) = match (&at, &self.optim_aux) {
            (Some(at), None) => (td.clone() + at.clone() * self.aux_weight, None),
            (Some(_), Some(_)) => {
                // burn back-propagates once through a graph: the auxiliary loss's gradient
                // comes from a second forward pass over s, with the same weights.
                let frames = self.device_frames(batch);
                let (l, d, g) = with_autodiff(self.inputs(batch, frames.as_ref(), false));
                let v_hat = self.online.forward(l, d, g).velocity.expect("the auxiliary head");
                let at = aux_loss(v_hat) * self.aux_weight;
                (td.clone(), Some(GradientsParams::from_grads(at.backward(), &self.online)))
            }
            (None, _) => (td.clone(), None),
        };
        let grads = GradientsParams::from_grads(loss.backward(), &self.online);
        let at = at.map_or_else(|| Tensor::zeros([1], &self.device), Tensor::inner);
        let parts = [td.inner(), at, q_mean].into_iter().chain(errors).collect();
        let losses = PendingLosses(Tensor::cat(parts, 0));
        (grads, aux_grads, losses, t1)
    }

    /// Lines 7–14 on the host kernels, up to the backward pass: the two eq. (10) forwards on
    /// `s'` beside the online forward on `s`, then the losses and their gradients with
    /// respect to the Q-values and the velocity estimates. The backward pass is
    /// hand-written (tested equal to burn's autodiff in `mdrlat_nn::host`). Last, the rows'
    /// TD errors where the batch has importance-sampling weights (else empty).
    #[allow(clippy::type_complexity)]
    fn host_losses<'a>(
        &self,
        online: &HostNet,
        target: &HostNet,
        batch: &'a Batch,
    ) -> (mdrlat_nn::host::Tape<'a>, Vec<f32>, Option<Vec<f32>>, Losses, Vec<f32>) {
        let b = batch.size;
        let aux = self.variant.auxiliary_task();
        let (next, now) = (batch_inputs(batch, true), batch_inputs(batch, false));
        // The online pass over s (kept for the backward pass) and over s' stacked into one
        // 64-row pass, which reads the online weights once for both, beside the target pass
        // over s' (eq. 10). Same bytes as three 32-row passes side by side. With the
        // row-panel forward kernel (`gemm_short_by_long`) real MDRLAT runs were faster
        // stacked than with three passes (and faster than before that kernel); with the
        // earlier kernel stacking had lost (side-by-side runs: `docs/performance.md`).
        let (tape, target_next) = rayon::join(
            || online.forward_parts(&[now, next], if aux { b } else { 0 }),
            || target.q_values(&next),
        );
        let online_next = &tape.q()[tape.q().len() / 2..];
        let actions = online_next.len() / b.max(1);
        let y = host_targets(online_next, &target_next, batch, self.gamma);
        // Eq. (13): mean over the batch of (y − Q(s, a))², each row's weighted by its
        // importance-sampling weight with prioritised replay (1 otherwise: the same bits);
        // its gradient reaches Q(s, a) only.
        let mut dq = vec![0.0f32; b * actions];
        let (mut td, mut q_sum) = (0.0f32, 0.0f32);
        let mut errors = Vec::new();
        for i in 0..b {
            let a = usize::try_from(batch.actions[i]).unwrap_or(0).min(actions - 1);
            let q_sa = tape.q()[i * actions + a];
            let err = y[i] - q_sa;
            let w = batch.weights.get(i).copied().unwrap_or(1.0);
            if !batch.weights.is_empty() {
                errors.push(err);
            }
            td += w * err * err;
            q_sum += q_sa;
            dq[i * actions + a] = -2.0 * w * err / b as f32;
        }
        let (td, q_mean) = (td / b as f32, q_sum / b as f32);
        // Eq. (12): mean over the batch of Σ_j (v_j − ṽ_j)², weighted into the loss.
        let (at, dvel) = if aux {
            let (est, n) = (tape.velocity(), 2 * ODOM_HISTORY);
            let mut at = 0.0f32;
            let mut dvel = vec![0.0f32; b * n];
            for i in 0..b {
                let mut row = 0.0f32;
                for j in 0..n {
                    let err = batch.odom[i * n + j] - est[i * n + j];
                    row += err * err;
                    dvel[i * n + j] = -2.0 * self.aux_weight * err / b as f32;
                }
                at += row;
            }
            (at / b as f32, Some(dvel))
        } else {
            (0.0, None)
        };
        (tape, dq, dvel, Losses { td, at, q_mean }, errors)
    }

    /// Saves the online and target weights and the Adam moments into `dir` (burnpack files,
    /// which keep parameter ids so the optimiser state matches on load).
    ///
    /// # Errors
    /// A file cannot be written.
    pub fn save(&self, dir: &Path) -> Result<(), String> {
        let store = |name: &str| {
            BurnpackStore::from_file(dir.join(name)).overwrite(true).auto_extension(false)
        };
        self.online.save_into(&mut store("online.bpk")).map_err(|e| format!("online.bpk: {e}"))?;
        self.target.save_into(&mut store("target.bpk")).map_err(|e| format!("target.bpk: {e}"))?;
        if let Some(averaged) = &self.averaged {
            averaged
                .save_into(&mut store(AVERAGE_FILE))
                .map_err(|e| format!("{AVERAGE_FILE}: {e}"))?;
        }
        let optimizers = std::iter::once((OPTIMIZER_FILE, &self.optim))
            .chain(self.optim_aux.as_ref().map(|o| (AUX_OPTIMIZER_FILE, o)));
        for (name, optim) in optimizers {
            let path = dir.join(name);
            optim.save(&path).map_err(|e| format!("{name}: {e}"))?;
            in_name_order(&path).map_err(|e| format!("{name}: {e}"))?;
        }
        Ok(())
    }

    /// A learner of `task` restored from [`Learner::save`] files, `updates` gradient steps
    /// in.
    ///
    /// # Errors
    /// A missing, truncated or foreign file, or weights of another variant or task.
    pub fn load(
        config: &TrainConfig,
        task: Task,
        device: &Device,
        dir: &Path,
        updates: u64,
    ) -> Result<Self, String> {
        let mut learner = Learner::new(config, task, device);
        let read = |net: &mut QNet, name: &str| read_net(net, &dir.join(name), config.variant);
        read(&mut learner.online, "online.bpk")?;
        learner.plain = learner.online.valid();
        let mut target = learner.net_config.init(&learner.device);
        read(&mut target, "target.bpk")?;
        learner.target = target;
        let averaged = dir.join(AVERAGE_FILE);
        let expected = config.average_horizon > 0 && updates >= AVERAGE_EVERY;
        match (expected, averaged.exists()) {
            (true, true) => {
                let mut net = learner.net_config.init(&learner.device);
                read(&mut net, AVERAGE_FILE)?;
                learner.averaged = Some(net);
            }
            (true, false) => {
                return Err(format!(
                    "{}: missing, yet the run keeps an average of its weights \
                     (train.average_horizon = {})",
                    averaged.display(),
                    config.average_horizon
                ));
            }
            (false, true) => {
                return Err(format!(
                    "{}: an averaged network, yet the run's config keeps none \
                     (train.average_horizon = 0)",
                    averaged.display()
                ));
            }
            (false, false) => {}
        }
        let path = dir.join(OPTIMIZER_FILE);
        learner.optim =
            learner.optim.load(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        let aux_path = dir.join(AUX_OPTIMIZER_FILE);
        match learner.optim_aux.take() {
            Some(_) if !aux_path.exists() => {
                return Err(format!(
                    "{}: missing: this checkpoint was trained with one Adam for both losses \
                     (train.aux_optimizer = \"joint\"), its config asks for two",
                    aux_path.display()
                ));
            }
            Some(optim) => {
                let optim =
                    optim.load(&aux_path).map_err(|e| format!("{}: {e}", aux_path.display()))?;
                learner.optim_aux = Some(optim);
            }
            None if aux_path.exists() => {
                return Err(format!(
                    "{}: this checkpoint was trained with a second Adam for the auxiliary loss \
                     (train.aux_optimizer = \"separate\"), its config asks for one",
                    aux_path.display()
                ));
            }
            None => {}
        }
        learner.updates = updates;
        Ok(learner)
    }

    /// A warm start (`train.init_from`): the online, acting and target networks take the
    /// weights of the trained model `config.init_from` (see [`init_weights`]); the
    /// optimisers and the averaged network stay fresh.
    ///
    /// # Errors
    /// No model there, or one of another variant, task or scan.
    pub fn warm_start(&mut self, config: &TrainConfig, sim: &SimConfig) -> Result<(), TrainError> {
        (self.online, _) = init_weights(config, sim, &self.train_device)?;
        self.plain = self.online.valid();
        self.target = self.plain.clone();
        Ok(())
    }

    /// Lines 16–17: θ⁻ ← θ.
    pub fn sync_target(&mut self) {
        self.target = self.plain.clone();
    }

    /// Forward and backward times of each stage of the online network on `batch`
    /// (with autodiff, as in a gradient step), milliseconds.
    pub fn stage_times(&self, batch: &Batch) -> Vec<mdrlat_nn::StageTime> {
        let frames = self.device_frames(batch);
        let (l, d, g) = with_autodiff(self.inputs(batch, frames.as_ref(), false));
        self.online.stage_times(l, d, g, true)
    }

    /// On the host kernels: each stage's forward and backward milliseconds of one pass of
    /// the online network over `batch` (as in a gradient step: the auxiliary head included,
    /// unit loss gradients), in forward order; `None` off the host kernels.
    pub fn host_stage_times(&self, batch: &Batch) -> Option<Vec<mdrlat_nn::StageTime>> {
        let (online, _) = self.host_nets_for(batch)?;
        let aux = self.variant.auxiliary_task();
        let tape = online.forward(&batch_inputs(batch, false), aux);
        let dq = vec![1.0 / batch.size.max(1) as f32; tape.q().len()];
        let dvel = aux.then(|| vec![1.0; tape.velocity().len()]);
        let (_, backward) = online.backward_timed(&tape, &dq, dvel.as_deref());
        let stages = tape.times.stages.iter().map(|&(name, forward_ms)| {
            let backward_ms = backward
                .stages
                .iter()
                .filter(|(b, _)| b.starts_with(name))
                .map(|(_, ms)| ms)
                .sum::<f64>();
            mdrlat_nn::StageTime { name, forward_ms, backward_ms: Some(backward_ms) }
        });
        Some(stages.collect())
    }

    /// The policy the run evaluates and ships, without autodiff: the averaged network where
    /// the run keeps one (`train.average_horizon`), else the online network.
    pub fn policy_net(&self) -> QNet {
        self.averaged.as_ref().unwrap_or(&self.plain).clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::replay::{ReplayBuffer, Transition};
    use mdrlat_core::DEPTH_LEN;

    /// The averaged policy's arithmetic (`train.average_horizon` = 200, moves every 100
    /// gradient steps): the first move copies the online weights, the second takes the mean
    /// of the two snapshots (`w = max(100/200, 1/2)`), the third weighs the online weights
    /// `max(1/2, 1/3)`; acting still uses the online network.
    #[test]
    fn the_averaged_policy_is_the_running_mean_then_the_exponential_average() {
        let config = TrainConfig {
            variant: Variant::LaserOnly,
            average_horizon: 200,
            ..TrainConfig::default()
        };
        let mut learner = Learner::new(&config, Task::Avoid, &Device::flex());
        let mut snapshots = Vec::new();
        for k in 0..300u64 {
            learner.update(&crate::bench::random_batch(Variant::LaserOnly, 8, k));
            if (k + 1) % AVERAGE_EVERY == 0 {
                snapshots.push(learner.plain.flat_weights());
            }
        }
        assert!(learner.averaged.is_some(), "an average after 100 gradient steps");
        let (p1, p2, p3) = (&snapshots[0], &snapshots[1], &snapshots[2]);
        let after_two: Vec<f32> = p1.iter().zip(p2).map(|(&a, &b)| a * 0.5 + b * 0.5).collect();
        let want: Vec<f32> = after_two.iter().zip(p3).map(|(&a, &b)| a * 0.5 + b * 0.5).collect();
        assert_eq!(learner.policy_net().flat_weights(), want);
        assert_ne!(
            learner.policy_net().flat_weights(),
            *p3,
            "the policy is not the online network"
        );
    }

    /// The stacks a learner builds on its device from a batch's frames are the replay's own
    /// stacks, bit for bit — including millimetres above 32,767, which travel as negative
    /// 16-bit integers.
    /// `n` transitions of one episode whose depth frames cycle through values from 0 to beyond
    /// 65.535 m (stored 65,535 mm) and NaN (stored 0), frame `f`'s pixel `j` reading value
    /// `(7j + f) mod 9`.
    fn replay_with_far_depths(n: usize) -> ReplayBuffer {
        let metres = [0.0, 0.4, 1.234, 9.999, 32.767, 32.768, 50.0, 70.0, f32::NAN];
        let mut replay = ReplayBuffer::new(n, n + 8, true, true);
        let ids: Vec<_> = (0..n + FRAME_STACK)
            .map(|f| {
                let depth: Vec<f32> =
                    (0..DEPTH_LEN).map(|j| metres[(j * 7 + f) % metres.len()]).collect();
                let laser = [0.5 + f as f32 * 0.1; LASER_BEAMS];
                replay.push_frame(&laser, &depth)
            })
            .collect();
        for t in 0..n {
            let stack = |s: usize| std::array::from_fn(|k| ids[s + k]);
            replay.push(Transition {
                steps: 1,
                obs: stack(t),
                next: stack(t + 1),
                action: (t % 10) as u8,
                reward: 0.5 - t as f32 * 0.1,
                terminated: t % 5 == 4,
                odom: std::array::from_fn(|k| 0.1 * k as f32),
                goal: [0.0; 3],
                next_goal: [0.0; 3],
            });
        }
        replay
    }

    #[test]
    fn stacks_built_from_frames_on_the_device_are_the_replay_stacks() {
        let replay = replay_with_far_depths(3);
        let indices = [2, 0, 2, 1];
        let (mut stacks, mut frames) = (Batch::default(), Batch::default());
        replay.write_batch_as(&indices, &mut stacks, DepthLayout::Stacks);
        replay.write_batch_as(&indices, &mut frames, DepthLayout::Frames);
        assert_eq!(frames.depth_frames.len(), 7, "frames 0..=6, each once");

        let config = TrainConfig { variant: Variant::Mdrlat, ..TrainConfig::default() };
        let learner = Learner::new(&config, Task::Avoid, &Device::flex());
        let on_device = learner.device_frames(&frames).expect("a batch of frames");
        for (next, want) in [(false, &stacks.depth), (true, &stacks.next_depth)] {
            let (_, depth, _) = learner.inputs(&frames, Some(&on_device), next);
            let Some(mdrlat_nn::DepthInput::Stacks(depth)) = depth else {
                panic!("frames give stacks");
            };
            assert_eq!(depth.dims(), [4, FRAME_STACK, DEPTH_ROWS, DEPTH_COLS]);
            let got: Vec<u32> = depth
                .into_data()
                .try_to_vec::<f32>()
                .expect("f32")
                .iter()
                .map(|v| v.to_bits())
                .collect();
            let want: Vec<u32> = want.iter().map(|v| v.to_bits()).collect();
            assert!(got == want, "s{} differs", if next { "'" } else { "" });
        }
    }

    /// On LibTorch (here its CPU), gradient steps on a batch of frames give the same bytes as
    /// on the same batch of stacks, millimetres above 32,767 included (`cargo test --features
    /// tch`, with LibTorch set up).
    #[cfg(feature = "tch")]
    #[test]
    #[allow(deprecated)] // burn-tch is deprecated upstream; it is our `tch` backend.
    fn libtorch_steps_on_frames_equal_steps_on_stacks() {
        let device = Device::libtorch();
        let config = TrainConfig { variant: Variant::Mdrlat, ..TrainConfig::default() };
        let replay = replay_with_far_depths(12);
        let mut learners = [false, true].map(|_| Learner::new(&config, Task::Avoid, &device));
        assert_eq!(learners[0].depth_layout(), DepthLayout::Frames);
        let mut losses = [Vec::new(), Vec::new()];
        for step in 0..3usize {
            let indices: Vec<usize> = (0..6).map(|i| (i * 5 + step * 3) % 12).collect();
            for (k, layout) in [DepthLayout::Stacks, DepthLayout::Frames].into_iter().enumerate() {
                let mut batch = Batch::default();
                replay.write_batch_as(&indices, &mut batch, layout);
                losses[k].push(learners[k].update(&batch));
            }
        }
        assert_eq!(losses[0], losses[1]);
        let weights = |l: &Learner| {
            let mut batch = Batch::default();
            replay.write_batch_as(&[0, 7], &mut batch, DepthLayout::Stacks);
            l.target_q_next(&batch).iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        };
        learners.iter_mut().for_each(Learner::sync_target);
        assert!(weights(&learners[0]) == weights(&learners[1]));
    }
}
