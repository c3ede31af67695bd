//! Measuring the learner: gradient-step time per variant, single-decision inference latency
//! and replay memory.

use crate::config::TrainConfig;
use crate::learner::{Inputs, Learner};
use crate::replay::{Batch, DepthLayout, ReplayBuffer, Transition};
use mdrlat_core::{DEPTH_LEN, FRAME_STACK, LASER_BEAMS, Observation, Rng};
use mdrlat_nn::Variant;
use mdrlat_nn::burn::prelude::Device;
use mdrlat_sim::config::Task;
use std::time::{Duration, Instant};

/// The CPU model (`/proc/cpuinfo`'s first `model name`, or `unknown`), for the record beside
/// a measured time.
pub fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| "unknown".into())
}

/// A random batch in the network's input layout (values in the normalised ranges).
pub fn random_batch(variant: Variant, size: usize, seed: u64) -> Batch {
    let mut rng = Rng::seed_from_u64(seed);
    let mut fill = |n: usize| (0..n).map(|_| rng.uniform() as f32).collect::<Vec<f32>>();
    let ls = if variant.uses_laser() { size * FRAME_STACK * LASER_BEAMS } else { 0 };
    let ds = if variant.uses_depth() { size * FRAME_STACK * DEPTH_LEN } else { 0 };
    Batch {
        size,
        laser: fill(ls),
        depth: fill(ds),
        next_laser: fill(ls),
        next_depth: fill(ds),
        actions: (0..size as i64).map(|i| i % 10).collect(),
        rewards: fill(size),
        terminated: (0..size).map(|i| (i % 7 == 0) as u8 as f32).collect(),
        steps: vec![1; size],
        odom: fill(size * 6),
        goal: Vec::new(),
        next_goal: Vec::new(),
        depth_frames: Default::default(),
        weights: Vec::new(),
    }
}

/// A random batch for `learner`'s gradient steps: [`random_batch`], or where the learner takes
/// its depth input as frames ([`Learner::depth_layout`]), `size` transitions drawn at random
/// from eight times as many of one episode of random frames ([`random_replay`]), in that
/// layout: like a training run's batches, they share few frames (~5 distinct a row).
pub fn learner_batch(learner: &Learner, size: usize, seed: u64) -> Batch {
    let variant = learner.variant();
    match learner.depth_layout() {
        DepthLayout::Stacks => random_batch(variant, size, seed),
        layout => {
            let replay = random_replay(variant, 8 * size.max(1), seed);
            let indices = replay.sample_indices(size, &mut Rng::seed_from_u64(seed + 1));
            let mut out = Batch::default();
            replay.write_batch_as(&indices, &mut out, layout);
            out
        }
    }
}

/// A replay buffer of `n` transitions of one long episode of random frames (laser
/// 0.1–5.6 m, depth 0.4–10 m), with actions, rewards, terminations and velocities as
/// [`random_batch`] has them.
pub fn random_replay(variant: Variant, n: usize, seed: u64) -> ReplayBuffer {
    let mut rng = Rng::seed_from_u64(seed);
    let mut replay = ReplayBuffer::new(n, n, variant.uses_laser(), variant.uses_depth());
    let frame = |replay: &mut ReplayBuffer, rng: &mut Rng| {
        let laser: Vec<f32> = (0..LASER_BEAMS).map(|_| rng.range_f32(0.1, 5.6)).collect();
        let depth: Vec<f32> = (0..DEPTH_LEN).map(|_| rng.range_f32(0.4, 10.0)).collect();
        replay.push_frame(&laser, &depth)
    };
    let mut ids = [frame(&mut replay, &mut rng); FRAME_STACK];
    for i in 0..n {
        let obs = ids;
        ids.rotate_left(1);
        ids[FRAME_STACK - 1] = frame(&mut replay, &mut rng);
        let t = Transition {
            obs,
            next: ids,
            action: (i % 10) as u8,
            reward: rng.uniform() as f32,
            terminated: i % 7 == 0,
            steps: 1,
            odom: std::array::from_fn(|_| rng.uniform() as f32),
            goal: [0.0; 3],
            next_goal: [0.0; 3],
        };
        replay.push(t);
    }
    replay
}

