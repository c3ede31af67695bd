//! Measuring the learner: gradient-step time per variant, single-decision inference latency
//! and replay memory.

use crate::config::TrainConfig;
use crate::learner::{Inputs, Learner};
use crate::replay::{Batch, ReplayBuffer};
use mdrlat_core::{DEPTH_LEN, FRAME_STACK, LASER_BEAMS, Rng};
use mdrlat_nn::Variant;
use mdrlat_nn::burn::prelude::Device;
use std::time::{Duration, Instant};

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
        odom: fill(size * 6),
    }
}

/// Median milliseconds of `f` over runs filling at least `min_time` (after one warm-up).
pub fn median_ms(min_time: Duration, mut f: impl FnMut()) -> (f64, usize) {
    f();
    let start = Instant::now();
    let mut samples = Vec::new();
    while start.elapsed() < min_time || samples.len() < 3 {
        let t = Instant::now();
        f();
        samples.push(t.elapsed().as_secs_f64() * 1e3);
    }
    samples.sort_by(f64::total_cmp);
    (samples[samples.len() / 2], samples.len())
}

/// Median milliseconds of one gradient step (batch `batch`) of `variant` on `device`.
pub fn update_ms(
    variant: Variant,
    batch: usize,
    device: &Device,
    min_time: Duration,
) -> (f64, usize) {
    let config = TrainConfig { variant, batch_size: batch, ..TrainConfig::default() };
    let mut learner = Learner::new(&config, device);
    let b = random_batch(variant, batch, 1);
    median_ms(min_time, || {
        learner.update(&b);
    })
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
    let learner = Learner::new(&config, device);
    let b = random_batch(variant, 1, 2);
    let inputs = Inputs { size: 1, laser: b.laser, depth: b.depth };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .build()
        .expect("inference thread pool");
    pool.install(|| {
        median_ms(min_time, || {
            learner.greedy(&inputs);
        })
    })
}

/// Bytes of a full replay buffer of `capacity` transitions for `variant`.
pub fn replay_bytes(variant: Variant, capacity: usize) -> usize {
    let reserve = crate::checkpoint::frame_reserve(capacity);
    ReplayBuffer::new(capacity, reserve, variant.uses_laser(), variant.uses_depth()).memory_bytes()
}

/// Where one gradient step's time goes, milliseconds: the forward pass by stage (batch
/// `batch`, no autodiff), the two target-network forwards of eq. (10), and the rest of the
/// step (forward with autodiff, backward, Adam), each a median.
pub fn profile(
    variant: Variant,
    batch: usize,
    device: &Device,
    min_time: Duration,
) -> Vec<(String, f64)> {
    let config = TrainConfig { variant, batch_size: batch, ..TrainConfig::default() };
    let mut learner = Learner::new(&config, device);
    let b = random_batch(variant, batch, 3);
    let mut stages: Vec<(String, Vec<f64>)> = Vec::new();
    let start = Instant::now();
    while start.elapsed() < min_time || stages.first().is_none_or(|s| s.1.len() < 3) {
        for (i, (name, ms)) in learner.stage_times(&b).into_iter().enumerate() {
            if stages.len() <= i {
                stages.push((name.to_string(), Vec::new()));
            }
            stages[i].1.push(ms);
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let mut out: Vec<(String, f64)> =
        stages.into_iter().map(|(n, mut v)| (n, median(&mut v))).collect();
    let forward: f64 = out.iter().map(|s| s.1).sum();
    let (targets, _) = median_ms(min_time, || {
        learner.td_targets(&b);
    });
    let (step, _) = median_ms(min_time, || {
        learner.update(&b);
    });
    out.push(("= forward, one pass".into(), forward));
    out.push(("target forwards (eq. 10, 2 passes)".into(), targets));
    out.push(("forward + backward + Adam".into(), (step - targets).max(0.0)));
    out.push(("= gradient step".into(), step));
    out
}