/// Median milliseconds of `f` over runs filling at least `min_time` (after one warm-up).
pub fn median_ms(min_time: Duration, f: impl FnMut()) -> (f64, usize) {
    let samples = samples_ms(min_time, f);
    (samples[samples.len() / 2], samples.len())
}

/// Sorted milliseconds of `f` over runs filling at least `min_time` (at least 3, after one
/// warm-up).
fn samples_ms(min_time: Duration, mut f: impl FnMut()) -> Vec<f64> {
    f();
    let start = Instant::now();
    let mut samples = Vec::new();
    while start.elapsed() < min_time || samples.len() < 3 {
        let t = Instant::now();
        f();
        samples.push(t.elapsed().as_secs_f64() * 1e3);
    }
    samples.sort_by(f64::total_cmp);
    samples
}

/// Median milliseconds of one gradient step (batch `batch`) of `variant` on `device`, with
/// the host kernels where the backend has them (`host_kernels`; else burn's autodiff).
pub fn update_ms(
    variant: Variant,
    batch: usize,
    device: &Device,
    host_kernels: bool,
    min_time: Duration,
) -> (f64, usize) {
    let config = TrainConfig { variant, batch_size: batch, ..TrainConfig::default() };
    let mut learner = Learner::new(&config, Task::Avoid, device);
    learner.set_host_kernels(host_kernels);
    let b = learner_batch(&learner, batch, 1);
    median_ms(min_time, || {
        learner.update(&b);
    })
}

/// The arithmetic rate of a gradient step of `variant` (batch `batch`) that takes `ms`
/// milliseconds, GFLOP/s (see `QNetConfig::update_flops`).
pub fn update_gflops(variant: Variant, batch: usize, ms: f64) -> f64 {
    let flop = mdrlat_nn::QNetConfig::new(variant).update_flops() as f64 * batch as f64;
    flop / (ms * 1e-3) / 1e9
}

/// Median milliseconds of one greedy decision (batch 1) of `variant` on `device`, with the
/// CPU backend's kernels limited to `threads` threads (1: one core, as on the robot).
///
/// # Panics
/// If the OS refuses the measurement's thread.
pub fn infer_ms(
    variant: Variant,
    device: &Device,
    min_time: Duration,
    threads: usize,
) -> (f64, usize) {
    let config = TrainConfig { variant, ..TrainConfig::default() };
    let learner = Learner::new(&config, Task::Avoid, device);
    let b = random_batch(variant, 1, 2);
    let inputs = Inputs { size: 1, laser: b.laser, depth: b.depth, goal: Vec::new() };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .build()
        .expect("inference thread pool");
    pool.install(|| {
        median_ms(min_time, || {
            let _ = learner.greedy(&inputs);
        })
    })
}

/// Median milliseconds of one decision of a fresh `variant` policy on one core of the CPU
/// backend — `Policy::decide` on one observation, as the ROS node calls it: the inputs
/// normalised, the network, the greedy action — with its linear layers' weights in
/// bfloat16 when `bf16` ([`crate::GreedyPolicy::with_bf16_weights`]), and the samples.
///
/// # Errors
/// The CPU lacks the bfloat16 kernel, or the policy's thread cannot start.
pub fn decision_ms(
    variant: Variant,
    bf16: bool,
    min_time: Duration,
) -> Result<(f64, usize), String> {
    let mut policy = crate::GreedyPolicy::untrained(variant, Task::Avoid, 0, &Device::flex(), 1)?;
    if bf16 {
        policy = policy.with_bf16_weights()?;
    }
    let obs = random_observations(1, 2);
    Ok(median_ms(min_time, || {
        let _ = mdrlat_core::decide_one(&mut policy, &obs[0], 0);
    }))
}

/// Median milliseconds of one batched greedy decision for `observations` random
/// observations of `variant` (as an evaluation makes them: normalisation, forwards of
/// `forward_batch` rows side by side on `threads` threads, argmax), and the arithmetic rate
/// that gives, GFLOP/s.
///
/// # Panics
/// If the OS refuses the policy's threads.
pub fn policy_batch_ms(
    variant: Variant,
    device: &Device,
    observations: usize,
    forward_batch: Option<usize>,
    threads: usize,
    min_time: Duration,
) -> (f64, f64) {
    use mdrlat_core::Policy;
    let mut policy = crate::GreedyPolicy::untrained(variant, Task::Avoid, 0, device, threads)
        .expect("inference thread pool")
        .with_forward_batch(forward_batch);
    let obs = random_observations(observations, 6);
    let batch: Vec<&Observation> = obs.iter().collect();
    let slots: Vec<usize> = (0..observations).collect();
    let mut decisions = Vec::new();
    let (ms, _) = median_ms(min_time, || {
        let _ = policy.decide(&batch, &slots, &mut decisions);
    });
    let flop = mdrlat_nn::QNetConfig::new(variant).decision_flops() as f64 * observations as f64;
    (ms, flop / (ms * 1e-3) / 1e9)
}

/// `n` random observations (laser 0.2–5.6 m, depth 0.4–9 m) for the decision benchmarks.
fn random_observations(n: usize, seed: u64) -> Vec<Observation> {
    let mut rng = Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let mut o = Observation::zeros();
            for _ in 0..FRAME_STACK {
                o.laser.push_slot().iter_mut().for_each(|r| *r = rng.range_f32(0.2, 5.6));
                o.depth.push_slot().iter_mut().for_each(|d| *d = rng.range_f32(0.4, 9.0));
            }
            o
        })
        .collect()
}

/// Median milliseconds of making the network inputs of `observations` random observations
/// of `variant` on one thread ([`crate::observation_inputs`]: each observation's frames,
/// normalised, into the batch's stacks): the part of a batched decision before any forward.
pub fn observation_inputs_ms(variant: Variant, observations: usize, min_time: Duration) -> f64 {
    let obs = random_observations(observations, 6);
    let batch: Vec<&Observation> = obs.iter().collect();
    let config = mdrlat_nn::QNetConfig::new(variant);
    let mut inputs = Inputs::default();
    median_ms(min_time, || {
        let _ = crate::observation_inputs(&batch, &config, &mut inputs);
    })
    .0
}

/// Median milliseconds of each stage of one forward pass of `rows` random observations of
/// a fresh `variant` network on the host kernels, all on the calling thread (as each of a
/// batched decision's forwards runs), in forward order; empty where the host kernels do not
/// run (never on `flex`).
pub fn forward_stages_ms(
    variant: Variant,
    rows: usize,
    min_time: Duration,
) -> Vec<(&'static str, f64)> {
    let config = mdrlat_nn::QNetConfig::new(variant);
    let Some(host) = config.init_seeded(&Device::flex(), 0).host(&config) else {
        return Vec::new();
    };
    let host = host.on_calling_thread();
    let obs = random_observations(rows, 6);
    let batch: Vec<&Observation> = obs.iter().collect();
    let mut inputs = Inputs::default();
    if crate::observation_inputs(&batch, &config, &mut inputs).is_err() {
        return Vec::new();
    }
    let mut samples: Vec<Vec<(&'static str, f64)>> = Vec::new();
    median_ms(min_time, || samples.push(host.forward(&inputs.host(), false).times.stages));
    let stages = samples.first().map_or(0, Vec::len);
    (0..stages)
        .map(|i| {
            let mut ms: Vec<f64> = samples.iter().filter_map(|s| s.get(i).map(|x| x.1)).collect();
            ms.sort_by(f64::total_cmp);
            (samples[0][i].0, ms[ms.len() / 2])
        })
        .collect()
}

/// The machine's own fp32 GEMM rate through the same library the learner uses (burn's
/// `flex` backend, whose matrix products are the `gemm` crate's): one `n × n × n` product
/// per thread on `threads` threads at once, GFLOP/s summed over the threads, from the
/// fastest of the samples. The yardstick
/// the learner's and the evaluation's arithmetic rates are divided by.
///
/// # Panics
/// If the OS refuses the measurement's threads.
pub fn gemm_reference_gflops(n: usize, threads: usize, min_time: Duration) -> f64 {
    use mdrlat_nn::burn::prelude::*;
    use rayon::prelude::*;
    let device = Device::flex();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .build()
        .expect("gemm reference thread pool");
    let mut rng = Rng::seed_from_u64(8);
    let mut matrix = || {
        let v: Vec<f32> = (0..n * n).map(|_| rng.range_f32(-1.0, 1.0)).collect();
        Tensor::<2>::from_data(TensorData::new(v, [n, n]), &device)
    };
    let (a, b) = (matrix(), matrix());
    // The fastest sample: the limit is what the machine can do, and a shared VM's other
    // tenants only ever slow a sample down.
    let ms = pool.install(|| {
        samples_ms(min_time, || {
            (0..threads.max(1)).into_par_iter().for_each(|_| {
                let c = a.clone().matmul(b.clone());
                let _ = c.into_data();
            });
        })[0]
    });
    2.0 * (n as f64).powi(3) * threads.max(1) as f64 / (ms * 1e-3) / 1e9
}

/// Bytes of a full replay buffer of `capacity` transitions for `variant`.
pub fn replay_bytes(variant: Variant, capacity: usize) -> usize {
    let reserve = crate::checkpoint::frame_reserve(capacity);
    ReplayBuffer::new(capacity, reserve, variant.uses_laser(), variant.uses_depth()).memory_bytes()
}

/// Median milliseconds of sampling a batch of `batch` transitions from a replay buffer of
/// 2,000 (random frames, one long episode) in `layout`: the frame lookups, and for stacks the
/// u16 → f32 normalisation, that every gradient step starts with.
pub fn sample_ms(variant: Variant, batch: usize, layout: DepthLayout, min_time: Duration) -> f64 {
    let replay = random_replay(variant, 2_000, 4);
    let mut rng = Rng::seed_from_u64(5);
    let mut out = Batch::default();
    median_ms(min_time, || {
        let indices = replay.sample_indices(batch, &mut rng);
        replay.write_batch_as(&indices, &mut out, layout);
    })
    .0
}

/// Where one gradient step's time goes, milliseconds: forward and backward of each network
/// stage (batch `batch`, with autodiff, each stage's inputs detached), the two
/// target-network forwards of eq. (10), the rest of the step (losses, graph, Adam) and the
/// whole step, each a median.
pub fn profile(
    variant: Variant,
    batch: usize,
    device: &Device,
    min_time: Duration,
) -> Vec<(String, f64)> {
    let config = TrainConfig { variant, batch_size: batch, ..TrainConfig::default() };
    let mut learner = Learner::new(&config, Task::Avoid, device);
    let b = learner_batch(&learner, batch, 3);
    // Per stage: forward and backward samples.
    let mut stages: Vec<(&'static str, Vec<f64>, Vec<f64>)> = Vec::new();
    let start = Instant::now();
    let stage_times =
        |learner: &Learner| learner.host_stage_times(&b).unwrap_or_else(|| learner.stage_times(&b));
    while start.elapsed() < min_time || stages.first().is_none_or(|s| s.1.len() < 3) {
        for (i, st) in stage_times(&learner).into_iter().enumerate() {
            if stages.len() <= i {
                stages.push((st.name, Vec::new(), Vec::new()));
            }
            stages[i].1.push(st.forward_ms);
            stages[i].2.push(st.backward_ms.unwrap_or(0.0));
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let mut out = Vec::new();
    let (mut forward, mut backward) = (0.0, 0.0);
    for (name, mut f, mut bw) in stages {
        let (f, bw) = (median(&mut f), median(&mut bw));
        out.push((format!("{name}: forward"), f));
        out.push((format!("{name}: backward"), bw));
        forward += f;
        backward += bw;
    }
    let (targets, _) = median_ms(min_time, || {
        learner.td_targets(&b);
    });
    let layout = learner.depth_layout();
    let sample = sample_ms(variant, batch, layout, min_time);
    let to_device = variant.uses_depth().then(|| {
        median_ms(min_time, || {
            learner.depth_to_device(&b);
        })
        .0
    });
    let mut phases: [Vec<f64>; 3] = Default::default();
    let (fused_before, fallback_before) = learner.adam_paths();
    let (step, _) = median_ms(min_time, || {
        learner.update(&b);
        for (v, ms) in phases.iter_mut().zip(learner.phase_times()) {
            v.push(ms);
        }
    });
    let [mut p0, mut p1, mut p2] = phases;
    let (fused, fallback) = learner.adam_paths();
    let (fused, fallback) = (fused - fused_before, fallback - fallback_before);
    let share = 100.0 * fused as f64 / (fused + fallback).max(1) as f64;
    out.push(("= forward with autodiff, one pass".into(), forward));
    out.push(("= backward, stage by stage".into(), backward));
    let (sampling, depth) = match layout {
        DepthLayout::Stacks => (
            "sampling a batch from the replay buffer (frames to f32 stacks)",
            "a batch's depth input, s and s', to the device (flex: patches cut on the host)",
        ),
        DepthLayout::Frames => (
            "sampling a batch from the replay buffer (its distinct depth frames as stored)",
            "a batch's depth input, s and s', to the device (frames as u16, stacks made there)",
        ),
    };
    out.push((sampling.into(), sample));
    if let Some(ms) = to_device {
        out.push((depth.into(), ms));
    }
    out.push(("target forwards (eq. 10, 2 passes; side by side on flex)".into(), targets));
    // On a GPU the first two phases only queue their work; the third's loss read waits for it.
    let queued = if mdrlat_nn::is_libtorch_gpu(device) { ", queued" } else { "" };
    out.push((
        format!("step phase 1: targets + online forward (side by side on flex{queued})"),
        median(&mut p0),
    ));
    let (two, three) = if learner.uses_host_kernels() {
        (
            "step phase 2: the heads' backward".to_string(),
            format!(
                "step phase 3: the rest of the backward beside the heads' and the fusion's Adam, \
                 then the streams' Adam ({share:.0}% of parameter updates fused)"
            ),
        )
    } else {
        (
            format!("step phase 2: losses and backward{queued}"),
            format!(
                "step phase 3: Adam ({share:.0}% of parameter updates fused) + plain copy + \
                 reading the losses{}",
                if queued.is_empty() { "" } else { ", which waits for the step" }
            ),
        )
    };
    out.push((two, median(&mut p1)));
    out.push((three, median(&mut p2)));
    out.push(("= gradient step".into(), step));
    out
}

/// A timing: median milliseconds and how many runs were timed, or why it could not be taken.
pub type Timed = Result<(f64, usize), String>;

/// What `mdrlat bench train` measures for one variant.
#[derive(Debug, Clone, PartialEq)]
pub struct VariantFigures {
    /// The variant.
    pub variant: Variant,
    /// Median gradient step (host kernels on `flex`), ms, and how many were timed.
    pub train: (f64, usize),
    /// The same step through burn's autodiff, when asked for.
    pub autodiff: Option<(f64, usize)>,
    /// Median single decision on one core, ms, and how many were timed.
    pub infer: (f64, usize),
    /// One decision through the policy path in f32 and in bfloat16 (CPU only; bfloat16 needs
    /// AVX-512), ms and samples, or why it could not be measured.
    pub precision: Option<(Timed, Timed)>,
    /// A batched decision of `observations` on all cores: ms and GFLOP/s.
    pub batch: (f64, f64),
    /// Replay memory for 20,000 transitions, MiB.
    pub replay_mib: f64,
}

/// The settings of [`measure_variant`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BenchSettings {
    /// Transitions per gradient step.
    pub batch: usize,
    /// Least time each measurement runs.
    pub time: Duration,
    /// Threads of the batched decision.
    pub threads: usize,
    /// Rows per forward of the batched decision.
    pub forward_batch: usize,
    /// Also time the gradient step through burn's autodiff.
    pub compare_autodiff: bool,
    /// Also time f32 against bfloat16 decisions (the CPU backend only).
    pub precision: bool,
}

/// Every learner figure of `variant` on `device` (the rows of `mdrlat bench train`).
pub fn measure_variant(variant: Variant, device: &Device, s: &BenchSettings) -> VariantFigures {
    let train = update_ms(variant, s.batch, device, true, s.time);
    let autodiff = s.compare_autodiff.then(|| update_ms(variant, s.batch, device, false, s.time));
    let infer = infer_ms(variant, device, s.time, 1);
    let precision = s
        .precision
        .then(|| (decision_ms(variant, false, s.time), decision_ms(variant, true, s.time)));
    let batch = policy_batch_ms(variant, device, 64, Some(s.forward_batch), s.threads, s.time);
    let replay_mib = replay_bytes(variant, 20_000) as f64 / (1024.0 * 1024.0);
    VariantFigures { variant, train, autodiff, infer, precision, batch, replay_mib }
}
